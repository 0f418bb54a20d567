"""Spall: the pullback of a free-surface velocity history, the spall strength and the spall plane.

docs/theory.md 1.8.  A plate (the target) hit by a thinner flyer sends a
compression pulse to its rear free surface; the releases from the flyer's
rear and from the target's rear meet inside the target and put it in
tension.  What is measured here:

* :func:`pullback`: from the rear free-surface velocity ``u_fs(t)`` (the
  VISAR trace), the arrival, the first maximum ``u_max``, the minimum
  ``u_min`` before the velocity rises again (the spall signal, when the target
  has broken), the pullback ``du = u_max - u_min`` and the unloading strain
  rate ``-(du_fs/dt) / (2 c)``;
* :func:`spall_strength`: ``sigma_sp = rho0 c du / 2`` (acoustic
  approximation; give ``c`` as the bulk speed c_b and as the lattice's
  longitudinal speed c_L);
* :class:`LagrangianMap`: the longitudinal virial stress binned by the
  particles' positions at the start (material coordinates), frame by frame,
  so that fronts are tracked in the material and their speeds are Lagrangian
  (speeds relative to the material ahead of them);
* :func:`wave_speeds`: on that map, the shock front and the two releases
  (the one from the flyer's rear running forward, the one reflected from the
  target's rear running back), tracked where the compression has fallen to
  ``level`` of the pulse's amplitude and each fitted by a straight line;
  where the two releases cross the target goes into tension from both
  sides, and that is where the spall plane is expected (in the acoustic
  picture, one flyer thickness from the rear face);
* :func:`spall_plane`: the spall plane of the final configuration, from the
  fragments: the scab is the fragment holding most of the target's rear
  layer, and its thickness (Lagrangian, from its share of the target's
  clusters) is the spall plane's distance from the rear face;
* :func:`ring_thickness`: the scab thickness the VISAR's reverberation gives
  (``c T / 2`` with T the period of the free-surface oscillation after the
  spall signal), the experimentalists' estimate.
"""

import math

import numpy as np

from ..errors import InputError

__all__ = ["pullback", "spall_strength", "LagrangianMap", "wave_speeds", "spall_plane", "ring_thickness"]


def _crossing(t, u, level, start, rising=True):
    """First time at or after index ``start`` where u crosses ``level`` (linear interpolation)."""
    for k in range(max(start, 1), len(u)):
        a, b = u[k - 1], u[k]
        if (rising and a <= level < b) or (not rising and a >= level > b):
            return float(t[k - 1] + (level - a) / (b - a) * (t[k] - t[k - 1]))
    return float("nan")


