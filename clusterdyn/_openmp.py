"""OpenMP waiting settings for numba's OpenMP runtime: :func:`configure_openmp`.

The runtime reads them once, when numba first runs a parallel kernel; the
reasons and measurements are in :mod:`clusterdyn.parallel`.  ``import
clusterdyn`` changes no environment variable: the ``clusterdyn`` command makes
these settings when it starts, and a Python user calls
:func:`configure_openmp` before the first step (or sets the variables
themselves).  A setting the user made (either variable) is kept.
"""

import os

#: libgomp spin iterations before an idle worker sleeps (about 50-100 us)
SPIN_COUNT = 5000


def configure_openmp(environ=None):
    """Set ``OMP_WAIT_POLICY=PASSIVE`` and ``GOMP_SPINCOUNT`` = :data:`SPIN_COUNT` in ``environ``
    (default ``os.environ``) unless either is set; returns the two values now in force.  Call it
    before numba's first parallel kernel runs (it has no effect after)."""
    env = os.environ if environ is None else environ
    if "OMP_WAIT_POLICY" not in env and "GOMP_SPINCOUNT" not in env:
        env["GOMP_SPINCOUNT"] = str(SPIN_COUNT)
    env.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    return {k: env.get(k) for k in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
