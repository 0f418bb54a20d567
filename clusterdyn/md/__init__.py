"""Dynamics (ASE MolecularDynamics subclasses) and boundary conditions."""

from .boundaries import Piston, RigidWall
from .damped import DampedVerlet, default_timestep, pair_stability_limit, stability_limit

__all__ = ["DampedVerlet", "Piston", "RigidWall", "default_timestep", "pair_stability_limit", "stability_limit"]
