"""Samples with a profiled free surface: sinusoid, triangular grooves, random roughness.

A sample is a slab of fcc clusters whose free surface is normal to ``axis``:
the clusters kept are the fcc sites with ``x_axis < depth + h(u, v)``, where
``u``, ``v`` are the lateral coordinates (``u`` along ``(axis + 1) % 3``, ``v``
along ``(axis + 2) % 3``), ``h`` the surface height (zero mean) and ``depth``
the mean height of the surface above the base (the base, ``x_axis = 0``, is a
full lattice plane).  Both lateral axes are periodic, the axis is open.

* **quasi-2D** (``dims=2``): ``h = h(u)``; the slab is ``slab_cells``
  orthorhombic lattice repeats thick along ``v`` (periodic): the profile is
  the same in every ``u``-``axis`` plane.
* **3D** (``dims=3``): a 2-D periodic height field ``h(u, v)`` over
  ``width x length``.

**Crystal orientation** (``direction``): the Miller direction along the
surface normal, the next two directions of
:data:`~clusterdyn.build.lattice.ORIENTATIONS` along ``u`` and ``v``: [100]
normal: ``u`` along [010], ``v`` along [001]; [110]: [-110], [001];
[111]: [1-10], [11-2].  ``info['profile']['orientation']`` states it.

**Profiles** (``h`` has zero mean; lengths in Angstrom):

* :class:`Sinusoid` ``h = A cos(2 pi u / lambda)`` (``crossed``: times
  ``cos(2 pi v / lambda)``, 3D only).  ``A`` is the amplitude, half the
  peak-to-valley height (the profile's Rz is ``2 A``).
* :class:`Grooves` symmetric V grooves of peak-to-valley ``depth`` and period
  ``p``: ``h = depth (|2 frac(u/p) - 1| - 1/2)``: a ridge at ``u = 0``, the
  groove bottom at ``u = p/2``; straight along ``v``.
* :class:`RandomRoughness` a Gaussian random field with the Gaussian
  autocorrelation ``C(r) = sigma^2 exp(-r^2 / xi^2)`` (``xi`` the correlation
  length: C falls to 1/e of C(0) at ``r = xi``), periodic over the sample
  (white noise filtered in Fourier space by ``exp(-k^2 xi^2 / 8)``), on a grid
  of spacing at most r0/2 interpolated (linear) to the clusters, and scaled
  so that the Rz measured on the built sample's surface clusters equals the
  target (a few builds, the closest kept; ``info['profile']`` reports the
  achieved Rz and correlation length, measured on the clusters).  3D: isotropic.

**Rz** (ISO 4287/4288 style): the evaluation length is the periodic width,
divided into ``n_sampling = 5`` equal sampling lengths; in each the maximum
height (highest peak to lowest valley) of the profile; Rz is their mean.  In
3D, the mean over the profile lines along ``u`` (one per bin along ``v``).

**Measured surface**: the height of the topmost cluster centre in each
lateral bin (width ``bin_width``, default r0; :func:`surface_heights`), from
which :func:`surface_amplitude` (the FFT's strongest mode: its amplitude and
wavelength) and :func:`surface_roughness` (Rz, rms, correlation length from the
periodic autocorrelation's 1/e lag) are computed.  Centres lie up to one
plane spacing below ``depth + h``; the offset does not enter Rz, amplitudes or
correlation lengths.

**Periodic widths**: a periodic profile needs a whole number of periods
across (refused otherwise), and the lattice needs a whole number of repeats:
the width is rounded to the nearest whole number of lattice repeats and the
profile stretched with it to stay periodic; ``info['profile']`` reports the
built width and wavelength (they differ from the request by at most half a
lattice repeat over the width).
"""

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, check_positive
from ..materials import get_material
from .bodies import crystal_rotation, plane_spacing
from .lattice import ORIENTATIONS, parse_axis, SQRT2, fcc_sites, make_cluster_atoms, parse_direction, repeat_lengths

#: number of sampling lengths in the evaluation length (ISO 4288's default)
N_SAMPLING = 5


def _miller(v):
    return "[" + "".join(str(int(c)) for c in v) + "]"