def pullback(t, u, u_ref, pulse=None, rise=0.05, c=None):
    """Pullback of a free-surface velocity history.

    Parameters
    ----------
    t, u : (K,) arrays
        Times and free-surface velocities (any consistent units).
    u_ref : float
        Scale of the trace (the impact speed of a symmetric impact): the
        arrival is the first time u exceeds ``u_ref / 4`` (interpolated).
    pulse : float, optional
        Expected duration of the compression at the surface (e.g. 2 L_flyer / c_L): the first
        maximum is sought within 1.2 ``pulse`` of the arrival and the minimum between half a
        pulse and two pulses after it (default: the largest velocity after the arrival, and the
        first minimum after it that the velocity rises from by ``rise * u_max``).
    rise : float, default 0.05
        The velocity rising again: by more than ``rise * u_max`` above the minimum (a spall
        signal, or the whole plate's reverberation: whether the target broke is for its
        fragments to tell).
    c : float, optional
        Sound speed for the unloading strain rate ``-(du_fs/dt)/(2c)`` (between 20% and 80% of
        the drop).

    Returns
    -------
    dict
        ``t_arrival``, ``u_max``, ``t_max``, ``u_min``, ``t_min``, ``du``, ``spall_signal`` (bool:
        the velocity rose again after the minimum), ``t_signal`` (time it rose past
        ``u_min + rise * u_max``), ``strain_rate`` (1/time units, NaN without ``c``).  NaN
        where the trace has no arrival.
    """
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    nan = float("nan")
    out = {"t_arrival": nan, "u_max": nan, "t_max": nan, "u_min": nan, "t_min": nan, "du": nan,
           "spall_signal": False, "t_signal": nan, "strain_rate": nan}
    if len(t) < 3 or not u_ref > 0:
        return out
    up = np.nonzero(u > 0.25 * u_ref)[0]
    if not len(up):
        return out
    ka = int(up[0])
    out["t_arrival"] = _crossing(t, u, 0.25 * u_ref, max(ka, 1))
    if pulse is not None:
        win = np.nonzero((t >= t[ka]) & (t <= t[ka] + 1.2 * pulse))[0]
    else:
        win = np.arange(ka, len(u))
    km = int(win[np.argmax(u[win])])
    u_max = float(u[km])
    if pulse is not None:
        # the minimum within [t_a + pulse/2, t_a + 2 pulse]: wiggles of the plateau (a split wave's
        # arrivals) come before it, the scab's ringing after it
        seg = np.nonzero((t >= t[ka] + 0.5 * pulse) & (t <= t[ka] + 2.0 * pulse))[0]
        seg = seg[seg > km]
        k_min = int(seg[np.argmin(u[seg])]) if len(seg) else km
        run_min = float(u[k_min])
        up = np.nonzero(u[k_min + 1:] > run_min + rise * u_max)[0]
        k_sig = k_min + 1 + int(up[0]) if len(up) else None
    else:
        run_min, k_min, k_sig = u_max, km, None
        for k in range(km + 1, len(u)):
            if u[k] < run_min:
                run_min, k_min = float(u[k]), k
            elif u[k] > run_min + rise * u_max:
                k_sig = k
                break
    out.update({"u_max": u_max, "t_max": float(t[km]), "u_min": run_min, "t_min": float(t[k_min]),
                "du": u_max - run_min, "spall_signal": k_sig is not None})
    if k_sig is not None:
        out["t_signal"] = float(t[k_sig])
    if c is not None and u_max > run_min:
        seg = slice(km, k_min + 1)
        t80 = _crossing(t[seg], u[seg], u_max - 0.2 * (u_max - run_min), 1, rising=False)
        t20 = _crossing(t[seg], u[seg], u_max - 0.8 * (u_max - run_min), 1, rising=False)
        if math.isfinite(t80) and math.isfinite(t20) and t20 > t80:
            out["strain_rate"] = 0.6 * (u_max - run_min) / (t20 - t80) / (2.0 * c)
    return out


def spall_strength(rho0, c, du):
    """Spall strength in the acoustic approximation, ``rho0 c du / 2`` (units of the inputs:
    ASE density, speed and velocity give eV/Angstrom^3)."""
    return 0.5 * rho0 * c * du


class LagrangianMap:
    """Longitudinal virial stress per rest volume, binned by the particles' initial positions.

    Each :meth:`add` stores, per bin, ``sum_i W_i,aa / sum_i V_i`` (W the
    particles' potential virials, tension positive, eV/Angstrom^3): the
    stress of the material that started in the bin, per rest volume (it
    differs from the Cauchy stress by the bin's compression; the fronts'
    positions and speeds do not depend on it).

    Parameters
    ----------
    x0 : (N,) array, Angstrom
        Each particle's position along ``axis`` at the start (material coordinate).
    width : float, Angstrom
        Bin width.
    volume : (N,) array or float, Angstrom^3
        Rest volume of each particle (``r0^3 / sqrt 2`` for clusters).
    axis : int, default 0
        Direction of the material coordinate.
    """

    def __init__(self, x0, width, volume, axis=0):
        x0 = np.asarray(x0, float)
        if not width > 0:
            raise InputError("width", width, "a positive bin width, Angstrom")
        self.axis = int(axis)
        self.lo = float(x0.min()) - 0.5 * width
        n = int(np.floor((x0.max() - self.lo) / width)) + 1
        self.edges = self.lo + width * np.arange(n + 1)
        self.bin = np.clip(np.floor((x0 - self.lo) / width).astype(np.int64), 0, n - 1)
        vol = np.broadcast_to(np.asarray(volume, float), x0.shape)
        self.vol = np.bincount(self.bin, weights=vol, minlength=n)
        self.t, self.s = [], []

    @property
    def x(self):
        """Bin centres (material coordinate), Angstrom."""
        return 0.5 * (self.edges[1:] + self.edges[:-1])

    def add(self, virials, time):
        """Store one frame: ``virials`` (N, 6) potential virials (eV), ``time``."""
        w = np.bincount(self.bin, weights=np.asarray(virials)[:, self.axis], minlength=len(self.vol))
        with np.errstate(invalid="ignore", divide="ignore"):
            self.s.append(np.where(self.vol > 0, w / self.vol, np.nan))
        self.t.append(float(time))

    def arrays(self):
        """``{"t": (F,), "x": (B,), "stress": (F, B)}`` (tension positive)."""
        return {"t": np.asarray(self.t, float), "x": self.x, "stress": np.array(self.s).reshape(len(self.t), -1)}

    def get_state(self):
        return {"t": list(self.t), "s": [np.asarray(x) for x in self.s]}

    def set_state(self, st):
        self.t = [float(x) for x in st["t"]]
        self.s = [np.asarray(x, float) for x in st["s"]]


