"""Neighbour search shared by every force model: numba cell list + Verlet list with skin."""

from .celllist import NeighborList, check_cell

__all__ = ["NeighborList", "check_cell"]