@dataclass
class Sinusoid:
    """``h = amplitude cos(2 pi u / wavelength)`` (times ``cos(2 pi v / wavelength)`` if ``crossed``)."""
    amplitude: float
    wavelength: float
    crossed: bool = False
    kind = "sinusoid"

    def __post_init__(self):
        self.amplitude = check_positive("amplitude", self.amplitude)
        self.wavelength = check_positive("wavelength", self.wavelength)

    @property
    def period(self):
        return self.wavelength

    def heights(self, u, v, period, period_v=None):
        """Heights at lateral points u, v (Angstrom) for the built period(s)."""
        h = self.amplitude * np.cos(2 * np.pi * u / period)
        return h * np.cos(2 * np.pi * v / (period if period_v is None else period_v)) if self.crossed else h

    def extremes(self):
        return -self.amplitude, self.amplitude


@dataclass
class Grooves:
    """Symmetric triangular (V) grooves: peak-to-valley ``depth``, ``period``; a ridge at u = 0."""
    depth: float
    period: float
    crossed = False
    kind = "grooves"

    def __post_init__(self):
        self.depth = check_positive("depth", self.depth)
        self.period = check_positive("period", self.period)

    def heights(self, u, v, period, period_v=None):
        """Heights at lateral points u (Angstrom) for the built period (v unused)."""
        f = np.mod(u / period, 1.0)
        return self.depth * (np.abs(2.0 * f - 1.0) - 0.5)

    def extremes(self):
        return -0.5 * self.depth, 0.5 * self.depth


@dataclass
class RandomRoughness:
    """Gaussian random surface: target ``rz`` and ``correlation_length`` (Angstrom), ``seed``."""
    rz: float
    correlation_length: float
    seed: int = None
    kind = "random"
    period = None
    crossed = False

    def __post_init__(self):
        self.rz = check_positive("rz", self.rz)
        self.correlation_length = check_positive("correlation_length", self.correlation_length)


#: profile kinds by name
PROFILES = {"sinusoid": Sinusoid, "grooves": Grooves, "random": RandomRoughness}


def gaussian_field(shape, spacing, correlation_length, rng):
    """Periodic Gaussian random field of unit rms with autocorrelation ``exp(-r^2/xi^2)``.

    Parameters
    ----------
    shape : (n1,) or (n1, n2) ints
        Grid points.
    spacing : float or (2,) floats
        Grid spacing per axis, Angstrom.
    correlation_length : float
        xi, Angstrom.
    rng : numpy Generator

    Returns
    -------
    array of ``shape``
        Zero mean, unit rms.
    """
    shape = tuple(int(n) for n in shape)
    dx = np.broadcast_to(np.asarray(spacing, float), (len(shape),))
    noise = rng.standard_normal(shape)
    k2 = np.zeros(shape)
    for d, (n, h) in enumerate(zip(shape, dx)):
        k = 2 * np.pi * np.fft.fftfreq(n, d=h)
        k2 = k2 + (k ** 2).reshape([-1 if i == d else 1 for i in range(len(shape))])
    # PSD of exp(-r^2/xi^2) is proportional to exp(-k^2 xi^2/4); the filter is its square root
    f = np.real(np.fft.ifftn(np.fft.fftn(noise) * np.exp(-k2 * correlation_length ** 2 / 8.0)))
    f -= f.mean()
    return f / np.sqrt((f ** 2).mean())


def _interp_periodic(grid, spacing, u, v=None):
    """Linear (1D) or bilinear (2D) periodic interpolation of ``grid`` at u (and v)."""
    n1 = grid.shape[0]
    x = u / spacing[0]
    i0 = np.floor(x).astype(np.int64)
    t = x - i0
    i0 %= n1
    i1 = (i0 + 1) % n1
    if grid.ndim == 1:
        return (1 - t) * grid[i0] + t * grid[i1]
    n2 = grid.shape[1]
    y = v / spacing[1]
    j0 = np.floor(y).astype(np.int64)
    s = y - j0
    j0 %= n2
    j1 = (j0 + 1) % n2
    return ((1 - t) * (1 - s) * grid[i0, j0] + t * (1 - s) * grid[i1, j0]
            + (1 - t) * s * grid[i0, j1] + t * s * grid[i1, j1])


