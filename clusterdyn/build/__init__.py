"""Builders: ASE Atoms of clusters and automata."""

from .lattice import (ORIENTATIONS, fcc_packing, fcc_sites, make_cluster_atoms, orientation_matrix,
                      parse_direction, repeat_lengths)
from .shapes import Box, Cylinder, Plate, Sphere

__all__ = ["fcc_packing", "fcc_sites", "make_cluster_atoms", "orientation_matrix", "parse_direction",
           "repeat_lengths", "ORIENTATIONS", "Box", "Cylinder", "Plate", "Sphere"]