def _fit(t, x):
    if len(t) < 3:
        return float("nan"), float("nan")
    A = np.polyfit(t, x, 1)
    return float(A[0]), float(A[1])


def wave_speeds(lmap, x_impact, x_face, level=0.5):
    """Shock and release speeds in a target on a :class:`LagrangianMap`, and where the releases cross.

    Parameters
    ----------
    lmap : dict
        :meth:`LagrangianMap.arrays` of a flyer-on-target run (flyer at lower x).
    x_impact, x_face : float
        Material coordinates of the impact plane and of the target's rear face.
    level : float, default 0.5
        The releases are tracked where the compression has fallen to ``level`` of the pulse's
        amplitude.

    In each frame the compressed part of the target is where the compression
    exceeds ``level`` of the amplitude; its front edge is the shock (until it
    reaches the rear face) and then the release reflected from the rear face
    running back, its back edge the release from the flyer's rear running
    forward.  Each is fitted by a straight line over the frames where it lies
    more than two bins inside the target and within 60% of the target from
    its side, up to the frame where the compressed part vanishes; the lines'
    crossing is where the two releases meet.

    Returns
    -------
    dict
        ``amplitude`` (the 99th percentile of the compression in the target, per rest volume,
        > 0), ``D`` (shock, tracked at half the amplitude), ``c_forward``, ``c_backward``
        (release speeds, > 0), ``t_cross``, ``x_cross``, ``d_expected`` (``x_face - x_cross``),
        and the number of frames of each fit.  Speeds are Lagrangian (material coordinate per
        time); NaN where a wave is not seen in 3 frames.
    """
    t, x, S = lmap["t"], lmap["x"], -np.asarray(lmap["stress"])          # compression positive
    L = x_face - x_impact
    tgt = (x > x_impact) & (x < x_face)
    P = float(np.nanpercentile(S[:, tgt], 99)) if tgt.any() else float("nan")
    nan = float("nan")
    out = {"amplitude": P, "D": nan, "c_forward": nan, "c_backward": nan, "t_cross": nan, "x_cross": nan,
           "d_expected": nan, "n_shock": 0, "n_forward": 0, "n_backward": 0, "level": level}
    if not P > 0:
        return out
    w = x[1] - x[0]
    k = np.arange(len(t))

    def edges(thr):
        lo, hi = np.full(len(t), np.nan), np.full(len(t), np.nan)
        for j in range(len(t)):
            c = tgt & (np.nan_to_num(S[j], nan=0.0) > thr)
            if c.any():
                lo[j], hi[j] = x[c].min(), x[c].max()
        return lo, hi

    _, front = edges(0.5 * P)
    at_face = np.nonzero(front >= x_face - 1.5 * w)[0]
    kf = int(at_face[0]) if len(at_face) else len(t)
    m = (k < kf) & (front > x_impact + 0.2 * L) & (front < x_face - 0.2 * L)
    out["D"], _ = _fit(t[m], front[m])
    out["n_shock"] = int(m.sum())
    lo, hi = edges(level * P)
    gone = np.nonzero((k > kf) & ~(hi - lo >= 2 * w))[0]
    ke = int(gone[0]) if len(gone) else len(t)
    mf = (k < ke) & (lo > x_impact + 2 * w) & (lo < x_impact + 0.6 * L)
    mb = (k > kf) & (k < ke) & (hi < x_face - 2 * w) & (hi > x_face - 0.6 * L)
    cf, bf = _fit(t[mf], lo[mf])
    cb, bb = _fit(t[mb], hi[mb])
    out.update({"c_forward": cf, "c_backward": -cb, "n_forward": int(mf.sum()), "n_backward": int(mb.sum())})
    if math.isfinite(cf) and math.isfinite(cb) and cf > 0 > cb:
        tc = (bb - bf) / (cf - cb)
        out["t_cross"], out["x_cross"] = tc, cf * tc + bf
        out["d_expected"] = x_face - out["x_cross"]
    return out


