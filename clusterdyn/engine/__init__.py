"""The Cluster Dynamics engine: the pair kernels (:mod:`.pair`), the integrator kernels
(:mod:`.integrate`) and the engine object that owns the neighbour list, the tables and the
row-order buffers of a CD run."""

from .core import CDEngine

__all__ = ["CDEngine"]
