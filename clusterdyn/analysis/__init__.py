"""Analysis of runs: stresses, profiles, shock fronts, fragments."""
