"""Removing the particles that leave a region of interest: :class:`RegionOfInterest` (the box)
and :class:`Removal`, the piece of :class:`clusterdyn.md.DampedVerlet` that takes them out every
few steps and books what they carry away."""

import numpy as np

from ..errors import InputError
from . import _integrate as I
from .drives import _Layer
from .pieces import Piece


class RegionOfInterest:
    """An axis-aligned box; particles that leave it can be removed from a run.

    A particle is inside when ``lo <= x <= hi`` on every axis (NaN is outside).
    Used by :class:`DampedVerlet` (``region=``): every ``remove_interval``
    steps the particles outside are taken out of the Atoms, and the kinetic
    energy, pair energy and momentum they carry away are booked in
    :meth:`DampedVerlet.energy_ledger`.

    Parameters
    ----------
    lo, hi : (3,) array-like, Angstrom
        Corners; ``-inf`` / ``inf`` (or None for the whole vector) leave an
        axis unbounded.  Periodic axes must be unbounded.
    """

    def __init__(self, lo=None, hi=None):
        self.lo = self._corner("lo", lo, -np.inf)
        self.hi = self._corner("hi", hi, np.inf)
        if np.any(self.hi < self.lo):
            raise InputError("hi", self.hi.tolist(), f">= lo = {self.lo.tolist()} on every axis")

    @staticmethod
    def _corner(name, v, default):
        if v is None:
            return np.full(3, default)
        try:
            a = np.array(v, dtype=float).reshape(3)
        except (TypeError, ValueError):
            raise InputError(name, v, "three numbers (Angstrom; +-inf for an unbounded axis)") from None
        if np.any(np.isnan(a)):
            raise InputError(name, v, "three numbers (Angstrom; +-inf for an unbounded axis), no NaN")
        return a

    def inside(self, positions):
        """(N,) bool: particles within the box."""
        return ~self.outside(positions)[0]

    def outside(self, positions):
        """((N,) bool, count): particles outside the box (one pass)."""
        x = np.ascontiguousarray(positions, dtype=np.float64)
        out = np.empty(x.shape[0], np.bool_)
        return out, int(I.outside_box(x.reshape(-1, 3), self.lo, self.hi, out))

    def todict(self):
        return {"kind": "RegionOfInterest", "lo": self.lo.tolist(), "hi": self.hi.tolist()}

    @classmethod
    def fromdict(cls, d):
        return cls(d["lo"], d["hi"])

    def __repr__(self):
        return f"RegionOfInterest(lo={self.lo.tolist()}, hi={self.hi.tolist()})"


#: rows moved at a time by :func:`_compact`
COMPACT_ROWS = 65536


def _compact(a, keep):
    """The rows ``keep`` (ascending) of ``a``, moved to its front in place: a view of its first
    ``len(keep)`` rows.  Nothing of the array's size is allocated (rows are moved a block at a
    time; row keep[t] >= t, so a block reads only rows no earlier block has written), which keeps
    removing particles from raising the peak memory; the memory of the removed rows is not given
    back (the Atoms' arrays keep their size at the start of the run)."""
    k = keep.size
    if not a.flags.c_contiguous:
        return np.ascontiguousarray(a[keep])
    for s in range(0, k, COMPACT_ROWS):
        e = min(s + COMPACT_ROWS, k)
        a[s:e] = a[keep[s:e]]
    return a[:k]


class Removal(Piece):
    """Every ``interval`` steps (at the end of a step) take the particles outside ``region`` out
    of the Atoms (:meth:`remove`); particles of pistons and tractions are kept.

    :attr:`removed` books what they took away since the start: count, mass (amu), kinetic and
    pair energy (eV), momentum (3,) (amu Angstrom / ASE time)."""

    name = "removal"
    #: removal runs before sorting at the end of a step
    order = 10

    def __init__(self, region, interval):
        self.region = region
        self.interval = interval
        self.removed = {"count": 0, "mass": 0.0, "kinetic": 0.0, "potential": 0.0, "momentum": np.zeros(3)}

    def end_step(self):
        if (self.dyn.nsteps + 1) % self.interval == 0:
            self.remove()

    def remove(self):
        """Take the particles outside the region out now; returns how many.

        Their kinetic energy, momentum and pair energy (potential energy before minus after:
        their bonds to the rest and among themselves) are added to :attr:`removed`; the dynamics
        takes them out of the Atoms and of its forces (:meth:`clusterdyn.md.DampedVerlet.take_out`).
        """
        dyn = self.dyn
        atoms = dyn.atoms
        out, nout = self.region.outside(atoms.arrays["positions"])
        if nout == 0:
            return 0
        for d in dyn._drives():
            if isinstance(d, _Layer):
                out[d.index] = False
        if not out.any():
            return 0
        gone = np.flatnonzero(out)
        keep = np.flatnonzero(~out)
        if keep.size == 0:
            raise InputError("region", repr(self.region), "a region that keeps at least one particle",
                             hint=f"all {len(atoms)} particles are outside at step {dyn.nsteps}")
        if dyn.forces is None:
            dyn._refresh_properties()
        p = atoms.arrays["momenta"]
        m = atoms.get_masses()
        k_gone = 0.5 * float(((p[gone] ** 2).sum(axis=1) / m[gone]).sum())
        p_gone = p[gone].sum(axis=0)
        u_before, u_after = dyn.take_out(out, keep)
        r = self.removed
        r["count"] += int(gone.size)
        r["mass"] += float(m[gone].sum())
        r["kinetic"] += k_gone
        r["potential"] += float(u_before - u_after)
        r["momentum"] = r["momentum"] + p_gone
        return int(gone.size)

    def get_state(self):
        r = self.removed
        return {"removed": {"count": r["count"], "mass": r["mass"], "kinetic": r["kinetic"],
                            "potential": r["potential"], "momentum": np.array(r["momentum"], dtype=float)},
                "region": dict(self.region.todict(), remove_interval=self.interval)}
