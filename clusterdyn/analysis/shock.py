"""Shock analysis: binned profiles along the shock direction, front tracking, the state behind the front.

Conventions (docs/theory.md 1.4-1.5): stresses are tension-positive; the
longitudinal stress behind the front is ``P = -sigma_xx`` with the virial
and kinetic parts (kinetic part about the bin's mean velocity).  D is the
lab-frame speed of the front into material at rest.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import units
from ..io.lammps.export import META_FILE
from ..io.lammps.run import frame_atoms
from .slabs import binned_profile
from .stress import von_mises


def front_position(x, u_axis, u_piston, fraction=0.5, support=0):
    """Position of the shock front along the profile.

    The furthest slab whose particle velocity reaches ``fraction * u_piston``
    and is backed by ``support`` slabs behind it that reach it too, searched
    from the far end; linear interpolation to the next slab.  ``support=0``
    (default) is the plain furthest crossing, which follows the leading
    oscillation of a weak lattice shock; ``support=2`` skips single slabs of
    clusters thrown ahead of the front (planes slipping through each other at
    high u), which :func:`ejecta_ahead` counts.
    """
    thr = fraction * u_piston
    ok = np.asarray(u_axis) >= thr
    backed = ok.copy()
    for s in range(1, int(support) + 1):
        backed[s:] &= ok[:-s]
        backed[:s] = False
    above = np.nonzero(backed)[0]
    if len(above) == 0:
        above = np.nonzero(ok)[0]
        if len(above) == 0:
            return np.nan
    k = above.max()
    if k + 1 >= len(x):
        return x[k]
    u1, u2 = u_axis[k], u_axis[k + 1]
    if u1 == u2 or u2 >= thr:
        return x[k]
    return x[k] + (x[k + 1] - x[k]) * (u1 - thr) / (u1 - u2)


def ejecta_ahead(profile, front, axis=0, fraction=0.5, u_piston=None):
    """Mass in slabs ahead of ``front`` moving faster than ``fraction * u_piston`` (amu)."""
    v = profile["velocity"][:, axis]
    ahead = (profile["x"] > front + profile["width"]) & (v >= fraction * u_piston)
    return float(profile["mass"][ahead].sum())


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


#: A run is steady when (docs/theory.md 1.5, docs/hugoniot.md) the front position is linear in
#: time -- rms residual of the line at most STEADY_FIT_RMS slab widths and D from the first and
#: second half of the fit window within STEADY_D_HALVES of each other -- and the mean particle
#: velocity behind the front is within STEADY_U_TOL of the piston speed.
STEADY_FIT_RMS = 0.5
STEADY_D_HALVES = 0.03
STEADY_U_TOL = 0.03
#: fewest frames in the fit window (the two halves need three each)
STEADY_MIN_FRAMES = 6


@dataclass
class ShockState:
    """The state behind a shock front, from a run's frames (ASE units).

    Attributes
    ----------
    D_fit, D_fit_err : float
        Front speed from the straight-line fit of front position against time,
        and the standard error of the slope (Angstrom/ASE time).
    fit_rms : float
        Rms residual of that fit (Angstrom); ``fit_rms / width`` in slabs.
    D_halves : (float, float)
        D fitted over the first and the second half of the fit window.
    u, u_spread : float
        Mass-weighted mean particle velocity along the shock in the steady
        region (between ``piston_gap`` slabs ahead of the piston and
        ``behind_gap`` slabs behind the front), mean and std over frames.
    rho, rho_spread : float
        Density there, from the Lagrangian compression ``dx/dX`` (slope of
        current against initial positions of the region's particles):
        ``rho = M / (dx/dX * V_rest)``.  Free of the plane-counting noise of slabs.
    rho_bins : float
        The same from the slab densities (for comparison).
    P, P_spread : float
        Longitudinal stress ``-sigma_xx`` of the region: virial plus kinetic
        part about each slab's mean velocity, over the region's current volume.
    sigma_u, sigma_u_spread : float
        Von Mises intensity (CD eq. 4) of the region's mean stress.
    D_mass, D_mass_spread : float
        D from mass conservation ``rho0 D = rho (D - u)``, i.e.
        ``D = u / (1 - dx/dX)``.  ``dx/dX`` is the least-squares slope of
        current against initial positions over the region, which is the mean
        local compression weighted by ``(X - Xa)(Xb - X)``; ``u`` here is the
        particle velocity averaged with the same weights, so that a steady wave
        of any profile (a ramped weak shock included) gives ``D_mass = D``
        exactly (``1 - dx/dX = u/D`` holds at every point of it).
    P_momentum : float
        ``rho0 D_fit u`` (momentum conservation), to compare with P.
    steady : bool
        See STEADY_FIT_RMS, STEADY_D_HALVES, STEADY_U_TOL.
    steady_reasons : list of str
        Why the run is not steady (empty when it is).
    ejecta : float
        Mean mass moving faster than half the piston speed ahead of the main
        front (the front found with ``support=2``: clusters thrown ahead, or
        the leading oscillation of a weak shock), in slabs of material at rest.
    """

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
    D_halves: tuple = (np.nan, np.nan)
    D_mass_spread: float = np.nan
    sigma_u: float = np.nan
    sigma_u_spread: float = np.nan
    rho_bins: float = np.nan
    width: float = np.nan
    steady_reasons: list = field(default_factory=list)
    ejecta: float = 0.0

    @property
    def mass_check(self):
        """``D_mass / D_fit - 1``."""
        return self.D_mass / self.D_fit - 1.0

    @property
    def momentum_check(self):
        """``P / (rho0 D u) - 1``."""
        return self.P / self.P_momentum - 1.0


def _line(t, x):
    A = np.vstack([t, np.ones_like(t)]).T
    (D, x0), *_ = np.linalg.lstsq(A, x, rcond=None)
    return float(D), float(x0)


class ShockTracker:
    """Collect profiles frame by frame and reduce them to a :class:`ShockState`.

    Every frame gives a slab profile (:func:`binned_profile`), the front
    position (:func:`front_position` at half the piston speed) and the state of
    the region between the piston and the front (particles more than
    ``piston_gap`` slabs ahead of the piston and ``behind_gap`` slabs behind
    the front): mean velocity, Lagrangian compression, stress.

    Parameters
    ----------
    rho0 : float
        Density ahead of the front (amu/A^3).
    u_piston : float
        Piston speed along +axis.
    width : float
        Slab width (Angstrom).
    axis : int
    lo, hi : float, optional
        Range of the slabs along ``axis``.
    rest_volume : (N,) array, optional
        Volume of each particle at rest (Angstrom^3); default ``m / rho0``.
        Two-phase samples pass each cluster's own ``r0^3 / sqrt(2)``.
    behind_gap, piston_gap : float
        Gaps (slab widths) that keep the front's ramp and the piston's
        start-up out of the averaged region.
    fit_from : float, optional
        Front travel (Angstrom from ``lo``) before which frames are left out
        of the fit and the averages: the start-up transient of the front
        (overdriven at first, then relaxing), whose length depends on the
        piston speed, not on the sample (:func:`clusterdyn.scenes.shock.shock_size`).
        The fit window starts at the larger of this and ``x_min_frac`` of the sample.

    The first frame added is the reference configuration (the Lagrangian
    coordinates ``X0`` of the compression ``dx/dX``): add it before the run starts.
    """

    def __init__(self, rho0, u_piston, width, axis=0, lo=None, hi=None, rest_volume=None,
                 behind_gap=3.0, piston_gap=3.0, fit_from=None):
        self.rho0, self.u_piston, self.width, self.axis = rho0, u_piston, width, axis
        self.lo, self.hi = lo, hi
        self.fit_from = None if fit_from is None else float(fit_from)
        self.rest_volume = None if rest_volume is None else np.asarray(rest_volume, float)
        self.behind_gap, self.piston_gap = float(behind_gap), float(piston_gap)
        self.X0 = None
        self.frames = []

    def get_state(self):
        """Everything needed to resume (for checkpoints)."""
        return {"rho0": self.rho0, "u_piston": self.u_piston, "width": self.width, "axis": self.axis,
                "lo": self.lo, "hi": self.hi, "frames": self.frames, "X0": self.X0,
                "rest_volume": self.rest_volume, "behind_gap": self.behind_gap,
                "piston_gap": self.piston_gap, "fit_from": self.fit_from}

    @classmethod
    def from_state(cls, st):
        t = cls(float(st["rho0"]), float(st["u_piston"]), float(st["width"]), int(st["axis"]),
                None if st["lo"] is None else float(st["lo"]), None if st["hi"] is None else float(st["hi"]),
                rest_volume=st.get("rest_volume"), behind_gap=float(st.get("behind_gap", 3.0)),
                piston_gap=float(st.get("piston_gap", 3.0)), fit_from=st.get("fit_from"))
        t.frames = [dict(f) for f in st["frames"]]
        if st.get("X0") is not None:
            t.X0 = np.asarray(st["X0"], float)
        return t

    def set_state(self, st):
        """Resume from :meth:`get_state` (in place)."""
        self.__dict__.update(type(self).from_state(st).__dict__)

    def add(self, time, atoms, virials, piston_x, exclude=None):
        """Record one frame; returns the front position (nan if none)."""
        ax = self.axis
        if self.X0 is None:
            self.X0 = atoms.positions[:, ax].copy()
        if self.rest_volume is None:
            self.rest_volume = atoms.get_masses() / self.rho0
        prof = binned_profile(atoms, virials, ax, self.width, self.lo, self.hi, exclude)
        u_ax = prof["velocity"][:, ax]
        xf = front_position(prof["x"], u_ax, self.u_piston)
        x2 = front_position(prof["x"], u_ax, self.u_piston, support=2)
        frame = {"t": float(time), "front": float(xf), "piston": float(piston_x), "profile": prof,
                 "ejecta_mass": ejecta_ahead(prof, x2, ax, u_piston=self.u_piston) if np.isfinite(x2) else 0.0}
        frame.update(self._region(atoms, virials, prof, xf, piston_x, exclude))
        self.frames.append(frame)
        return xf

    def _region(self, atoms, virials, prof, xf, piston_x, exclude):
        ax = self.axis
        nan = {"n_region": 0, "u_region": np.nan, "slope": np.nan, "rho_region": np.nan,
               "stress_region": np.full(6, np.nan)}
        if not np.isfinite(xf):
            return nan
        x = atoms.positions[:, ax]
        keep = np.ones(len(atoms), bool) if exclude is None else ~np.asarray(exclude, bool)
        a = piston_x + self.piston_gap * self.width
        b = xf - self.behind_gap * self.width
        sel = keep & (x > a) & (x < b)
        X0 = self.X0[sel]
        if sel.sum() < 8 or np.ptp(X0) < 2 * self.width:
            return nan
        m = atoms.get_masses()[sel]
        v = atoms.get_velocities()[sel]
        M = m.sum()
        vbar = (m[:, None] * v).sum(axis=0) / M
        slope = np.polyfit(X0, x[sel], 1)[0]
        # the least-squares slope is the mean local compression dx/dX with weights
        # (X - Xa)(Xb - X) per particle; mass conservation pairs it with the velocity
        # averaged with the same weights (see ShockState.D_mass)
        wq = (X0 - X0.min()) * (X0.max() - X0)
        u_fit = float((wq * v[:, ax]).sum() / wq.sum())
        V = slope * self.rest_volume[sel].sum()
        # kinetic part about each slab's mean velocity (as in the profile)
        edges = prof["edges"]
        k = np.clip(np.floor((x[sel] - edges[0]) / self.width).astype(np.int64), 0, len(prof["x"]) - 1)
        dv = v - prof["velocity"][k]
        pairs = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
        W = np.array([-(m * dv[:, p] * dv[:, q]).sum() for p, q in pairs])
        if virials is not None:
            W = W + np.asarray(virials)[sel].sum(axis=0)
        return {"n_region": int(sel.sum()), "u_region": float(vbar[ax]), "u_fit": u_fit, "slope": float(slope),
                "rho_region": float(M / V), "stress_region": W / V}

    def fit_window(self, x_min_frac=0.2, x_max_frac=0.85):
        """The front positions ``(a, b)`` (Angstrom) between which frames are fitted and averaged:
        ``a = lo + max(x_min_frac L, fit_from)``, ``b = lo + x_max_frac L`` (L the slabs' span)."""
        lo = self.frames[0]["profile"]["edges"][0]
        hi = self.frames[0]["profile"]["edges"][-1]
        L = hi - lo
        a = max(x_min_frac * L, self.fit_from or 0.0)
        return lo + a, lo + x_max_frac * L

    def result(self, x_min_frac=0.2, x_max_frac=0.85):
        """Fit D over the frames with the front in :meth:`fit_window`, and average the state
        of the region behind the front over the same frames.
        """
        if not self.frames:
            raise ValueError("no frames recorded")
        ax = self.axis
        notes = []
        t = np.array([f["t"] for f in self.frames])
        xf = np.array([f["front"] for f in self.frames])
        a, b = self.fit_window(x_min_frac, x_max_frac)
        use = np.isfinite(xf) & (xf > a) & (xf < b)
        n_window = int(use.sum())
        if n_window < 3:
            lo = self.frames[0]["profile"]["edges"][0]
            notes.append(f"only {int(use.sum())} frames with the front between {(a - lo) / self.width:.1f} and "
                         f"{(b - lo) / self.width:.1f} slabs of the sample; fit uses all frames with a front")
            use = np.isfinite(xf)
        D, x0, rms = fit_front(t[use], xf[use])
        tt = t[use]
        D_err = rms / np.sqrt(((tt - tt.mean()) ** 2).sum()) if len(tt) > 2 else np.nan
        halves = (np.nan, np.nan)
        if len(tt) >= STEADY_MIN_FRAMES:
            h = len(tt) // 2
            halves = (_line(tt[:h], xf[use][:h])[0], _line(tt[h:], xf[use][h:])[0])
        frames = [f for f, ok in zip(self.frames, use) if ok and f.get("n_region", 0) > 0]
        # the binned density, for comparison
        rb = []
        for f in frames:
            p = f["profile"]
            sel = ((p["x"] > f["piston"] + self.piston_gap * self.width)
                   & (p["x"] < f["front"] - self.behind_gap * self.width) & (p["count"] > 0))
            if sel.sum():
                rb.append(p["density"][sel].mean())
        if not frames:
            notes.append("no steady region between piston and front")
            us = rhos = Ps = sus = Dm = slopes = np.array([np.nan])
        else:
            us = np.array([f["u_region"] for f in frames])
            slopes = np.array([f["slope"] for f in frames])
            rhos = np.array([f["rho_region"] for f in frames])
            st = np.array([f["stress_region"] for f in frames])
            Ps = -st[:, ax]
            sus = von_mises(st)
            # frames recorded before the fit weights existed carry only u_region
            ufs = np.array([f.get("u_fit", f["u_region"]) for f in frames])
            with np.errstate(divide="ignore", invalid="ignore"):
                Dm = ufs / (1.0 - slopes)
        u = float(np.mean(us))
        s_mean = float(np.mean(slopes))
        u_fit = float(np.mean(ufs)) if frames else np.nan
        D_mass = u_fit / (1.0 - s_mean) if s_mean < 1.0 else np.nan
        reasons = []
        if not np.isfinite(D):
            reasons.append("no front fit")
        elif n_window < STEADY_MIN_FRAMES:
            reasons.append(f"only {n_window} frames in the fit window, {STEADY_MIN_FRAMES} needed: the sample is "
                           "too short for the front to settle")
        else:
            if not rms <= STEADY_FIT_RMS * self.width:
                reasons.append(f"front not linear in time (rms residual {rms / self.width:.2f} slabs > "
                               f"{STEADY_FIT_RMS})")
            if np.all(np.isfinite(halves)) and abs(halves[1] - halves[0]) > STEADY_D_HALVES * abs(D):
                reasons.append(f"D changes along the run ({halves[0] / D:.3f} D -> {halves[1] / D:.3f} D "
                               f"over the two halves of the fit)")
        if not abs(u - self.u_piston) <= STEADY_U_TOL * abs(self.u_piston):
            reasons.append(f"particle velocity behind the front {u / self.u_piston:.3f} of the piston "
                           f"speed (tolerance {STEADY_U_TOL:.0%})")
        ej = [f.get("ejecta_mass", 0.0) / (self.rho0 * f["profile"]["area"] * self.width)
              for f, ok in zip(self.frames, use) if ok]
        ejecta = float(np.mean(ej)) if ej else 0.0
        if ejecta > 0.05:
            notes.append(f"fast material ahead of the main front: {ejecta:.2f} slabs of material on average")
        steady = not reasons
        if not steady:
            notes.append("run not steady: " + "; ".join(reasons))
        return ShockState(
            D, float(D_err), rms, u, float(np.std(us)), float(np.mean(rhos)), float(np.std(rhos)),
            float(np.mean(Ps)), float(np.std(Ps)), float(D_mass), float(self.rho0 * D * u), self.rho0,
            self.u_piston, steady, int(use.sum()), notes, D_halves=tuple(float(h) for h in halves),
            D_mass_spread=float(np.std(Dm)), sigma_u=float(np.mean(sus)), sigma_u_spread=float(np.std(sus)),
            rho_bins=float(np.mean(rb)) if rb else np.nan, width=float(self.width), steady_reasons=reasons,
            ejecta=ejecta)


def hugoniot_interpolant(u, D):
    """D(u) through measured points: monotone cubic (PCHIP) inside, straight lines outside.

    Parameters
    ----------
    u, D : (n,) arrays
        Particle velocities and shock speeds (any consistent units), n >= 2.

    Returns
    -------
    callable ``D(u)`` accepting scalars or arrays.
    """
    from scipy.interpolate import PchipInterpolator
    u = np.asarray(u, float)
    D = np.asarray(D, float)
    ok = np.isfinite(u) & np.isfinite(D)
    u, D = u[ok], D[ok]
    order = np.argsort(u)
    u, D = u[order], D[order]
    if len(u) < 2:
        raise ValueError("a Hugoniot interpolant needs at least two points")
    inner = PchipInterpolator(u, D, extrapolate=False)
    s_lo = (D[1] - D[0]) / (u[1] - u[0])
    s_hi = (D[-1] - D[-2]) / (u[-1] - u[-2])

    def f(x):
        x = np.asarray(x, float)
        y = np.where(x < u[0], D[0] + s_lo * (x - u[0]),
                     np.where(x > u[-1], D[-1] + s_hi * (x - u[-1]), inner(np.clip(x, u[0], u[-1]))))
        return y if y.ndim else float(y)
    return f


def mixture_D(u, phases, closure="equal_u"):
    """Shock speed of a mixture at particle velocity ``u`` (Kuropatenko's rule, docs/theory.md 1.6).

    .. math::

        \\frac{1}{D - u} = \\sum_i \\frac{\\alpha_i}{D_i - u_i}

    with ``alpha_i`` the shocked volume fractions.  Two closures:

    ``equal_u``
        every phase has the mixture's ``u``; the rule is then exactly
        ``1/D = sum_i phi0_i / D_i(u)`` with the initial volume fractions ``phi0_i``.
    ``equal_p``
        the phases are at one pressure ``P``, each on its own Hugoniot
        (``P = rho0_i D_i u_i``), and their specific volumes add
        (``v = sum_i w_i v_i``); the mixture's ``u`` and ``D`` follow from
        ``P = rho0 D u`` and ``v/v0 = 1 - u/D``.

    Parameters
    ----------
    u : float
        Mixture particle velocity (any units, consistent with ``D_i``).
    phases : sequence of (mass_fraction, rho0, D_of_u)
        Mass fraction, initial density and Hugoniot ``D_i(u_i)`` (callable) of each phase.
    closure : "equal_u" or "equal_p"

    Returns
    -------
    float
    """
    from scipy.optimize import brentq
    w = np.array([p[0] for p in phases], float)
    w = w / w.sum()
    v0i = 1.0 / np.array([p[1] for p in phases], float)
    Df = [p[2] for p in phases]
    v0 = float((w * v0i).sum())
    phi0 = w * v0i / v0
    if closure == "equal_u":
        return float(1.0 / sum(p / float(d(u)) for p, d in zip(phi0, Df)))
    if closure != "equal_p":
        raise ValueError(f"closure={closure!r}: expected 'equal_u' or 'equal_p'")
    if u <= 0:
        return float(1.0 / sum(p / float(d(0.0)) for p, d in zip(phi0, Df)))

    def phase_u(P, v0_, d):
        f = lambda x: x * float(d(x)) / v0_ - P      # noqa: E731
        hi = max(u, 1e-9)
        while f(hi) < 0:
            hi *= 2.0
            if hi > 1e6 * max(u, 1.0):
                raise ValueError("no particle velocity reaches this pressure on the phase's Hugoniot")
        return brentq(f, 0.0, hi, xtol=1e-14 * hi)

    def mix(P):
        v = 0.0
        for wi, v0_, d in zip(w, v0i, Df):
            ui = phase_u(P, v0_, d)
            v += wi * v0_ * (1.0 - ui / float(d(ui)))
        dv = v0 - v
        return np.sqrt(P * dv), v0 * np.sqrt(P / dv)

    P_hi = u * float(Df[0](u)) / v0
    while mix(P_hi)[0] < u:
        P_hi *= 2.0
    P = brentq(lambda P: mix(P)[0] - u, 1e-12 * P_hi, P_hi, xtol=1e-13 * P_hi)
    return float(mix(P)[1])


def shock_from_lammps(run, template, piston_mask, rho0, u, slab, length, x_lo, axis=0, rest_volume=None,
                      fit_from=None):
    """Shock front analysis (:class:`clusterdyn.analysis.shock.ShockTracker`) of a LAMMPS run's frames.

    ``axis``: the shock direction (0, 1, 2); ``rest_volume``: (N,) rest volume
    of each cluster for a two-phase sample (as the live run's tracker); ``fit_from``:
    the start of the fit window, as the clusterdyn run's."""
    tracker = ShockTracker(rho0, u, slab, axis=axis, lo=x_lo, hi=x_lo + length + slab, rest_volume=rest_volume,
                           fit_from=fit_from)
    dt_ps = None
    meta = json.loads((Path(run.folder) / META_FILE).read_text())
    dt_ps = meta["dt_ps"]
    for fr in run.frames:
        a, vir = frame_atoms(template, fr)
        t = fr["step"] * dt_ps * units.PS
        pist = a.positions[piston_mask, axis].max()
        tracker.add(t, a, vir, pist, exclude=piston_mask)
    return tracker, tracker.result()
