"""Dynamics (ASE MolecularDynamics subclasses) and the drive and wall family."""

from .damped import DampedVerlet, RegionOfInterest, default_timestep, pair_stability_limit, stability_limit
from .drives import Drive, from_state
from .histories import Constant, Function, SmoothRamp, Table
from .layer_drives import Piston, Traction
from .wall import Wall
from .pulses import flat_top
from .pieces import Piece
from .boundary import BoundaryLaw, BoundaryTerm  # noqa: E402  (registers the piece kind for checkpoints)

__all__ = ["DampedVerlet", "RegionOfInterest", "Piston", "Wall", "Traction", "Table", "Constant", "SmoothRamp", "Function", "Drive",
           "from_state", "default_timestep", "pair_stability_limit", "stability_limit",
           "flat_top", "Piece", "BoundaryLaw", "BoundaryTerm"]
