"""Neighbour search shared by every force model: numba cell list + Verlet list with skin, and the
minimum-image convention of its boxes."""

from .celllist import NeighborList, check_cell
from .image import image_component, minimum_image

__all__ = ["NeighborList", "check_cell", "image_component", "minimum_image"]
