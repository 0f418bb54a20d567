"""Jets and ejecta from a profiled free surface after shock breakout.

The sample is periodic across (the lateral axes ``u = (axis + 1) % 3`` and
``v = (axis + 2) % 3``) and open along ``axis``; its free surface faces
+axis (:func:`clusterdyn.build.profiled_sample`).  The measures of one frame
(:func:`ejecta_frame`), with the definitions the scenes state:

* **Body**: the clusters of fragments (:func:`clusterdyn.analysis.fragments.fragments`,
  bond distance b r0, default the cutoff) with more than ``g_small``
  clusters (default 10, the dusting limit ``G_MAX``): single stray clusters
  and dust are not body.
* **Free surface**: the uppermost full-width layer (a fragment bonded to
  its own image across the periodic width: the sample, or the sheet that
  has spalled off it) with what is still attached to it (spikes); if no
  full-width layer is left, the body.
* **Surface heights** h(u): the topmost free-surface cluster per lateral
  bin (one lattice plane wide, as
  :func:`clusterdyn.build.profiled.surface_heights` bins).
* **Bubble (valley) front** ``x_b = min_u h(u)``.
* **Free-surface velocity** ``u_fs``: the mean axis velocity of the free
  surface's clusters in the layer ``fs_layer`` (default 3 r0) below the
  bubble front, across the whole width (the continuous material under the
  surface).
* **Jet tip**: the foremost cluster of the fragments with at least ``g_tip``
  clusters (default 11: single clusters and dust do not count); its velocity
  is the mean axis velocity of that fragment's clusters within 2 r0 of the
  tip.  While a spike is still attached to the sample this is the spike's
  tip; once spikes break up it is the foremost sizeable piece.
* **Ejected mass per unit area**: the mass ahead of the bubble front moving
  faster than ``margin * u_fs`` (default margin 1.05), over the lateral
  area (periodic width times slab thickness); defined once the surface
  moves (``u_fs >= breakout_fraction * u_drive``, default 0.5), NaN before.
* **Perturbation amplitude**: ``eta`` the signed amplitude of the initial
  wavelength's cosine mode of h(u) (``2/n sum h cos(2 pi u / lambda)``;
  positive with crests where the initial crests were, negative once the
  perturbation has inverted), and ``eta_pv`` half the spike-to-bubble
  distance ``(max h - min h)/2``.
* **Layers**: fragments bonded to their own image across ``u`` (full-width
  sheets).  More than one layer means the sample has split across its whole
  width: a spall.  Each layer's deepest *initial* height (Lagrangian) gives
  the spall plane.
* **Dust**: fragments of at most ``g_small`` clusters ahead of the valley
  front: their number and mass per unit area (on a smooth surface this is
  the numerical dusting the pair damping removes, CD paper section 3; dust
  off the sample's rear face is not counted).

:class:`EjectaRecorder` collects these frame by frame during a run (with
snapshots and the fragment spectrum at stated times) and is checkpointable
(``get_state`` / ``set_state``).
"""

import math

import numpy as np

from .. import units
from ..errors import InputError
from .fragment_spectra import G_MAX
from .fragments import fragments

__all__ = ["ejecta_frame", "separation_depths", "mode_amplitude", "EjectaRecorder", "spectrum_table", "G_TIP", "MARGIN",
           "FS_LAYER", "BREAKOUT_FRACTION", "fit_rate"]

#: fragments of at least this many clusters carry a jet tip
G_TIP = G_MAX + 1
#: ejecta move faster than MARGIN * u_fs
MARGIN = 1.05
#: free-surface velocity: the layer this many r0 below the bubble front
FS_LAYER = 3.0
#: the surface counts as moving once u_fs reaches this fraction of the drive's speed
BREAKOUT_FRACTION = 0.5


def _bins(atoms, profile, ax, iu):
    """Lateral bins along u: count, width, offset (one lattice plane each, as the builder measures)."""
    W = atoms.cell.lengths()[iu]
    bw = profile.get("bins_A", [None])[0] or float(np.atleast_1d(atoms.info["cd_r0"])[0])
    off = profile.get("bin_offsets_A", [0.0, 0.0])[0]
    n = max(1, int(round(W / bw)))
    return n, W / n, off, W


