"""ASE calculators: Cluster Dynamics and Movable Cellular Automata."""

from .cluster import ClusterDynamics, mark_initial_bonds

__all__ = ["ClusterDynamics", "mark_initial_bonds"]
from ..mca.calculator import MCA  # noqa: E402,F401
__all__ += ["MCA"]
