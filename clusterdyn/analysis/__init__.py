"""Analysis of runs: stresses, profiles, shock fronts, fragments."""
from .stress import kinetic_virials, local_stress, particle_virials, stress_profile, von_mises  # noqa: E402,F401
from .profiles import trajectory_profiles, write_profiles_csv  # noqa: E402,F401
from .fragments import (FragmentAnalysis, FragmentFinder, FragmentObserver, Fragments,  # noqa: E402,F401
                        fragments)