def surface_profile(pos, mask, ax, iu, nbins, width, offset, length):
    """Topmost masked position along ``ax`` per lateral bin along ``iu`` ((nbins,), NaN where empty)."""
    k = np.floor(np.mod(pos[mask, iu] - offset, length) / width).astype(np.int64) % nbins
    h = np.full(nbins, -np.inf)
    np.maximum.at(h, k, pos[mask, ax])
    h[~np.isfinite(h)] = np.nan
    return h


def mode_amplitude(h, length, wavelength, offset=0.0, width=None):
    """Signed amplitude of ``cos(2 pi u / wavelength)`` in heights ``h`` on ``len(h)`` equal bins.

    Parameters
    ----------
    h : (n,) array
        Heights per bin (NaN bins are left out).
    length : float
        Periodic length the bins cover.
    wavelength : float
        Mode's wavelength (``length`` a whole number of them).
    offset : float
        Position of the first bin's lower edge.

    Returns
    -------
    float
        ``A`` of the least-squares fit ``h = c + A cos + B sin`` (equal to
        ``2/n sum h cos`` when no bin is empty).
    """
    h = np.asarray(h, float)
    n = len(h)
    w = length / n if width is None else width
    u = offset + (np.arange(n) + 0.5) * w
    ok = np.isfinite(h)
    if ok.sum() < 3:
        return math.nan
    ph = 2 * np.pi * u[ok] / wavelength
    M = np.stack([np.ones(ok.sum()), np.cos(ph), np.sin(ph)], axis=1)
    coef = np.linalg.lstsq(M, h[ok], rcond=None)[0]
    return float(coef[1])


