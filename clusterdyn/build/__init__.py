"""Builders: ASE Atoms of clusters and automata."""

from .lattice import (ORIENTATIONS, fcc_packing, fcc_sites, make_cluster_atoms, orientation_matrix,
                      along_axis, parse_axis, parse_direction, repeat_lengths)
from .shapes import Box, Cylinder, Plate, Sphere

__all__ = ["along_axis", "parse_axis", "fcc_packing", "fcc_sites", "make_cluster_atoms", "orientation_matrix", "parse_direction",
           "repeat_lengths", "ORIENTATIONS", "Box", "Cylinder", "Plate", "Sphere"]
from .polycrystal import grain_statistics, polycrystal, polycrystal_summary  # noqa: E402
from .orientation import (grain_orientation, misorientation_angle, misorientation_distribution,  # noqa: E402
                          spacegroup)
__all__ += ["polycrystal", "polycrystal_summary", "grain_statistics", "grain_orientation", "misorientation_angle", "misorientation_distribution", "spacegroup"]  # noqa: E501
from .mca import mca_packing, notch, precrack  # noqa: E402,F401
__all__ += ["mca_packing", "precrack", "notch"]
from .two_phase import PAPER_CASES, two_phase  # noqa: E402
__all__ += ["two_phase", "PAPER_CASES"]
from .bodies import (combine_bodies, crystal_rotation, place, plate, plate_stack, rod, sphere,  # noqa: E402
                     translate)
__all__ += ["rod", "sphere", "plate", "plate_stack", "place", "translate", "combine_bodies", "crystal_rotation"]
from .profiled import (Grooves, RandomRoughness, Sinusoid, profiled_sample, surface_amplitude,  # noqa: E402
                       surface_heights, surface_roughness)
__all__ += ["profiled_sample", "Sinusoid", "Grooves", "RandomRoughness", "surface_heights", "surface_amplitude",
            "surface_roughness"]
