"""Neighbour search shared by every force model: numba cell list + Verlet list with skin, and the
minimum-image convention of its boxes.

One concept a module: the cell grid (:mod:`.grid`), the sort into cell order (:mod:`.sort`), the
fill of the list and its memory pool (:mod:`.fill`), the rebuild tests (:mod:`.rebuild`), the
list (:mod:`.celllist`, :class:`NeighborList`), periodic images (:mod:`.image`)."""

from .celllist import NeighborList
from .grid import check_cell
from .image import image_component, minimum_image

__all__ = ["NeighborList", "check_cell", "image_component", "minimum_image"]
