"""Thread count of the numba kernels, sized to the system.

A parallel region costs a thread synchronisation; on a loaded machine a
descheduled worker turns microseconds into milliseconds.  Kernels therefore
use one thread per :data:`MIN_PARTICLES_PER_THREAD` particles, up to
:func:`max_threads` (numba's thread count, or ``set_max_threads``).  The
count depends only on N and the limit.  (The force sums do not depend on
it at all: the kernels' chunks are fixed by N, see engine.pair.)

OpenMP waiting: numba's default ``omp`` threading layer lets idle workers
spin for about 3 ms (libgomp's default), which on a machine shared with other
jobs steals the cores the working threads need (measured: 2 threads at 1.9e6
particle-steps/s instead of 1.07e7 under a load of 3.4 on 2 cores).  Never
spinning is no better on a quiet machine: a sleeping worker took about 70 us
to start each parallel region here (a KVM guest), and a step has two or
three regions, a list build two more; at 32k clusters that was a tenth of a
two-thread step.  Unless the user set ``OMP_WAIT_POLICY`` or
``GOMP_SPINCOUNT``, the ``clusterdyn`` command sets ``OMP_WAIT_POLICY=PASSIVE`` and
``GOMP_SPINCOUNT`` = :data:`SPIN_COUNT` before the OpenMP runtime starts (it
reads them once, when numba first runs a parallel kernel); from Python call
:func:`configure_openmp` first (``import clusterdyn`` changes no environment
variable of the process): an idle worker
spins about 50-100 us, enough to bridge the Python between a step's regions,
then sleeps.  (Measured, 32k, two threads against one in the same process:
79% without spinning, 88% with it; with one other busy process on the 2
cores a two-thread step was 15% slower with it, and slower than one thread
either way: on a loaded machine use one thread.)  ``OMP_WAIT_POLICY=PASSIVE
GOMP_SPINCOUNT=0`` restores pure sleeping.
Streaming passes (kicks, drift, gathers, the rebuild check) run in parallel over
fixed blocks too (they are a tenth of a step; serial they cap two threads at 80%).
"""

from ._openmp import SPIN_COUNT, configure_openmp  # noqa: F401  (the CLI calls it; Python users may)

import threading  # noqa: E402

import numba  # noqa: E402
from numba import njit  # noqa: E402

#: particles per thread below which a kernel runs on fewer threads (two threads from 8 192
#: particles; the pair loop's chunks are cut small enough for them, ``engine.pair``)
MIN_PARTICLES_PER_THREAD = 4096
#: particles per block of the streaming passes (kicks, drift, gathers): fixed, so their
#: results do not depend on the thread count
STREAM_BLOCK = 8192
_MAX = [None]
#: (generation, count) :func:`use_threads` last gave numba on this Python thread (numba's count
#: is per thread); :func:`set_max_threads` and :func:`forget_threads` start a new generation
_LAST = threading.local()
_GEN = [0]


def max_threads():
    return _MAX[0] or numba.config.NUMBA_NUM_THREADS


def set_max_threads(n):
    """Limit clusterdyn's kernels to ``n`` threads (None: numba's default)."""
    if n is not None and (int(n) < 1 or int(n) > numba.config.NUMBA_NUM_THREADS):
        from .errors import InputError
        raise InputError("threads", n, f"1..{numba.config.NUMBA_NUM_THREADS}")
    _MAX[0] = None if n is None else int(n)
    _GEN[0] += 1


def threads_for(n):
    """Threads for a kernel over n particles."""
    return max(1, min(max_threads(), n // MIN_PARTICLES_PER_THREAD))


def use_threads(n):
    """Set numba's thread count for the coming kernels over n particles; returns it.

    numba is told only when the count differs from the one this function last gave it on the
    calling thread (``numba.set_num_threads`` takes 1.4-1.9 us in a loop and more in a step,
    which asks five times: caching it took 10-15 us off a step of 101-112 us on 32 clusters).
    A count set with ``numba.set_num_threads`` between clusterdyn's calls therefore stays until
    clusterdyn's own count changes; limit clusterdyn's kernels with :func:`set_max_threads`, or
    call :func:`forget_threads` after setting numba's count directly.  The kernels' results do
    not depend on the count."""
    k = threads_for(n)
    want = (_GEN[0], k)
    if getattr(_LAST, "set", None) != want:
        numba.set_num_threads(k)
        _LAST.set = want
    return k


def forget_threads():
    """Make the next :func:`use_threads` on every thread set numba's count, whatever it last set."""
    _GEN[0] += 1


@njit(inline="always")
def max_take(m, k, v, i):
    """(largest value, its index) after offering value ``v`` of item ``i``; a NaN wins and stays
    (the streaming passes' speed maximum, so a blown-up particle is the one reported)."""
    if not v <= m and not (m != m):
        return v, i
    return m, k


@njit(inline="always")
def blocks_max(bmax_b, barg_b):
    """:func:`max_take` over per-block maxima in block order: the same on any thread count."""
    m = bmax_b[0]
    k = barg_b[0]
    for b in range(1, bmax_b.shape[0]):
        m, k = max_take(m, k, bmax_b[b], barg_b[b])
    return m, k
