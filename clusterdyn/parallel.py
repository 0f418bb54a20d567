"""Thread count of the numba kernels, sized to the system.

A parallel region costs a thread synchronisation; on a loaded machine a
descheduled worker turns microseconds into milliseconds.  Kernels therefore
use one thread per :data:`MIN_PARTICLES_PER_THREAD` particles, up to
:func:`max_threads` (numba's thread count, or ``set_max_threads``).  The
count depends only on N and the limit, so force sums stay deterministic.
"""

import numba

#: particles per thread below which a kernel runs on fewer threads
MIN_PARTICLES_PER_THREAD = 16384
_MAX = [None]


def max_threads():
    return _MAX[0] or numba.config.NUMBA_NUM_THREADS


def set_max_threads(n):
    """Limit clusterdyn's kernels to ``n`` threads (None: numba's default)."""
    if n is not None and (int(n) < 1 or int(n) > numba.config.NUMBA_NUM_THREADS):
        from .errors import InputError
        raise InputError("threads", n, f"1..{numba.config.NUMBA_NUM_THREADS}")
    _MAX[0] = None if n is None else int(n)


def threads_for(n):
    """Threads for a kernel over n particles."""
    return max(1, min(max_threads(), n // MIN_PARTICLES_PER_THREAD))


def use_threads(n):
    """Set numba's thread count for the coming kernels over n particles; returns it."""
    k = threads_for(n)
    numba.set_num_threads(k)
    return k