def ejecta_frame(atoms, *, axis, r0, b=None, exclude=None, u_drive=None, wavelength=None, g_small=G_MAX,
                 g_tip=G_TIP, margin=MARGIN, fs_layer=FS_LAYER, breakout_fraction=BREAKOUT_FRACTION,
                 frag=None):
    """The measures of one configuration (module docstring); ASE units.

    Parameters
    ----------
    atoms : ase.Atoms
        A profiled sample (``info['profile']`` of :func:`~clusterdyn.build.profiled_sample`
        gives the lateral bins; else one bin per r0).
    axis : int
        Surface normal.
    r0 : float
        Cluster size, Angstrom.
    b : float, optional
        Bond distance in r0 (default: the calculator's cutoff).
    exclude : (N,) bool, optional
        Particles left out (the piston layer).
    u_drive : float, optional
        The drive's plateau speed (Angstrom / ASE time): the ejected mass is
        reported once ``u_fs >= breakout_fraction * u_drive``.
    wavelength : float, optional
        Wavelength of the cosine mode ``eta`` (Angstrom).
    frag : Fragments, optional
        Fragments already found for this configuration.

    Returns
    -------
    dict
        ``x_bubble``, ``x_tip``, ``v_tip``, ``u_fs``, ``ejected_mass_area``
        (amu / Angstrom^2), ``ejected_mass``, ``eta``, ``eta_pv``,
        ``n_layers``, ``n_dust``, ``dust_mass``, ``n_fragments``, ``g_tip_fragment``, ``top_layer``
        (the free surface's fragment, -1 if none is full-width),
        plus ``frag`` (the :class:`~clusterdyn.analysis.fragment_spectra.Fragments`),
        ``body`` (N,) bool and ``heights`` (n_bins,).
    """
    ax = int(axis)
    iu, iv = (ax + 1) % 3, (ax + 2) % 3
    if not (atoms.pbc[iu] and atoms.pbc[iv]) or atoms.pbc[ax]:
        raise InputError("atoms.pbc", atoms.pbc.tolist(), f"periodic across and open along axis {ax}")
    if frag is None:
        frag = fragments(atoms, b, r0=r0, exclude=exclude)
    lab = frag.labels
    inc = lab >= 0
    g_of = np.zeros(len(atoms), np.int64)
    g_of[inc] = frag.g[lab[inc]]
    body = inc & (g_of > g_small)
    pos = atoms.positions
    vel = atoms.get_velocities()[:, ax]
    masses = atoms.get_masses()
    profile = atoms.info.get("profile", {})
    nb, bw, off, W = _bins(atoms, profile, ax, iu)
    layers = frag.percolating[:, iu]
    # the free surface is the uppermost full-width layer's (a spalled sheet, once one has split off);
    # without any full-width layer, the body's
    surf = body
    top_layer = -1
    if layers.any():
        cand = np.flatnonzero(layers)
        top_layer = int(cand[np.argmax(frag.com[cand, ax])])
        surf = lab == top_layer
    h = surface_profile(pos, surf, ax, iu, nb, bw, off, W) if surf.any() else np.full(nb, np.nan)
    x_b = float(np.nanmin(h)) if np.isfinite(h).any() else math.nan
    layer = surf & (pos[:, ax] <= x_b) & (pos[:, ax] > x_b - fs_layer * r0)
    u_fs = float(vel[layer].mean()) if layer.any() else math.nan
    area = W * atoms.cell.lengths()[iv]
    # jet tip
    big = inc & (g_of >= g_tip)
    if big.any():
        k = int(np.flatnonzero(big)[np.argmax(pos[big, ax])])
        x_tip = float(pos[k, ax])
        f = lab[k]
        near = (lab == f) & (pos[:, ax] > x_tip - 2 * r0)
        v_tip = float(vel[near].mean())
        g_tip_fragment = int(frag.g[f])
    else:
        x_tip = v_tip = math.nan
        g_tip_fragment = 0
    moving = u_drive is None or (np.isfinite(u_fs) and u_fs >= breakout_fraction * u_drive)
    if moving and np.isfinite(x_b):
        ej = inc & (pos[:, ax] > x_b) & (vel > margin * u_fs)
        m_ej = float(masses[ej].sum())
    else:
        m_ej = math.nan
    eta = mode_amplitude(h, W, wavelength, off, bw) if wavelength else math.nan
    eta_pv = 0.5 * float(np.nanmax(h) - np.nanmin(h)) if np.isfinite(h).any() else math.nan
    # dust ahead of the free surface (a sample's rear face, free after a pressure pulse, dusts too: not counted)
    small = (frag.g <= g_small) & (frag.com[:, ax] > x_b) if np.isfinite(x_b) else frag.g <= g_small
    return {"x_bubble": x_b, "x_tip": x_tip, "v_tip": v_tip, "u_fs": u_fs,
            "ejected_mass": m_ej, "ejected_mass_area": m_ej / area if np.isfinite(m_ej) else math.nan,
            "eta": eta, "eta_pv": eta_pv, "n_layers": int(layers.sum()), "n_dust": int(small.sum()),
            "dust_mass": float(frag.mass[small].sum()), "n_fragments": int(frag.n_fragments),
            "g_tip_fragment": g_tip_fragment, "top_layer": top_layer, "area": float(area), "frag": frag, "body": body, "heights": h}


def separation_depths(atoms, X0, frag, *, axis, exclude=None):
    """How deep below the initial surface the main body has lost its material, per lateral bin.

    The main body is the largest full-width layer (the largest fragment if
    none is full-width): a sheet spalled off near the surface, or a thin
    layer torn off a piston that holds the base, is not it.  Lateral bins are taken on the initial positions ``X0``
    (one lattice plane each, as the profiled builder measures).  In each bin
    the separation is the initial surface height (the topmost initial
    position in the bin) minus the topmost initial position of a main-body
    cluster in it: zero where the body keeps its surface, the thickness of
    what has left it elsewhere.  A **spall** leaves every bin separated;
    jets only some.

    Returns
    -------
    dict
        ``separation`` (n_bins,) Angstrom (NaN in an empty bin), ``min``,
        ``median``, ``max`` over the bins.
    """
    ax = int(axis)
    iu = (ax + 1) % 3
    X0 = np.asarray(X0, float)
    keep = np.ones(len(X0), bool) if exclude is None else ~np.asarray(exclude, bool)
    lab = frag.labels
    per = np.flatnonzero(frag.percolating[:, iu])
    f = int(per[np.argmax(frag.g[per])]) if len(per) else frag.largest
    main = lab == f
    nb, bw, off, W = _bins(atoms, atoms.info.get("profile", {}), ax, iu)
    h0 = surface_profile(X0, keep, ax, iu, nb, bw, off, W)
    hm = surface_profile(X0, keep & main, ax, iu, nb, bw, off, W)
    sep = h0 - hm
    sep[np.isnan(hm) & np.isfinite(h0)] = np.inf
    fin = sep[np.isfinite(sep)] if np.isfinite(sep).any() else np.array([math.nan])
    return {"separation": sep, "min": float(np.nanmin(sep)), "median": float(np.nanmedian(sep)),
            "max": float(np.nanmax(fin))}


