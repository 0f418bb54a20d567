"""ASE calculators: Cluster Dynamics (MCA's calculator is :class:`clusterdyn.mca.MCA`)."""

from .cluster import ClusterDynamics, mark_initial_bonds

__all__ = ["ClusterDynamics", "mark_initial_bonds"]
