"""Dynamics (ASE MolecularDynamics subclasses) and the drive and wall family."""

from .damped import DampedVerlet, RegionOfInterest, default_timestep, pair_stability_limit, stability_limit
from .drives import Constant, Drive, Function, Piston, Table, Traction, Wall, from_state

__all__ = ["DampedVerlet", "RegionOfInterest", "Piston", "Wall", "Traction", "Table", "Constant", "Function", "Drive",
           "from_state", "default_timestep", "pair_stability_limit", "stability_limit"]