def spectrum_table(g, diameter, mass=None, *, drop_below=None, shift=None):
    """Spectrum N(g) and equivalent diameters of a set of fragments, with the CD paper's corrections.

    Parameters
    ----------
    g : (F,) ints
        Clusters per fragment.
    diameter : (F,) floats
        Equivalent diameters, Angstrom.
    mass : (F,) floats, optional
        Masses, amu.
    drop_below : float, optional
        Leave out fragments with an equivalent diameter below this (Angstrom;
        the paper's first correction: 10 um).
    shift : float, optional
        Then add this to every diameter (Angstrom; the paper's second correction: +5 um).

    Returns
    -------
    dict
        ``g``, ``N`` (sizes present and their counts, after the drop),
        ``diameter`` (kept fragments, shifted), ``mass`` (kept fragments, or None),
        ``kept`` (F,) bool.
    """
    g = np.asarray(g, np.int64)
    d = np.asarray(diameter, float)
    keep = np.ones(len(d), bool) if drop_below is None else d >= drop_below
    dk = d[keep] + (0.0 if shift is None else shift)
    gs, n = np.unique(g[keep], return_counts=True)
    return {"g": gs, "N": n, "diameter": dk, "mass": None if mass is None else np.asarray(mass, float)[keep],
            "kept": keep}


