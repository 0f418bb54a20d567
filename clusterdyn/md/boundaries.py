"""Boundary conditions as ASE constraints: a piston driven at a prescribed velocity, a rigid wall.

They work in clusterdyn's dynamics and in ASE's own (VelocityVerlet, FIRE).
They deliberately have no ``todict()``: ASE can only rebuild constraints it
knows, so boundary conditions are recorded in H5MD metadata and checkpoints.
"""

import numpy as np

from ..errors import InputError
from ._integrate import set_momenta, take_forces


def _masses(atoms):
    m = atoms.arrays.get("masses")
    return m if m is not None else atoms.get_masses()


def _f64(a):
    return isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 2 and a.shape[1] == 3


class Piston:
    """A layer of particles moving at a constant velocity.

    The momenta of the layer are held at ``m * velocity``; the forces on it are
    recorded (:attr:`force`, the reaction of the sample on the piston, eV/Angstrom)
    and then zeroed.

    Parameters
    ----------
    indices : array of int or bool mask
        Particles of the layer (rows of the Atoms).
    velocity : float or (3,) array
        Velocity, Angstrom/ASE-time; a float means along +x.
    """

    def __init__(self, indices, velocity):
        idx = np.asarray(indices)
        if idx.dtype == bool:
            idx = np.nonzero(idx)[0]
        self.index = np.asarray(idx, dtype=np.int64)
        if self.index.size == 0:
            raise InputError("indices", "[]", "at least one particle in the piston layer")
        v = np.asarray(velocity, dtype=float)
        if v.ndim == 0:
            v = np.array([float(v), 0.0, 0.0])
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise InputError("velocity", velocity, "a finite number or 3-vector (Angstrom/ASE time)")
        self.velocity = v
        self.force = np.zeros(3)

    def adjust_positions(self, atoms, new):
        pass

    def adjust_momenta(self, atoms, momenta):
        m = _masses(atoms)
        if _f64(momenta) and m.dtype == np.float64:
            set_momenta(momenta, m, self.index, self.velocity)
        else:
            momenta[self.index] = m[self.index, None] * self.velocity[None, :]

    def adjust_forces(self, atoms, forces):
        if _f64(forces):
            f = np.empty(3)
            take_forces(forces, self.index, f)
            self.force = f
        else:
            self.force = forces[self.index].sum(axis=0).copy()
            forces[self.index] = 0.0

    def get_removed_dof(self, atoms):
        return 3 * len(self.index)

    def index_shuffle(self, atoms, ind):
        ind = np.asarray(ind)
        if ind.dtype == bool:
            ind = np.nonzero(ind)[0]
        pos = {int(old): new for new, old in enumerate(ind)}
        kept = [pos[i] for i in self.index if int(i) in pos]
        if not kept:
            raise IndexError("no piston particle left")
        self.index = np.array(kept, dtype=np.int64)

    def copy(self):
        c = Piston(self.index.copy(), self.velocity.copy())
        c.force = self.force.copy()
        return c

    def get_state(self):
        return {"kind": type(self).__name__, "index": self.index, "velocity": self.velocity,
                "force": self.force}

    def __repr__(self):
        return f"{type(self).__name__}({len(self.index)} particles, velocity={self.velocity.tolist()})"


class RigidWall(Piston):
    """A layer of particles held at rest (a piston with zero velocity)."""

    def __init__(self, indices):
        super().__init__(indices, 0.0)

    def copy(self):
        c = RigidWall(self.index.copy())
        c.force = self.force.copy()
        return c
