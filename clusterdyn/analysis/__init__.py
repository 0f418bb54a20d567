"""Analysis of runs: stresses, slab profiles, shock fronts, fragments."""
from .stress import kinetic_virials, local_stress, particle_virials, von_mises  # noqa: F401
from .slabs import binned_profile, stress_profile  # noqa: F401
from .profiles import TrajectoryProfiles, trajectory_profiles, write_profiles_csv  # noqa: F401
from .fragment_graph import FragmentFinder  # noqa: F401
from .fragment_spectra import Fragments  # noqa: F401
# the function fragments() is not re-exported: its name is its module's, so that
# ``import clusterdyn.analysis.fragments`` gives the module (use clusterdyn.analysis.fragments.fragments)
from .fragments import FragmentAnalysis, FragmentObserver  # noqa: F401
from .order import OrderReference, fcc_order  # noqa: F401