def spall_plane(atoms, frags, x0, target, rear, axis=0):
    """The spall plane of a target from its fragments (material coordinates).

    Parameters
    ----------
    atoms : ase.Atoms
    frags : Fragments
        Fragments of ``atoms``.
    x0 : (N,) array
        Initial positions along ``axis`` (material coordinates).
    target : (N,) bool
        The target's particles.
    rear : (N,) bool or int array
        Particles of the target's rear layer.

    Returns
    -------
    dict
        ``spalled`` (the scab -- the fragment holding most of the rear layer -- holds none of
        the target's particles that started in its front 5%), ``scab_fraction`` (the scab's
        share of the target's particles), ``scab_min_x0`` (its deepest particle's start),
        ``n_target_fragments``, ``largest_target_fragments`` (up to 5 sizes).
    """
    lab = frags.labels
    target = np.asarray(target, bool)
    rear_rows = np.nonzero(np.asarray(rear))[0] if np.asarray(rear).dtype == bool else np.asarray(rear, np.int64)
    if not len(rear_rows):
        raise InputError("rear", "empty", "the rows of the target's rear layer")
    scab = int(np.bincount(lab[rear_rows][lab[rear_rows] >= 0]).argmax())
    in_scab = (lab == scab) & target
    xt = x0[target]
    front = target & (x0 < xt.min() + 0.05 * (xt.max() - xt.min()))
    labs_t = np.unique(lab[target & (lab >= 0)])
    sizes = np.sort(np.bincount(lab[target & (lab >= 0)]))[::-1]
    return {"spalled": bool(not np.any(lab[front] == scab)), "scab_fraction": float(in_scab.sum() / target.sum()),
            "scab_min_x0": float(x0[in_scab].min()), "n_target_fragments": int(len(labs_t)),
            "largest_target_fragments": [int(s) for s in sizes[:5] if s > 0]}


def ring_thickness(t, u, t_from, c, min_cycles=1):
    """Scab thickness ``c T / 2`` from the period T of the free-surface velocity's oscillation
    after ``t_from`` (the spall signal): T is the mean spacing of the maxima (at least
    ``min_cycles`` + 1 of them, each the highest point between two crossings of the mean).
    Returns ``(thickness, T)`` or ``(nan, nan)``."""
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    sel = t >= t_from
    if sel.sum() < 8:
        return float("nan"), float("nan")
    tt, uu = t[sel], u[sel]
    m = uu.mean()
    above = uu > m
    peaks, k = [], 0
    while k < len(uu):
        if above[k]:
            j = k
            while j < len(uu) and above[j]:
                j += 1
            if j < len(uu):                   # a complete excursion above the mean
                peaks.append(tt[k + int(np.argmax(uu[k:j]))])
            k = j
        else:
            k += 1
    if len(peaks) < min_cycles + 1:
        return float("nan"), float("nan")
    T = float(np.mean(np.diff(peaks)))
    return 0.5 * c * T, T
