"""Analysis of runs: stresses, profiles, shock fronts, fragments."""
from .stress import kinetic_virials, local_stress, particle_virials, stress_profile, von_mises  # noqa: E402,F401
from .profiles import TrajectoryProfiles, trajectory_profiles, write_profiles_csv  # noqa: E402,F401
