"""OpenMP waiting settings, set when clusterdyn is imported, before numba's OpenMP runtime loads.

The runtime reads them once, when numba first runs a parallel kernel; the
reasons and measurements are in :mod:`clusterdyn.parallel`.  A setting the
user made (either variable) is kept.
"""

import os

#: libgomp spin iterations before an idle worker sleeps (about 50-100 us)
SPIN_COUNT = 5000

if "OMP_WAIT_POLICY" not in os.environ and "GOMP_SPINCOUNT" not in os.environ:
    os.environ["GOMP_SPINCOUNT"] = str(SPIN_COUNT)
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