def rz_of_profile(h, n_sampling=N_SAMPLING):
    """ISO mean peak-to-valley height: mean over ``n_sampling`` equal sampling lengths of max - min.

    Parameters
    ----------
    h : (n,) or (n, m) array
        Heights along a profile (axis 0); a 2-D array is m profile lines,
        whose Rz are averaged.  NaN (empty bins) are ignored.

    Returns
    -------
    float
        Same unit as ``h``.
    """
    h = np.asarray(h, float)
    if h.ndim == 1:
        h = h[:, None]
    if h.shape[0] < n_sampling:
        raise InputError("h", f"{h.shape[0]} points", f"at least n_sampling = {n_sampling} points per profile")
    parts = np.array_split(h, n_sampling, axis=0)
    rz = np.mean([np.nanmax(p, axis=0) - np.nanmin(p, axis=0) for p in parts], axis=0)
    return float(np.mean(rz))


def correlation_length(h, spacing):
    """Lag at which the periodic autocorrelation of ``h`` falls to 1/e of its zero-lag value.

    Parameters
    ----------
    h : (n,) or (n, m) array
        Heights on a periodic grid (NaN not allowed).
    spacing : float or (2,) floats
        Grid spacing per axis.

    Returns
    -------
    float
        The 1/e lag (linear interpolation between grid lags); in 2-D the mean
        of the lags along both axes.  ``nan`` if it does not fall to 1/e
        within half the period.
    """
    h = np.asarray(h, float)
    dx = np.broadcast_to(np.asarray(spacing, float), (h.ndim,))
    f = h - h.mean()
    acf = np.real(np.fft.ifftn(np.abs(np.fft.fftn(f)) ** 2))
    acf /= acf.flat[0]
    out = []
    for d in range(h.ndim):
        c = acf[(slice(None),) + (0,) * (h.ndim - 1)] if d == 0 else acf[0, :]
        c = c[: len(c) // 2 + 1]
        below = np.flatnonzero(c < math.exp(-1.0))
        if len(below) == 0:
            out.append(math.nan)
            continue
        k = below[0]
        t = (c[k - 1] - math.exp(-1.0)) / (c[k - 1] - c[k])
        out.append((k - 1 + t) * dx[d])
    return float(np.mean(out))


def _lateral_axes(axis):
    return (axis + 1) % 3, (axis + 2) % 3


def _repeat_count(length, repeat):
    n = max(1, int(round(length / repeat)))
    return n, n * repeat


def profiled_sample(material, r0, profile, *, depth, width, axis=0, direction=(1, 0, 0), dims=2, length=None,
                    slab_cells=3, bin_width=None, n_sampling=N_SAMPLING, max_builds=5):
    """A slab of fcc clusters whose free surface (normal to ``axis``) follows ``profile``.

    Parameters
    ----------
    material : str or Material
        A CD material.
    r0 : float
        Cluster size, Angstrom.
    profile : Sinusoid | Grooves | RandomRoughness
        The surface (module docstring).
    depth : float
        Mean height of the surface above the base, Angstrom; the valleys must
        leave at least 2 r0 of material.
    width : float
        Periodic width along ``u = (axis + 1) % 3``, Angstrom: a whole number
        of periods for a periodic profile; at least 5 correlation lengths
        for a random one.  Rounded to whole lattice repeats (reported).
    axis : 0, 1, 2 or 'x', 'y', 'z'
        Surface normal (the free surface faces +axis).
    direction : [100] | [110] | [111]
        Crystal direction along the normal.
    dims : 2 or 3
        Quasi-2D slab or 3D surface.
    length : float, optional
        3D: periodic length along ``v`` (default ``width``); whole periods
        for a crossed sinusoid.
    slab_cells : int
        Quasi-2D: slab thickness along ``v`` in lattice repeats (default 3).
    bin_width : float, optional
        Lateral bin of the surface measurement, Angstrom (default: quasi-2D
        one lattice plane normal to u, 3D one lattice repeat along u and v;
        see :func:`surface_heights`).
    n_sampling : int
        Sampling lengths per evaluation length for Rz (default 5).
    max_builds : int
        Random surface: builds to match the target Rz on the clusters.

    Returns
    -------
    ase.Atoms
        Arrays ``material``, ``radius``, ``id``; ``pbc`` True across, False
        along ``axis``; cell: the periodic lengths and ``depth + max h`` along
        ``axis``; ``info['profile']``: the request, the built width/length and
        period, orientation, the surface measured on the clusters
        (amplitude and wavelength, or Rz and correlation length) and the
        random field's rms ``sigma_A``.
    """
    mat = get_material(material)
    if mat.curve is None:
        raise InputError("material", mat.name, "a material with a cold curve (CD)")
    r0 = check_positive("r0", r0)
    if not isinstance(profile, (Sinusoid, Grooves, RandomRoughness)):
        raise InputError("profile", profile, "a Sinusoid, Grooves or RandomRoughness")
    depth = check_positive("depth", depth)
    width = check_positive("width", width)
    ax = parse_axis(axis)
    key = parse_direction(direction)
    if dims not in (2, 3):
        raise InputError("dims", dims, "2 (quasi-2D slab) or 3 (2-D periodic surface)")
    if dims == 2 and profile.crossed:
        raise InputError("profile", "Sinusoid(crossed=True)", "a profile h(u) in quasi-2D (dims=3 for crossed)")
    _check_count("slab_cells", slab_cells, "an integer >= 1 (lattice repeats across the slab)")
    _check_count("max_builds", max_builds, "an integer >= 1")
    bw = None if bin_width is None else check_positive("bin_width", bin_width)
    _check_count("n_sampling", n_sampling, "an integer >= 1 (sampling lengths per evaluation length)")
    g = _profile_geometry(profile, r0, ax, key, dims, width, length, slab_cells, n_sampling, bw)
    heights, scale, extremes = _profile_heights(profile, g, r0, dims, n_sampling)

    def build(s):
        return _cut_profiled_slab(mat, r0, depth, g, heights, extremes, s)

    rows = ORIENTATIONS[key]
    info = {"kind": profile.kind, "dims": dims, "axis": ax, "u_axis": g["iu"], "v_axis": g["iv"],
            "direction": _miller(key), "bins_A": [None if b is None else float(b) for b in g["bins"]],
            "bin_offsets_A": [-0.5 * g["d_u"], -0.5 * g["d_v"]],
            "n_sampling": n_sampling,
            "orientation": {"normal": _miller(rows[0]), "u": _miller(rows[1]), "v": _miller(rows[2])},
            "depth_A": depth, "width_requested_A": width, "width_A": float(g["W"]), "length_A": float(g["Lv"]),
            "lattice_repeats": [int(g["nu"]), int(g["nv"])], "slab_cells": int(slab_cells) if dims == 2 else None}
    if isinstance(profile, RandomRoughness):
        atoms = _build_to_rz(profile, build, scale, info, max_builds)
    else:
        atoms = build(1.0)
        atoms.info["profile"] = dict(info)
        m = surface_amplitude(atoms)
        req = {"amplitude_A": profile.amplitude} if isinstance(profile, Sinusoid) else {"groove_depth_A": profile.depth}
        info.update({**req, "period_requested_A": profile.period, "period_A": g["period_built"],
                     "n_periods": g["n_per_u"], "crossed": bool(profile.crossed), "period_v_A": g["period_v"],
                     "measured_amplitude_A": m["amplitude"], "measured_wavelength_A": m["wavelength"],
                     "measured_peak_to_valley_A": float(np.ptp(surface_heights(atoms)["heights"]))})
    atoms.info["profile"] = info
    atoms.info["direction"] = key
    return atoms


def _check_count(name, value, allowed):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(name, value, allowed)


def _whole_periods(name, value, period):
    n = value / period
    if abs(n - round(n)) > 1e-6 * max(1.0, n) or round(n) < 1:
        raise InputError(name, value, f"a whole number of periods of {period:.6g} A "
                         f"(e.g. {max(1, round(n)) * period:.6g})")
    return int(round(n))


def _profile_geometry(profile, r0, ax, key, dims, width, length, slab_cells, n_sampling, bw):
    """The lattice and the profile across the sample (checked): a dict of the lateral axes
    ``iu``, ``iv``, the rotation ``rot``, the built repeats ``nu``, ``nv`` and lengths ``W``,
    ``Lv``, the periods (``n_per_u``, ``n_per_v``, ``period_built``, ``period_v``), the plane
    spacings ``d_u``, ``d_v`` and the measurement ``bins``."""
    iu, iv = _lateral_axes(ax)
    rot = crystal_rotation(key, ax)
    rep = repeat_lengths(key, r0)                 # along the direction, then the two others
    rep_u, rep_v = rep[1], rep[2]
    length = width if (dims == 3 and length is None) else length
    if dims == 3:
        length = check_positive("length", length)
    elif length is not None:
        raise InputError("length", length, "None in quasi-2D (the slab is slab_cells repeats thick)")
    n_per_u = n_per_v = None
    if profile.period is not None:
        n_per_u = _whole_periods("width", width, profile.period)
        if profile.crossed:
            n_per_v = _whole_periods("length", length, profile.period)
    else:
        xi = profile.correlation_length
        if xi < r0:
            raise InputError("correlation_length", xi, f">= r0 = {r0:.6g} A (clusters resolve nothing finer)")
        for name, val in (("width", width),) + ((("length", length),) if dims == 3 else ()):
            if val < n_sampling * xi:
                raise InputError(name, val, f">= n_sampling x correlation_length = {n_sampling * xi:.6g} A "
                                 "(each sampling length holds a correlation length)")
    nu, W = _repeat_count(width, rep_u)
    if dims == 3:
        nv, Lv = _repeat_count(length, rep_v)
    else:
        nv, Lv = slab_cells, slab_cells * rep_v
    period_built = W / n_per_u if n_per_u else None
    period_v = Lv / n_per_v if n_per_v else None     # a crossed sinusoid: stretched to its own repeats along v
    # measurement bins: quasi-2D one lattice plane normal to u each; 3D one lattice repeat (u, v) each;
    # edges half a plane spacing off the planes (never on a column of clusters)
    d_u, d_v = plane_spacing(r0, rot, iu), plane_spacing(r0, rot, iv)
    if bw is None:
        bins = (d_u, None) if dims == 2 else (rep_u, rep_v)
    else:
        bins = (bw, None if dims == 2 else bw)
    if profile.period is not None and period_built < 2 * bins[0]:
        raise InputError("wavelength" if isinstance(profile, Sinusoid) else "period", profile.period,
                         f">= 2 bin widths ({2 * bins[0]:.6g} A) so that the surface resolves it")
    return {"ax": ax, "iu": iu, "iv": iv, "rot": rot, "nu": nu, "nv": nv, "W": W, "Lv": Lv, "n_per_u": n_per_u,
            "n_per_v": n_per_v, "period_built": period_built, "period_v": period_v, "d_u": d_u, "d_v": d_v,
            "bins": bins}


def _profile_heights(profile, g, r0, dims, n_sampling):
    """The surface heights at given lateral points: ``(heights(u, v, scale), scale, extremes(scale))``
    (a random field: its grid, scaled by ``scale``, first to the target Rz of the grid)."""
    if isinstance(profile, RandomRoughness):
        W, Lv = g["W"], g["Lv"]
        rng = np.random.default_rng(profile.seed)
        gu = int(math.ceil(W / (0.5 * r0)))
        if dims == 3:
            gv = int(math.ceil(Lv / (0.5 * r0)))
            grid = gaussian_field((gu, gv), (W / gu, Lv / gv), profile.correlation_length, rng)
            spacing = (W / gu, Lv / gv)
        else:
            grid = gaussian_field((gu,), W / gu, profile.correlation_length, rng)
            spacing = (W / gu,)
        unit_rz = rz_of_profile(grid, n_sampling)

        def heights(u, v, scale):
            return scale * (_interp_periodic(grid, spacing, u, v if dims == 3 else None))
        return heights, profile.rz / unit_rz, lambda s: (s * grid.min(), s * grid.max())

    def heights(u, v, scale):
        return profile.heights(u, v, g["period_built"], g["period_v"])
    return heights, 1.0, lambda s: profile.extremes()


def _cut_profiled_slab(mat, r0, depth, g, heights, extremes, s):
    """The fcc sites below the surface ``depth + heights(u, v, s)``, as cluster Atoms."""
    ax, iu, iv = g["ax"], g["iu"], g["iv"]
    pbc = np.ones(3, bool)
    pbc[ax] = False
    a = SQRT2 * r0
    hmin, hmax = extremes(s)
    if depth + hmin < 2.0 * r0:
        raise InputError("depth", depth, f"> {2 * r0 - hmin:.6g} A (the deepest valley, {-hmin:.6g} A below "
                         "the mean surface, must leave 2 r0 of material)")
    hi = np.zeros(3)
    hi[ax], hi[iu], hi[iv] = depth + hmax + a, g["W"], g["Lv"]
    pos = fcc_sites(r0, g["rot"], np.zeros(3), hi)
    keep = pos[:, ax] < depth + heights(pos[:, iu], pos[:, iv], s)
    pos = pos[keep]
    order = np.lexsort((pos[:, 2], pos[:, 1], pos[:, 0]))
    cell = np.zeros(3)
    cell[ax], cell[iu], cell[iv] = depth + hmax, g["W"], g["Lv"]
    return make_cluster_atoms(pos[order], [mat], [r0], cell=np.diag(cell), pbc=pbc)


def _build_to_rz(profile, build, scale, info, max_builds):
    """A random surface built up to ``max_builds`` times, rescaled each time towards the target Rz
    measured on the clusters; the closest is kept and ``info`` takes what it achieved."""
    best = None
    for _ in range(max_builds):
        atoms = build(scale)
        atoms.info["profile"] = dict(info)
        r = surface_roughness(atoms)
        err = abs(r["rz"] / profile.rz - 1.0)
        if best is None or err < best[0]:
            best = (err, atoms, scale, r)
        if err < 0.01:
            break
        scale *= profile.rz / r["rz"]
    _, atoms, scale, r = best
    info.update({"rz_target_A": profile.rz, "correlation_length_target_A": profile.correlation_length,
                 "seed": profile.seed, "sigma_A": float(scale), "rz_A": r["rz"], "rms_A": r["rms"],
                 "correlation_length_A": r["correlation_length"],
                 "rz_rel_error": r["rz"] / profile.rz - 1.0})
    return atoms


def surface_heights(atoms, *, axis=None, dims=None, bin_width=None):
    """Height of the topmost cluster centre per lateral bin.

    Parameters
    ----------
    atoms : ase.Atoms
        A sample with periodic lateral axes (defaults from ``info['profile']``
        of :func:`profiled_sample`).
    axis : int, optional
        Surface normal.
    dims : 2 or 3, optional
        2: bins along ``u`` only (the max over ``v``); 3: bins along ``u`` and ``v``.
    bin_width : float, optional
        Angstrom.  Default ``info['profile']['bins_A']``: quasi-2D one lattice
        plane normal to u per bin, 3D one lattice repeat along u and v per bin
        (every bin then holds the same set of cluster columns), else r0.  The
        periodic lengths are divided into whole numbers of bins, whose edges
        lie half a plane spacing off the lattice planes
        (``info['profile']['bin_offsets_A']``).

    Returns
    -------
    dict
        ``heights`` ((n_u,) or (n_u, n_v), Angstrom, NaN in an empty bin),
        ``spacing`` (bin widths along u (, v)), ``width``, ``length``,
        ``axis``, ``u_axis``, ``v_axis``.
    """
    p = atoms.info.get("profile", {})
    ax = parse_axis(p.get("axis", 0) if axis is None else axis)
    dims = p.get("dims", 2) if dims is None else dims
    if dims not in (2, 3):
        raise InputError("dims", dims, "2 or 3")
    iu, iv = _lateral_axes(ax)
    if not (atoms.pbc[iu] and (dims == 2 or atoms.pbc[iv])):
        raise InputError("atoms.pbc", atoms.pbc.tolist(), "periodic lateral axes (a profiled sample)")
    if bin_width is not None:
        bins = (check_positive("bin_width", bin_width),) * 2
    elif p.get("bins_A") and p.get("dims") == dims and p.get("axis") == ax:
        bins = p["bins_A"]
    elif "cd_r0" in atoms.info:
        bins = (float(atoms.info["cd_r0"][0]),) * 2
    else:
        raise InputError("bin_width", None, "a bin width (Angstrom)")
    off = p.get("bin_offsets_A", [0.0, 0.0]) if p.get("axis") == ax else [0.0, 0.0]
    L = atoms.cell.lengths()
    W, Lv = L[iu], L[iv]
    pos = atoms.positions

    def index(x, length, width, offset):
        n = max(1, int(round(length / width)))
        return np.floor(np.mod(x - offset, length) / (length / n)).astype(np.int64) % n, n, length / n

    i, nb_u, su = index(pos[:, iu], W, bins[0], off[0])
    if dims == 2:
        h = np.full(nb_u, -np.inf)
        np.maximum.at(h, i, pos[:, ax])
        spacing = (su,)
    else:
        j, nb_v, sv = index(pos[:, iv], Lv, bins[1], off[1])
        h = np.full((nb_u, nb_v), -np.inf)
        np.maximum.at(h, (i, j), pos[:, ax])
        spacing = (su, sv)
    h[~np.isfinite(h)] = np.nan
    return {"heights": h, "spacing": spacing, "width": float(W), "length": float(Lv), "axis": ax,
            "u_axis": iu, "v_axis": iv}


def _heights_of(atoms_or_heights, **kw):
    return atoms_or_heights if isinstance(atoms_or_heights, dict) else surface_heights(atoms_or_heights, **kw)


def surface_amplitude(atoms_or_heights, **kw):
    """Strongest Fourier mode of the measured surface: its amplitude and wavelength.

    Parameters
    ----------
    atoms_or_heights : ase.Atoms or dict from :func:`surface_heights`
    **kw : passed to :func:`surface_heights`

    Returns
    -------
    dict
        ``amplitude`` (Angstrom: the cosine's amplitude, half its
        peak-to-valley; for a mode along both u and v, the product form
        ``A cos cos``), ``wavelength`` (along u, Angstrom; inf if the mode has
        none), ``wavelength_v`` (along v, or inf), ``mode`` (periods across u, v).
    """
    s = _heights_of(atoms_or_heights, **kw)
    h = s["heights"]
    if np.isnan(h).any():
        raise InputError("atoms", "a surface with empty bins", "a cluster in every lateral bin (widen bin_width)")
    h2 = h if h.ndim == 2 else h[:, None]
    c = np.fft.fft2(h2 - h2.mean()) / h2.size
    mag = np.abs(c)
    mag[0, 0] = 0.0
    k1, k2 = np.unravel_index(int(np.argmax(mag)), mag.shape)
    n1, n2 = h2.shape
    k1 = k1 if k1 <= n1 // 2 else k1 - n1
    k2 = k2 if k2 <= n2 // 2 else k2 - n2
    mult = 2 if (k1 == 0 or k2 == 0) else 4
    return {"amplitude": float(mult * mag.max()),
            "wavelength": s["width"] / abs(k1) if k1 else math.inf,
            "wavelength_v": s["length"] / abs(k2) if k2 else math.inf,
            "mode": (abs(int(k1)), abs(int(k2)))}


def surface_roughness(atoms_or_heights, n_sampling=None, **kw):
    """Rz, rms and correlation length of the measured surface.

    Parameters
    ----------
    atoms_or_heights : ase.Atoms or dict from :func:`surface_heights`
    n_sampling : int, optional
        Sampling lengths per profile (default ``info['profile']['n_sampling']`` or 5).

    Returns
    -------
    dict
        ``rz`` (:func:`rz_of_profile` over profile lines along u), ``rms``,
        ``correlation_length`` (:func:`correlation_length`), all in Angstrom;
        ``n_sampling`` and ``sampling_length``.
    """
    if n_sampling is None:
        n_sampling = N_SAMPLING
        if not isinstance(atoms_or_heights, dict):
            n_sampling = atoms_or_heights.info.get("profile", {}).get("n_sampling", N_SAMPLING)
    s = _heights_of(atoms_or_heights, **kw)
    h = s["heights"]
    if np.isnan(h).any():
        raise InputError("atoms", "a surface with empty bins", "a cluster in every lateral bin (widen bin_width)")
    return {"rz": rz_of_profile(h, n_sampling), "rms": float(np.sqrt(((h - h.mean()) ** 2).mean())),
            "correlation_length": correlation_length(h, s["spacing"]), "n_sampling": int(n_sampling),
            "sampling_length": s["width"] / n_sampling}
