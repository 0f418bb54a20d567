"""ASE calculators: Cluster Dynamics and Movable Cellular Automata."""

from .cluster import ClusterDynamics

__all__ = ["ClusterDynamics"]
from ..mca.calculator import MCA  # noqa: E402,F401
__all__ += ["MCA"]
