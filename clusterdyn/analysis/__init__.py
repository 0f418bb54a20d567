"""Analysis of runs: stresses, slab profiles, shock fronts, fragments."""
from .stress import kinetic_virials, local_stress, particle_virials, von_mises  # noqa: F401
from .slabs import binned_profile, stress_profile  # noqa: F401
from .profiles import TrajectoryProfiles, trajectory_profiles, write_profiles_csv  # noqa: F401
from .fragments import FragmentAnalysis, FragmentFinder, FragmentObserver, Fragments, fragments  # noqa: F401
from .order import OrderReference, fcc_order  # noqa: F401
