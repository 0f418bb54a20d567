"""Pair potentials derived from cold curves (CD eq. 1-2), unlike-pair mixing, kernel tables."""

from .cluster import (DEFAULT_RC, N_BINS, R_MIN_FACTOR, ClusterPotential, MixedPairPotential, PairTable,
                      build_tables, check_rc)

__all__ = ["ClusterPotential", "MixedPairPotential", "PairTable", "build_tables", "check_rc",
           "DEFAULT_RC", "N_BINS", "R_MIN_FACTOR"]
