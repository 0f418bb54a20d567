"""Shock analysis: binned profiles along the shock direction, front tracking, the state behind the front.

Conventions (physics.md 1.4-1.5): stresses are tension-positive; the
longitudinal stress behind the front is ``P = -sigma_xx`` with the virial
and kinetic parts (kinetic part about the bin's mean velocity).  D is the
lab-frame speed of the front into material at rest.
"""

from dataclasses import dataclass, field

import numpy as np


def binned_profile(atoms, virials=None, axis=0, width=None, lo=None, hi=None, exclude=None):
    """Profiles of density, velocity and stress in slabs normal to ``axis``.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic (or at least with a 3-D cell) across the two other axes; the
        cross-section is the cell's.
    virials : (N, 6) array, optional
        Per-particle potential virials (Voigt xx yy zz yz xz xy, eV), e.g.
        ``calc.get_property('virials', atoms)``.  Without them only the
        kinetic part of the stress is returned.
    width : float
        Slab width, Angstrom.
    lo, hi : float
        Range along ``axis`` (default: the particles' extent).
    exclude : bool mask, optional
        Particles left out (e.g. a piston layer).

    Returns
    -------
    dict with ``x`` (slab centres), ``count``, ``mass``, ``density`` (amu/A^3),
    ``velocity`` ((nb, 3) mean velocity, A/time), ``stress`` ((nb, 6) virial +
    kinetic, eV/A^3, tension positive), ``width``, ``area``.
    """
    pos = atoms.positions[:, axis]
    m = atoms.get_masses()
    v = atoms.get_velocities()
    keep = np.ones(len(atoms), bool) if exclude is None else ~np.asarray(exclude, bool)
    if lo is None:
        lo = pos[keep].min()
    if hi is None:
        hi = pos[keep].max() + 1e-9 * max(1.0, abs(pos).max())
    nb = max(1, int(np.ceil((hi - lo) / width)))
    edges = lo + width * np.arange(nb + 1)
    idx = np.floor((pos - lo) / width).astype(np.int64)
    keep &= (idx >= 0) & (idx < nb)
    idx = idx[keep]
    mk, vk = m[keep], v[keep]
    others = [d for d in range(3) if d != axis]
    cell = atoms.cell.array
    area = abs(np.linalg.det(cell[np.ix_(others, others)])) if atoms.cell.rank == 3 else np.nan
    vol = area * width
    count = np.bincount(idx, minlength=nb)
    mass = np.bincount(idx, weights=mk, minlength=nb)
    mom = np.stack([np.bincount(idx, weights=mk * vk[:, c], minlength=nb) for c in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        vel = mom / mass[:, None]
    vel[mass == 0] = 0.0
    dv = vk - vel[idx]
    pairs = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    stress = np.zeros((nb, 6))
    for c, (p, q) in enumerate(pairs):
        stress[:, c] = -np.bincount(idx, weights=mk * dv[:, p] * dv[:, q], minlength=nb)
        if virials is not None:
            stress[:, c] += np.bincount(idx, weights=np.asarray(virials)[keep, c], minlength=nb)
    # the profile's axis becomes "xx": permute so that component 0 is along `axis`
    stress /= vol
    return {"x": 0.5 * (edges[1:] + edges[:-1]), "edges": edges, "count": count, "mass": mass,
            "density": mass / vol, "velocity": vel, "stress": stress, "width": width, "area": area}


def front_position(x, u_axis, u_piston, fraction=0.5):
    """Position of the shock front: the furthest point where the particle velocity
    along the shock reaches ``fraction * u_piston`` (linear interpolation
    between slabs, searched from the far end)."""
    thr = fraction * u_piston
    above = np.nonzero(u_axis >= thr)[0]
    if len(above) == 0:
        return np.nan
    k = above.max()
    if k + 1 >= len(x):
        return x[k]
    u1, u2 = u_axis[k], u_axis[k + 1]
    if u1 == u2:
        return x[k]
    return x[k] + (x[k + 1] - x[k]) * (u1 - thr) / (u1 - u2)


def fit_front(times, fronts):
    """Least-squares line through (t, x_front): returns (D, x0, rms residual)."""
    t = np.asarray(times, float)
    x = np.asarray(fronts, float)
    ok = np.isfinite(x)
    t, x = t[ok], x[ok]
    if len(t) < 3:
        return np.nan, np.nan, np.nan
    A = np.vstack([t, np.ones_like(t)]).T
    (D, x0), *_ = np.linalg.lstsq(A, x, rcond=None)
    res = x - (D * t + x0)
    return float(D), float(x0), float(np.sqrt(np.mean(res ** 2)))


@dataclass
class ShockState:
    """The state behind a shock front, from a run's frames (ASE units)."""

    D_fit: float
    D_fit_err: float
    fit_rms: float
    u: float
    u_spread: float
    rho: float
    rho_spread: float
    P: float
    P_spread: float
    D_mass: float
    P_momentum: float
    rho0: float
    u_piston: float
    steady: bool
    n_frames: int
    notes: list = field(default_factory=list)


class ShockTracker:
    """Collect profiles frame by frame and reduce them to a :class:`ShockState`.

    Parameters
    ----------
    rho0 : float
        Density ahead of the front (amu/A^3).
    u_piston : float
        Piston speed along +axis.
    width : float
        Slab width (Angstrom).
    axis : int
    """

    def __init__(self, rho0, u_piston, width, axis=0, lo=None, hi=None):
        self.rho0, self.u_piston, self.width, self.axis = rho0, u_piston, width, axis
        self.lo, self.hi = lo, hi
        self.frames = []

    def get_state(self):
        """Everything needed to resume (for checkpoints)."""
        return {"rho0": self.rho0, "u_piston": self.u_piston, "width": self.width, "axis": self.axis,
                "lo": self.lo, "hi": self.hi, "frames": self.frames}

    @classmethod
    def from_state(cls, st):
        t = cls(float(st["rho0"]), float(st["u_piston"]), float(st["width"]), int(st["axis"]),
                None if st["lo"] is None else float(st["lo"]), None if st["hi"] is None else float(st["hi"]))
        t.frames = [dict(f) for f in st["frames"]]
        return t

    def add(self, time, atoms, virials, piston_x, exclude=None):
        prof = binned_profile(atoms, virials, self.axis, self.width, self.lo, self.hi, exclude)
        u_ax = prof["velocity"][:, self.axis]
        xf = front_position(prof["x"], u_ax, self.u_piston)
        self.frames.append({"t": time, "front": xf, "piston": piston_x, "profile": prof})
        return xf

    def result(self, x_min_frac=0.2, x_max_frac=0.85, behind_gap=3.0, piston_gap=3.0):
        """Fit D over frames with the front between the given fractions of the sample length,
        and average the state between the piston and the front (gaps in slab widths).
        """
        if not self.frames:
            raise ValueError("no frames recorded")
        lo = self.frames[0]["profile"]["edges"][0]
        hi = self.frames[0]["profile"]["edges"][-1]
        L = hi - lo
        notes = []
        t = np.array([f["t"] for f in self.frames])
        xf = np.array([f["front"] for f in self.frames])
        use = np.isfinite(xf) & (xf > lo + x_min_frac * L) & (xf < lo + x_max_frac * L)
        if use.sum() < 3:
            notes.append(f"only {int(use.sum())} frames with the front in {x_min_frac:.2f}-"
                         f"{x_max_frac:.2f} of the sample; fit uses all frames with a front")
            use = np.isfinite(xf)
        D, x0, rms = fit_front(t[use], xf[use])
        # standard error of the slope
        tt = t[use]
        D_err = rms / np.sqrt(((tt - tt.mean()) ** 2).sum()) if len(tt) > 2 else np.nan
        us, rhos, Ps = [], [], []
        ax = self.axis
        for f in np.array(self.frames, dtype=object)[use]:
            p = f["profile"]
            a = f["piston"] + piston_gap * self.width
            b = f["front"] - behind_gap * self.width
            sel = (p["x"] > a) & (p["x"] < b) & (p["count"] > 0)
            if sel.sum() < 2:
                continue
            w = p["mass"][sel]
            us.append(np.average(p["velocity"][sel, ax], weights=w))
            rhos.append(p["density"][sel].mean())
            Ps.append(-p["stress"][sel, ax].mean())
        if not us:
            notes.append("no steady region between piston and front")
            us, rhos, Ps = [np.nan], [np.nan], [np.nan]
        u = float(np.mean(us))
        rho = float(np.mean(rhos))
        P = float(np.mean(Ps))
        D_mass = rho * u / (rho - self.rho0) if rho > self.rho0 else np.nan
        steady = bool(np.isfinite(D) and abs(u - self.u_piston) <= 0.03 * abs(self.u_piston)
                      and rms < 0.5 * self.width * 4)
        if not steady:
            notes.append("run not steady: front not linear in time or particle velocity behind the "
                         "front more than 3% from the piston speed")
        return ShockState(D, float(D_err), rms, u, float(np.std(us)), rho, float(np.std(rhos)), P,
                          float(np.std(Ps)), float(D_mass), float(self.rho0 * D * u), self.rho0,
                          self.u_piston, steady, int(use.sum()), notes)