def fit_rate(t, y, t0, t1):
    """Slope and intercept (at t0) of the least-squares line of ``y(t)`` over ``t0 <= t <= t1``.

    Returns (slope, value at t0, number of points); NaN if fewer than 3 points.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    ok = np.isfinite(t) & np.isfinite(y) & (t >= t0) & (t <= t1)
    if ok.sum() < 3:
        return math.nan, math.nan, int(ok.sum())
    A = np.polyfit(t[ok] - t0, y[ok], 1)
    return float(A[0]), float(A[1]), int(ok.sum())


class EjectaRecorder:
    """Frame-by-frame ejecta measures of a run, with snapshots and a spectrum at stated times.

    Parameters
    ----------
    atoms : ase.Atoms
        The sample at set-up (its positions are the Lagrangian reference).
    axis : int
    r0 : float
    exclude : (N,) bool
        Piston layer.
    u_drive : float
        The drive's plateau speed.
    wavelength : float or None
        Wavelength of the eta mode.
    snapshot_times : sequence of float
        Times of the stored snapshots (positions and axis velocities, float32).
    spectrum_time : float or None
        Time of the fragment spectrum (the first frame at or after it, within
        half a frame interval before).
    half_frame : float
        Half the frame interval (snapshots and the spectrum are taken at the
        first frame later than their time minus this).
    b : float, optional
        Bond distance in r0.
    options : dict
        g_small, g_tip, margin, fs_layer, breakout_fraction.
    """

    def __init__(self, atoms=None, *, axis=0, r0=None, exclude=None, u_drive=None, wavelength=None,
                 snapshot_times=(), spectrum_time=None, half_frame=0.0, b=None, **options):
        self.axis, self.r0, self.u_drive, self.wavelength, self.b = axis, r0, u_drive, wavelength, b
        self.exclude = None if exclude is None else np.asarray(exclude, bool)
        self.X0 = None if atoms is None else atoms.positions.copy()
        self.snapshot_times = [float(t) for t in snapshot_times]
        self.spectrum_time = spectrum_time
        self.half_frame = float(half_frame)
        self.options = dict(options)
        self.frames = []
        self.snapshots = []
        self.spectrum = None
        self.extra_frames = []

    # -- checkpoint --------------------------------------------------------------------------
    def get_state(self):
        return {"axis": self.axis, "r0": self.r0, "u_drive": self.u_drive,
                "wavelength": -1.0 if self.wavelength is None else self.wavelength,
                "b": -1.0 if self.b is None else self.b,
                "exclude": self.exclude, "X0": self.X0, "snapshot_times": list(self.snapshot_times),
                "spectrum_time": -1.0 if self.spectrum_time is None else self.spectrum_time,
                "half_frame": self.half_frame, "options": dict(self.options),
                "frames": {k: np.array([f[k] for f in self.frames]) for k in (self.frames[0] if self.frames else {})},
                "snapshots": list(self.snapshots), "spectrum": self.spectrum or {}}

    def set_state(self, st):
        self.axis = int(st["axis"])
        self.r0 = float(st["r0"])
        self.u_drive = float(st["u_drive"])
        self.wavelength = None if float(st["wavelength"]) < 0 else float(st["wavelength"])
        self.b = None if float(st["b"]) < 0 else float(st["b"])
        self.exclude = np.asarray(st["exclude"], bool)
        self.X0 = np.asarray(st["X0"], float)
        self.snapshot_times = [float(t) for t in st["snapshot_times"]]
        self.spectrum_time = None if float(st["spectrum_time"]) < 0 else float(st["spectrum_time"])
        self.half_frame = float(st["half_frame"])
        self.options = {k: (float(v) if k not in ("g_small", "g_tip") else int(v))
                        for k, v in dict(st["options"]).items()}
        fr = dict(st["frames"])
        n = len(next(iter(fr.values()))) if fr else 0
        self.frames = [{k: float(np.asarray(v)[i]) for k, v in fr.items()} for i in range(n)]
        self.snapshots = [dict(s) for s in st["snapshots"]]
        self.spectrum = dict(st["spectrum"]) or None

    # -- frames ------------------------------------------------------------------------------
    def add(self, time, atoms):
        """Measure one frame; returns its dict of scalars."""
        o = self.options
        m = ejecta_frame(atoms, axis=self.axis, r0=self.r0, b=self.b, exclude=self.exclude,
                         u_drive=self.u_drive, wavelength=self.wavelength,
                         **{k: o[k] for k in ("g_small", "g_tip", "margin", "fs_layer", "breakout_fraction")
                            if k in o})
        row = {"t": float(time)}
        row.update({k: float(v) for k, v in m.items() if k not in ("frag", "body", "heights")})
        self.frames.append(row)
        t = float(time)
        done = {round(s["t_target"], 9) for s in self.snapshots}
        for ts in self.snapshot_times:
            if round(ts, 9) not in done and t >= ts - self.half_frame:
                self._snapshot(ts, t, atoms)
                done.add(round(ts, 9))
        if self.spectrum is None and self.spectrum_time is not None and t >= self.spectrum_time - self.half_frame:
            self._spectrum(t, atoms, m)
        return row

    def _snapshot(self, t_target, t, atoms):
        ax = self.axis
        iu = (ax + 1) % 3
        keep = np.ones(len(atoms), bool) if self.exclude is None else ~self.exclude
        self.snapshots.append({"t_target": float(t_target), "t": float(t),
                               "u": atoms.positions[keep, iu].astype(np.float32),
                               "x": atoms.positions[keep, ax].astype(np.float32),
                               "v": atoms.get_velocities()[keep, ax].astype(np.float32)})

    def _spectrum(self, t, atoms, m):
        """The fragments ahead of the bubble front that are not full-width layers."""
        frag = m["frag"]
        ax = self.axis
        iu = (ax + 1) % 3
        ahead = (frag.com[:, ax] > m["x_bubble"]) & ~frag.percolating[:, iu]
        self.spectrum = {"t": float(t), "x_bubble": float(m["x_bubble"]), "u_fs": float(m["u_fs"]),
                         "g": frag.g[ahead].astype(np.int64), "diameter": frag.diameter[ahead].astype(float),
                         "mass": frag.mass[ahead].astype(float), "v": frag.velocity[ahead, ax].astype(float),
                         "area": float(m["area"]),
                         "layers_min_X0": self._layer_depths(frag, atoms)}

    def _layer_depths(self, frag, atoms):
        """Deepest initial height (Lagrangian, along the axis) of each full-width layer, ascending."""
        ax = self.axis
        iu = (ax + 1) % 3
        lab = frag.labels
        out = []
        for f in np.flatnonzero(frag.percolating[:, iu]):
            out.append(float(self.X0[lab == f, ax].min()))
        return np.array(sorted(out))

    def layer_depths(self, atoms, frag=None):
        """:meth:`_layer_depths` of a configuration (finds the fragments when not given)."""
        if frag is None:
            frag = fragments(atoms, self.b, r0=self.r0, exclude=self.exclude)
        return self._layer_depths(frag, atoms)

    def separation(self, atoms, frag=None):
        """:func:`separation_depths` of a configuration against the set-up positions."""
        if frag is None:
            frag = fragments(atoms, self.b, r0=self.r0, exclude=self.exclude)
        return separation_depths(atoms, self.X0, frag, axis=self.axis, exclude=self.exclude)

    def series(self, key):
        """(t, values) of a frame quantity over the recorded frames."""
        return (np.array([f["t"] for f in self.frames]), np.array([f[key] for f in self.frames]))


def _nanmean(a):
    a = np.asarray(a, float)
    return float(a[np.isfinite(a)].mean()) if np.isfinite(a).any() else math.nan


#: the plateau behind a front: slabs within this fraction of the largest velocity
PLATEAU = 0.9


class ShockProbe:
    """The shock in a profiled sample before it breaks out: pressure, speed, order behind the front.

    Sampled (as a dynamics observer) while the front is in the full-width
    part of the sample (below the deepest valley): slabs normal to the axis
    between ``lo`` and ``hi`` (:func:`clusterdyn.analysis.slabs.binned_profile`
    with the particles' virials), the front where the slab velocity falls
    through half the drive's speed (:func:`clusterdyn.analysis.shock.front_position`).
    Per sample: the front position, the **pressure delivered** ``P = -sigma``
    along the axis averaged over the plateau behind the front (the slabs
    between the piston and the front whose velocity is within 10% of the
    largest, 3-slab mean, velocity there: the peak state the wave carries
    towards the surface, also when an elastic precursor runs ahead of it or
    a release has begun to erode it), the particle velocity there, and the
    **ordered fraction** (:mod:`clusterdyn.analysis.order`) of
    the clusters between ``piston_gap`` slabs ahead of the piston and 3 slabs
    behind the front.

    Parameters
    ----------
    atoms : ase.Atoms
        The sample at set-up (the order reference).
    axis : int
    r0, slab : float
        Cluster size and slab width, Angstrom.
    u_drive : float
        The drive's plateau speed.
    lo, hi : float
        Slab range along the axis (the sample's base and its deepest valley).
    exclude : (N,) bool
        The piston layer.
    """

    def __init__(self, atoms=None, *, axis=0, r0=None, slab=None, u_drive=None, lo=None, hi=None, exclude=None,
                 piston_gap=3.0):
        self.axis, self.r0, self.slab, self.u_drive = axis, r0, slab, u_drive
        self.lo, self.hi = lo, hi
        self.piston_gap = piston_gap
        self.exclude = None if exclude is None else np.asarray(exclude, bool)
        self.X0 = None if atoms is None else atoms.positions.copy()
        self.cell = None if atoms is None else atoms.cell.array.copy()
        self.pbc = None if atoms is None else atoms.pbc.copy()
        self.samples = []
        self.done = False
        self._ref = None

    def get_state(self):
        return {"axis": self.axis, "r0": self.r0, "slab": self.slab, "u_drive": self.u_drive, "lo": self.lo,
                "hi": self.hi, "piston_gap": self.piston_gap, "exclude": self.exclude, "X0": self.X0,
                "cell": self.cell, "pbc": self.pbc, "done": bool(self.done),
                "samples": {k: np.array([s[k] for s in self.samples]) for k in (self.samples[0] if self.samples else {})}}

    def set_state(self, st):
        for k in ("r0", "slab", "u_drive", "lo", "hi", "piston_gap"):
            setattr(self, k, float(st[k]))
        self.axis = int(st["axis"])
        self.exclude = np.asarray(st["exclude"], bool)
        self.X0 = np.asarray(st["X0"], float)
        self.cell = np.asarray(st["cell"], float)
        self.pbc = np.asarray(st["pbc"], bool)
        self.done = bool(st["done"])
        fr = dict(st["samples"])
        n = len(next(iter(fr.values()))) if fr else 0
        self.samples = [{k: float(np.asarray(v)[i]) for k, v in fr.items()} for i in range(n)]
        self._ref = None

    def reference(self):
        from ase import Atoms
        from .order import OrderReference
        if self._ref is None:
            self._ref = OrderReference(Atoms(positions=self.X0, cell=self.cell, pbc=self.pbc), r0=self.r0)
        return self._ref

    def sample(self, time, atoms, virials):
        """Record one sample (nothing once the front has reached ``hi``); returns the front position."""
        from .shock import front_position
        from .slabs import binned_profile
        if self.done:
            return math.nan
        ax = self.axis
        prof = binned_profile(atoms, virials, ax, self.slab, self.lo, self.hi, self.exclude)
        u_ax = prof["velocity"][:, ax]
        xf = front_position(prof["x"], u_ax, self.u_drive)
        if not np.isfinite(xf):
            return xf
        if xf > self.hi - 2 * self.slab:
            self.done = True
            return xf
        x = prof["x"]
        pos = atoms.positions[:, ax]
        pist = float(pos[self.exclude].max()) if self.exclude is not None and self.exclude.any() else self.lo
        region = (x > pist + self.piston_gap * self.slab) & (x < xf) & (prof["count"] > 0)
        P = ub = math.nan
        if region.sum() >= 3:
            # the plateau: slabs within PLATEAU of the largest (3-slab mean) velocity behind the front
            us = np.convolve(np.where(region, u_ax, 0.0), np.ones(3) / 3, mode="same")
            peak = us[region].max()
            plateau = region & (u_ax >= PLATEAU * peak)
            if plateau.sum() >= 2:
                P = float(-prof["stress"][plateau, ax].mean())
                ub = float(u_ax[plateau].mean())
        behind = (pos > pist + self.piston_gap * self.slab) & (pos < xf - 3 * self.slab)
        if self.exclude is not None:
            behind &= ~self.exclude
        order = self.reference().fraction(atoms, behind) if behind.any() else math.nan
        self.samples.append({"t": float(time), "front": float(xf), "P": P, "u": ub, "ordered": order,
                             "piston": pist})
        return xf

    def result(self, lo_frac=0.3, hi_frac=0.95):
        """Pressure, front speed and order over the samples with the front in ``[lo_frac, hi_frac]``
        of the range (the last three samples when fewer lie there).

        Returns
        -------
        dict
            ``P``, ``P_spread`` (std over samples), ``D`` (straight-line fit of
            front against time), ``u`` (particle velocity behind the front),
            ``ordered`` (mean ordered fraction), ``t_hi`` (time the fitted
            front reaches ``hi``), ``n`` (samples used); NaN without samples.
        """
        from .shock import fit_front
        nan = {"P": math.nan, "P_spread": math.nan, "D": math.nan, "u": math.nan, "ordered": math.nan,
               "t_hi": math.nan, "n": 0}
        if not self.samples:
            return nan
        t = np.array([s["t"] for s in self.samples])
        xf = np.array([s["front"] for s in self.samples])
        L = self.hi - self.lo
        use = (xf >= self.lo + lo_frac * L) & (xf <= self.lo + hi_frac * L)
        if use.sum() < 3:
            use = np.zeros(len(t), bool)
            use[-min(3, len(t)):] = True
        P = np.array([s["P"] for s in self.samples])[use]
        out = dict(nan)
        out["n"] = int(np.isfinite(P).sum())
        out["P"] = _nanmean(P)
        out["P_spread"] = float(np.nanstd(P)) if np.isfinite(P).any() else math.nan
        out["u"] = _nanmean(np.array([s["u"] for s in self.samples])[use])
        out["ordered"] = _nanmean(np.array([s["ordered"] for s in self.samples])[use])
        if use.sum() >= 3:
            D, x0, _ = fit_front(t[use], xf[use])
            out["D"] = float(D)
            out["t_hi"] = float((self.hi - x0) / D) if D > 0 else math.nan
        return out
