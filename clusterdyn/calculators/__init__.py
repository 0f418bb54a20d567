"""ASE calculators: Cluster Dynamics and Movable Cellular Automata."""

from .cluster import ClusterDynamics

__all__ = ["ClusterDynamics"]
