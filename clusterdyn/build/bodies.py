"""Bodies for impact scenes: rods, spheres, plates, stacks of plates, and their combination.

Every builder returns ASE Atoms of one body (a stack: one body per plate)
carrying the arrays every CD kernel reads (``material``, ``radius``, ``id``)
plus ``grain`` (grain id) and ``body`` (body id), its velocity in the
momenta, and ``info['bodies']``: one JSON-friendly dict per body (kind,
material, r0, geometric centre and sizes, velocity, structure, grain ids,
porosity, mass choice).  Bodies are either

* a **single crystal**: the fcc packing (:func:`~clusterdyn.build.lattice.fcc_sites`)
  in a chosen orientation (a Miller direction along the body's axis, or a
  rotation matrix), carved by the body's shape (clusters whose centres lie
  inside).  A lattice site sits at the centre of a sphere and on the axis of
  a rod or round plate; along a rod's or plate's axis (and across a
  rectangular plate) the lattice planes are centred so that their number n
  makes ``n d`` (d the plane spacing) closest to the body's size: the mass
  is right to half a plane, not biased by half a plane per face pair; or
* a **polycrystal**: :func:`~clusterdyn.build.polycrystal.polycrystal` in the
  body's shape (grain size or number of grains, seed, minimum distance or
  target porosity), which gives random grain orientations.

Open boundaries (``pbc`` False): the cell is the bounding box of the
clusters (``info['origin']`` its lower corner), which matters only for output.

**Masses.**  ``mass="cluster"`` (default) keeps each cluster's material mass
``rho0 r0^3/sqrt(2)``: a porous packing (polycrystal, porosity phi) is then
lighter than the solid by ``1 - phi`` and carries that much less momentum at
the same speed; its wave speeds are the packing's own.  ``mass="dense"``
scales every cluster mass of the body by ``f = rho0 V / (N rho0 r0^3/sqrt(2))``
(V the body's geometric volume), so the body has the mass, momentum and
kinetic energy of the full-density solid; the pair forces are unchanged, so
its elastic wave speeds drop by ``1/sqrt(f)`` and the pair damping rate
(eta from the material's cluster mass) by ``1/f``.  ``info['bodies']`` records
the choice and ``f``.

**Gaps.**  :func:`place` and :func:`plate_stack` measure a gap between two
bodies along an axis as the clearance between their clusters' spheres (radius
``r0/2``): the lowest ``x - r0/2`` of the upper body minus the highest
``x + r0/2`` of the lower body.  A gap g >= 0 guarantees that no two clusters
of the two bodies are closer than ``r0 + g`` (centre to centre); g = 0 is
contact at the bond length, g > (rc - 1) r0 (0.15 r0 at rc = 1.15) leaves
the bodies without interaction until they move.

**Combining.**  :func:`combine_bodies` concatenates bodies into one Atoms:
particle ids ``id = offset_b + id_b`` (``offset_b`` = sum of ``max(id) + 1``
over the earlier bodies), body and grain ids offset the same way, and one
material table: each distinct (material name, r0) gets one id, in order of
first appearance, written to ``info['cd_materials']`` / ``info['cd_r0']`` and
``arrays['material']`` exactly as :class:`~clusterdyn.calculators.ClusterDynamics`
reads them (unlike pairs need nothing more: the calculator mixes them).
"""

import math

import numpy as np
from ase import Atoms
from scipy.spatial import cKDTree

from .. import units
from ..errors import InputError, check_positive
from ..materials import get_material
from .lattice import SQRT2, fcc_sites, make_cluster_atoms, orientation_matrix, parse_axis, parse_direction
from .polycrystal import DEFAULT_D_MIN, polycrystal
from .shapes import Box, Cylinder, Sphere, _vec3

#: the two mass choices (see the module docstring)
MASS_CHOICES = ("cluster", "dense")


def crystal_rotation(orientation=None, axis=0):
    """Rotation ``lab = R @ crystal`` of a single crystal.

    Parameters
    ----------
    orientation : None, Miller direction or (3, 3) array
        None = [100]; a direction ``"100"``, ``"110"``, ``"111"`` (or a tuple)
        is put along lab ``axis``, with the two other crystal directions of
        :data:`~clusterdyn.build.lattice.ORIENTATIONS` along the next axes in
        cyclic order (e.g. [110] along z: [-110] along x, [001] along y);
        a (3, 3) proper rotation is returned as given.
    axis : 0, 1, 2 or 'x', 'y', 'z'

    Returns
    -------
    (3, 3) array
        Rows are the lab axes in crystal coordinates, columns the cube axes
        in the lab frame.
    """
    ax = parse_axis(axis)
    if orientation is not None and np.ndim(orientation) == 2:
        R = np.asarray(orientation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-8) or \
                not abs(np.linalg.det(R) - 1.0) < 1e-8:
            raise InputError("orientation", "matrix", "a (3, 3) proper rotation (orthogonal, det +1)")
        return R
    key = parse_direction((1, 0, 0) if orientation is None else orientation)
    rows = orientation_matrix(key)
    return np.array([rows[(i - ax) % 3] for i in range(3)])


def plane_spacing(r0, rot, axis):
    """Spacing of the lattice planes normal to lab ``axis`` (Angstrom), or 0 if they are not
    lattice planes (a general rotation): the smallest gap between distinct site coordinates."""
    a = SQRT2 * r0
    x = np.sort(fcc_sites(r0, rot, np.full(3, -2 * a), np.full(3, 2 * a))[:, axis])
    x = x[np.concatenate([[True], np.diff(x) > 1e-6 * r0])]
    d = float(np.diff(x).min()) if len(x) > 1 else 0.0
    return d if d > 0.2 * r0 else 0.0


def _centred_offset(length, d):
    """Offset (0 or d/2) of the planes from a body's mid-plane whose plane count n has n d nearest
    ``length`` (the planes in [-length/2, length/2))."""
    if d <= 0:
        return 0.0
    best = None
    for o in (0.0, 0.5 * d):
        k = np.arange(-int(length / d) - 2, int(length / d) + 3)
        x = o + k * d
        n = int(np.count_nonzero((x >= -0.5 * length) & (x < 0.5 * length)))
        if best is None or abs(n * d - length) < best[0] - 1e-9 * d:
            best = (abs(n * d - length), o)
    return best[1]


def _single_crystal(r0, rot, shape, center, fit):
    """fcc sites of rotation ``rot`` inside ``shape``.

    A site sits at ``center`` shifted, along each lab axis ``i`` of ``fit``
    (a dict axis -> body length), by 0 or half the plane spacing, whichever
    puts the number of planes n closest to the length (n d ~ length); a
    further 1e-7 r0 keeps planes off the faces' round-off.
    """
    lo, hi = shape.bounds()
    a = SQRT2 * r0
    anchor = np.asarray(center, float) + 1e-7 * r0
    for i, length in fit.items():
        anchor[i] += _centred_offset(length, plane_spacing(r0, rot, i))
    pts = fcc_sites(r0, rot, lo - a, hi + a)
    k = int(np.argmin(((pts - anchor) ** 2).sum(axis=1)))
    pts = pts + (anchor - pts[k])       # a translation by less than a/2: the box still covers the shape
    return pts[shape.contains(pts)]


def _shape_volume(shape):
    if isinstance(shape, Box):
        return float(np.prod(shape.hi - shape.lo))
    if isinstance(shape, Sphere):
        return 4.0 / 3.0 * math.pi * shape.radius ** 3
    return math.pi * shape.radius ** 2 * shape.length


def _bbox_cell(atoms):
    """Cell = bounding box of the cluster spheres; ``info['origin']`` its lower corner."""
    if len(atoms) == 0:
        return
    r = atoms.arrays["radius"][:, None]
    lo = (atoms.positions - r).min(axis=0)
    hi = (atoms.positions + r).max(axis=0)
    atoms.set_cell(np.diag(hi - lo))
    atoms.info["origin"] = lo.tolist()


def _body(kind, material, r0, shape, *, axis, fit, velocity, orientation, grain_size, n_grains, seed,
          d_min, target_porosity, mass, geometry):
    """Shared tail of the builders: fill ``shape``, set arrays, masses, velocity, info."""
    mat = get_material(material)
    if mat.curve is None:
        raise InputError("material", mat.name, "a material with a cold curve (CD)")
    v = _vec3("velocity", velocity)
    if mass not in MASS_CHOICES:
        raise InputError("mass", mass, "'cluster' (material mass per cluster) or 'dense' (full-density body)")
    poly = grain_size is not None or n_grains is not None or target_porosity is not None
    vol = _shape_volume(shape)
    if poly:
        if orientation is not None:
            raise InputError("orientation", orientation,
                             "None for a polycrystal (grain orientations are random; set seed)")
        if grain_size is None and n_grains is None:
            raise InputError("grain_size", None, "a grain size or n_grains for a polycrystal (target_porosity given)")
        atoms = polycrystal(mat, r0, shape, grain_size=grain_size, n_grains=n_grains, seed=seed, d_min=d_min,
                            target_porosity=target_porosity)
        report = atoms.info.pop("polycrystal")
        rots = np.asarray(atoms.info.pop("grain_rotations"))
        seeds = np.asarray(atoms.info.pop("grain_seeds"))
        atoms.info.pop("origin", None)
        structure = {"structure": "polycrystal", "n_grains": int(report["n_grains"]),
                     "grain_size_A": None if grain_size is None else float(grain_size),
                     "seed": seed, "d_min_r0": report["d_min_r0"], "polycrystal": report}
    else:
        rot = crystal_rotation(orientation, axis)
        pos = _single_crystal(r0, rot, shape, np.asarray(shape.bounds()).mean(axis=0), fit)
        if len(pos) == 0:
            raise InputError("size", geometry, f"a body that holds at least one cluster of r0 = {r0:.4g} A")
        order = np.lexsort((pos[:, 2], pos[:, 1], pos[:, 0]))
        atoms = make_cluster_atoms(pos[order], [mat], [r0])
        atoms.new_array("grain", np.zeros(len(atoms), np.int64))
        rots = rot[None]
        seeds = np.asarray(shape.bounds()).mean(axis=0)[None]
        structure = {"structure": "single crystal", "n_grains": 1, "rotation": rot.tolist()}
    n = len(atoms)
    atoms.new_array("body", np.zeros(n, np.int64))
    m_cluster = mat.rho0 * r0 ** 3 / SQRT2
    factor = vol * mat.rho0 / (n * m_cluster) if mass == "dense" else 1.0
    atoms.set_masses(np.full(n, m_cluster * factor))
    atoms.set_velocities(np.broadcast_to(v, (n, 3)))
    atoms.pbc = False
    _bbox_cell(atoms)
    atoms.info["grain_rotations"] = rots
    atoms.info["grain_seeds"] = seeds
    center = np.asarray(shape.bounds()).mean(axis=0)
    porosity = 1.0 - n * r0 ** 3 / SQRT2 / vol
    info = {"kind": kind, "material": mat.name, "r0": float(r0), "axis": int(axis),
            "center": center.tolist(), **geometry, "volume_A3": vol,
            "velocity": v.tolist(), "velocity_km_s": (v / units.km_s).tolist(),
            "n_clusters": int(n), "porosity": float(porosity),
            "mass_choice": mass, "mass_factor": float(factor), "mass_amu": float(n * m_cluster * factor),
            "density_g_cm3": float(n * m_cluster * factor / vol / units.g_cm3),
            "grain_offset": 0, **structure}
    atoms.info["bodies"] = [info]
    return atoms


def _sizes(**kw):
    return {k: check_positive(k, v) for k, v in kw.items()}


def rod(material, r0, length, diameter, *, axis=0, center=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0),
        orientation=None, grain_size=None, n_grains=None, seed=None, d_min=DEFAULT_D_MIN,
        target_porosity=None, mass="cluster"):
    """A cylindrical rod (a Taylor rod): length along ``axis``, circular cross-section.

    Parameters
    ----------
    material : str or Material
        A CD material (with a cold curve).
    r0 : float
        Cluster size, Angstrom.
    length, diameter : float
        Angstrom, > 0.
    axis : 0, 1, 2 or 'x', 'y', 'z'
        The rod's axis.
    center : (3,) floats
        Geometric centre (centroid of the cylinder), Angstrom.
    velocity : (3,) floats
        Initial velocity of every cluster, ASE units (``units.km_s``).
    orientation : None, Miller direction or (3, 3) rotation
        Single crystal: the crystal direction along ``axis`` (default [100])
        or a rotation (:func:`crystal_rotation`).  Must be None for a polycrystal.
    grain_size, n_grains, seed, d_min, target_porosity :
        Give ``grain_size`` (Angstrom, diameter of the sphere of the mean grain
        volume) or ``n_grains`` for a polycrystal; passed to
        :func:`~clusterdyn.build.polycrystal.polycrystal`.
    mass : "cluster" or "dense"
        Keep the material's cluster mass, or scale to the full-density mass
        (module docstring).

    Returns
    -------
    ase.Atoms
        One body: arrays ``material``, ``radius``, ``id``, ``grain``, ``body``;
        momenta set; ``info['bodies']``, ``['grain_rotations']``, ``['grain_seeds']``.
    """
    s = _sizes(r0=r0, length=length, diameter=diameter)
    ax = parse_axis(axis)
    c = _vec3("center", center)
    e = np.eye(3)[ax]
    base = c - 0.5 * s["length"] * e
    shape = Cylinder(base, 0.5 * s["diameter"], s["length"], ax)
    return _body("rod", material, s["r0"], shape, axis=ax, fit={ax: s["length"]}, velocity=velocity,
                 orientation=orientation, grain_size=grain_size, n_grains=n_grains, seed=seed, d_min=d_min,
                 target_porosity=target_porosity, mass=mass,
                 geometry={"length_A": s["length"], "diameter_A": s["diameter"]})


def sphere(material, r0, diameter, *, center=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), axis=0,
           orientation=None, grain_size=None, n_grains=None, seed=None, d_min=DEFAULT_D_MIN,
           target_porosity=None, mass="cluster"):
    """A sphere of ``diameter`` (Angstrom) centred at ``center``, a lattice site at its centre.

    ``axis`` is the lab axis the Miller ``orientation`` refers to (default [100]
    along x).  Other parameters as :func:`rod`.
    """
    s = _sizes(r0=r0, diameter=diameter)
    ax = parse_axis(axis)
    c = _vec3("center", center)
    shape = Sphere(c, 0.5 * s["diameter"])
    return _body("sphere", material, s["r0"], shape, axis=ax, fit={}, velocity=velocity,
                 orientation=orientation, grain_size=grain_size, n_grains=n_grains, seed=seed, d_min=d_min,
                 target_porosity=target_porosity, mass=mass, geometry={"diameter_A": s["diameter"]})


def plate(material, r0, thickness, *, radius=None, width=None, axis=0, center=(0.0, 0.0, 0.0),
          velocity=(0.0, 0.0, 0.0), orientation=None, grain_size=None, n_grains=None, seed=None,
          d_min=DEFAULT_D_MIN, target_porosity=None, mass="cluster"):
    """A plate of finite lateral size: ``thickness`` along ``axis``, round or rectangular.

    Parameters not listed here are as for :func:`rod` (``center`` is the plate's centroid).

    Parameters
    ----------
    thickness : float
        Along ``axis``, Angstrom.
    radius : float, optional
        A round plate (a disc), Angstrom.
    width : float or (2,) floats, optional
        A rectangular plate: widths along the two other axes in increasing
        order (e.g. axis z: x then y), Angstrom.  Give exactly one of
        ``radius`` and ``width``.
    """
    s = _sizes(r0=r0, thickness=thickness)
    ax = parse_axis(axis)
    c = _vec3("center", center)
    e = np.eye(3)[ax]
    if (radius is None) == (width is None):
        raise InputError("radius", radius, "exactly one of radius (round plate) or width (rectangular plate)")
    base = c - 0.5 * s["thickness"] * e
    if radius is not None:
        rad = check_positive("radius", radius)
        shape = Cylinder(base, rad, s["thickness"], ax)
        geometry = {"thickness_A": s["thickness"], "radius_A": rad}
    else:
        try:
            w = np.broadcast_to(np.asarray(width, dtype=float), (2,))
        except (TypeError, ValueError):
            raise InputError("width", width, "one or two positive lengths (Angstrom)") from None
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise InputError("width", width, "one or two positive lengths (Angstrom)")
        ext = np.empty(3)
        ext[ax] = s["thickness"]
        ext[[d for d in range(3) if d != ax]] = w
        shape = Box(c - 0.5 * ext, c + 0.5 * ext)
        geometry = {"thickness_A": s["thickness"], "width_A": w.tolist()}
    fit = {ax: s["thickness"]} if radius is not None else {i: float(shape.hi[i] - shape.lo[i]) for i in range(3)}
    return _body("plate", material, s["r0"], shape, axis=ax, fit=fit,
                 velocity=velocity, orientation=orientation, grain_size=grain_size, n_grains=n_grains,
                 seed=seed, d_min=d_min, target_porosity=target_porosity, mass=mass, geometry=geometry)


def _extent(atoms, ax):
    x = atoms.positions[:, ax]
    r = atoms.arrays["radius"]
    return float((x - r).min()), float((x + r).max())


def translate(body, shift):
    """Copy of ``body`` moved by ``shift`` (Angstrom), its ``info`` (centres, grain seeds) kept in step."""
    s = _vec3("shift", shift)
    out = body.copy()
    out.positions += s
    out.info["bodies"] = [dict(b, center=(np.asarray(b["center"]) + s).tolist()) for b in body.info.get("bodies", [])]
    if "grain_seeds" in body.info:
        out.info["grain_seeds"] = np.asarray(body.info["grain_seeds"]) + s
    if "origin" in body.info:
        out.info["origin"] = (np.asarray(body.info["origin"]) + s).tolist()
    return out


def _lateral_center(atoms):
    b = atoms.info.get("bodies")
    if b:
        return np.mean([x["center"] for x in b], axis=0)
    return atoms.positions.mean(axis=0)


def place(body, on, *, axis, gap, side=1, align=True):
    """Move ``body`` along ``axis`` to ``gap`` from ``on`` (a copy is returned).

    Parameters
    ----------
    body, on : ase.Atoms
        Bodies from this module (or any clusterdyn Atoms with ``radius``).
    axis : 0, 1, 2 or 'x', 'y', 'z'
    gap : float
        Clearance between the clusters' spheres along ``axis``, Angstrom, >= 0
        (module docstring): e.g. ``0.5 * r0`` puts a sphere half a cluster
        size above a plate, every pair across at least 1.5 r0 apart.
    side : +1 or -1
        +1: ``body`` above ``on`` (larger coordinate), -1: below.
    align : bool
        Also move ``body`` across ``axis`` so its geometric centre lies on
        ``on``'s (the mean of its bodies' centres).

    Returns
    -------
    ase.Atoms
        The moved copy (positions, ``info`` centres and grain seeds).
    """
    ax = parse_axis(axis)
    g = check_positive("gap", gap, allow_zero=True)
    if side not in (1, -1):
        raise InputError("side", side, "+1 (above) or -1 (below)")
    lo_b, hi_b = _extent(body, ax)
    lo_o, hi_o = _extent(on, ax)
    shift = np.zeros(3)
    shift[ax] = (hi_o + g - lo_b) if side == 1 else (lo_o - g - hi_b)
    if align:
        d = _lateral_center(on) - _lateral_center(body)
        d[ax] = 0.0
        shift += d
    return translate(body, shift)


def plate_stack(layers, r0, radius, *, gaps=0.0, axis=0, origin=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0),
                orientation=None, grain_size=None, seed=None, d_min=DEFAULT_D_MIN, mass="cluster"):
    """A stack of round plates of different materials along ``axis``, with gaps, one body per plate.

    Parameters
    ----------
    layers : list of (material, thickness)
        From the lowest coordinate up; thickness in Angstrom.
    r0 : float or list of floats
        Cluster size (one for all plates or one per plate), Angstrom.
    radius : float
        Common lateral radius of the plates, Angstrom.
    gaps : float or list of floats
        Clearance between consecutive plates (``len(layers) - 1`` values, or
        one for all), Angstrom, >= 0, measured as in :func:`place`; 0 =
        plates in contact.
    origin : (3,) floats
        Centre of the first plate's lower face, Angstrom.
    velocity : (3,) floats
        Velocity of the whole stack, ASE units.
    orientation, grain_size, seed, d_min, mass :
        As :func:`plate`, for every plate; a polycrystal plate k uses
        ``seed + k``.

    Returns
    -------
    ase.Atoms
        The plates combined (:func:`combine_bodies`): body id k = plate k.
    """
    if isinstance(layers, (str, bytes)) or not hasattr(layers, "__len__") or len(layers) == 0:
        raise InputError("layers", layers, "a non-empty list of (material, thickness)")
    try:
        mats = [m for m, _ in layers]
        thick = [check_positive("thickness", t) for _, t in layers]
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError("layers", layers, "a non-empty list of (material, thickness)") from None
    n = len(layers)
    r0s = np.broadcast_to(np.asarray(r0, dtype=float), (n,)) if np.ndim(r0) == 0 else np.asarray(r0, float)
    if r0s.shape != (n,):
        raise InputError("r0", r0, f"one cluster size or {n} (one per layer)")
    gl = np.broadcast_to(np.asarray(gaps, dtype=float), (n - 1,)) if np.ndim(gaps) == 0 else \
        np.asarray(gaps, dtype=float)
    if gl.shape != (n - 1,) or not np.all(np.isfinite(gl)) or np.any(gl < 0):
        raise InputError("gaps", gaps, f"one gap >= 0 or {n - 1} (between consecutive plates), Angstrom")
    ax = parse_axis(axis)
    o = _vec3("origin", origin)
    e = np.eye(3)[ax]
    grains = grain_size is not None
    plates = []
    for k, (m, t) in enumerate(zip(mats, thick)):
        p = plate(m, r0s[k], t, radius=radius, axis=ax, center=o + 0.5 * t * e, velocity=velocity,
                  orientation=orientation, grain_size=grain_size, seed=None if (seed is None or not grains)
                  else seed + k, d_min=d_min, mass=mass)
        if k:
            p = place(p, plates[-1], axis=ax, gap=float(gl[k - 1]), side=1, align=True)
        plates.append(p)
    return combine_bodies(plates)


def combine_bodies(bodies, *, min_distance=1.0):
    """Combine bodies into one Atoms with stable ids and one material table.

    Parameters
    ----------
    bodies : list of ase.Atoms
        Bodies from this module (a stack counts as its plates) or any
        clusterdyn Atoms (``material``, ``radius``, ``info['cd_materials']``,
        ``['cd_r0']``); missing ``body``/``grain`` arrays count as one body,
        one grain.
    min_distance : float
        Refuse bodies with two clusters closer than ``min_distance (R_i + R_j)``
        (R = r0/2, so 1.0 = closer than the bond length: overlapping).

    Returns
    -------
    ase.Atoms
        ``pbc`` False; arrays ``material`` (merged table), ``radius``, ``id``
        (``offset_b + id``), ``body`` and ``grain`` (offset per body), momenta
        and masses as given; ``info['cd_materials']``, ``['cd_r0']``,
        ``['bodies']`` (concatenated, with ``grain_offset`` and the body id
        as ``body``), ``['grain_rotations']`` when every body has them.
    """
    if isinstance(bodies, Atoms) or not hasattr(bodies, "__len__") or len(bodies) == 0:
        raise InputError("bodies", type(bodies).__name__, "a non-empty list of Atoms")
    min_distance = check_positive("min_distance", min_distance, allow_zero=True)
    table = []          # (name, r0)
    parts = {k: [] for k in ("positions", "numbers", "masses", "momenta", "material", "radius", "id", "body",
                             "grain")}
    extra_names = None
    infos, rots, seeds = [], [], []
    id_off = body_off = grain_off = 0
    for b, at in enumerate(bodies):
        if not isinstance(at, Atoms):
            raise InputError("bodies", type(at).__name__, "a list of ase.Atoms")
        for key in ("material", "radius"):
            if key not in at.arrays:
                raise InputError(f"bodies[{b}]", f"Atoms without arrays['{key}']", "clusters from clusterdyn.build")
        if np.any(at.pbc):
            raise InputError(f"bodies[{b}]", f"Atoms with pbc={at.pbc.tolist()}", "open bodies (pbc False)")
        if "bonds0" in at.arrays:
            raise InputError(f"bodies[{b}]", "Atoms with arrays['bonds0']",
                             "bodies without set-up bonds (call mark_initial_bonds on the combined Atoms)")
        names, r0s = at.info.get("cd_materials"), at.info.get("cd_r0")
        if names is None or r0s is None:
            raise InputError(f"bodies[{b}]", "Atoms without info['cd_materials'] / ['cd_r0']",
                             "clusters from clusterdyn.build")
        r0s = list(np.broadcast_to(np.asarray(r0s, float), (len(names),)))
        remap = []
        for name, r in zip(names, r0s):
            name = name if isinstance(name, str) else get_material(name).name
            hit = [i for i, (nm, rr) in enumerate(table) if nm == name and abs(rr - r) <= 1e-12 * abs(r)]
            if not hit:
                table.append((name, float(r)))
                hit = [len(table) - 1]
            remap.append(hit[0])
        n = len(at)
        ids = at.arrays.get("id", np.arange(n, dtype=np.int64))
        bid = at.arrays.get("body", np.zeros(n, np.int64))
        gid = at.arrays.get("grain", np.zeros(n, np.int64))
        parts["positions"].append(at.positions)
        parts["numbers"].append(at.numbers)
        parts["masses"].append(at.get_masses())
        parts["momenta"].append(at.get_momenta())
        parts["material"].append(np.asarray(remap, np.int64)[at.arrays["material"]])
        parts["radius"].append(at.arrays["radius"])
        parts["id"].append(ids + id_off)
        parts["body"].append(bid + body_off)
        parts["grain"].append(gid + grain_off)
        extra = {k for k in at.arrays if k not in parts and k not in ("numbers", "positions", "masses", "momenta")}
        if extra_names is None:
            extra_names = extra
        elif extra != extra_names:
            raise InputError(f"bodies[{b}]", f"arrays {sorted(extra)}",
                             f"the same extra per-particle arrays as bodies[0] ({sorted(extra_names)})")
        n_bodies = int(bid.max()) + 1 if n else 1
        n_grain_ids = int(gid.max()) + 1 if n else 1
        r = at.info.get("grain_rotations")
        if r is not None:
            n_grain_ids = max(n_grain_ids, len(r))
            rots.append(np.asarray(r))
            s = at.info.get("grain_seeds")
            seeds.append(np.asarray(s) if s is not None else np.full((len(r), 3), np.nan))
        else:
            rots.append(None)
        given = at.info.get("bodies") or [
            {"kind": "block", "material": names[int(at.arrays["material"][bid == k][0])] if np.any(bid == k)
             else names[0], "center": at.positions[bid == k].mean(axis=0).tolist() if np.any(bid == k)
             else [0.0, 0.0, 0.0]} for k in range(n_bodies)]
        for k, d in enumerate(given):
            d = dict(d)
            d["body"] = body_off + k
            d["grain_offset"] = d.get("grain_offset", 0) + grain_off
            infos.append(d)
        id_off += int(ids.max()) + 1 if n else 0
        body_off += n_bodies
        grain_off += n_grain_ids
    out = Atoms(numbers=np.concatenate(parts["numbers"]), positions=np.vstack(parts["positions"]), pbc=False)
    out.set_masses(np.concatenate(parts["masses"]))
    out.set_momenta(np.vstack(parts["momenta"]))
    for k in ("material", "radius", "id", "body", "grain"):
        out.new_array(k, np.concatenate(parts[k]))
    for k in sorted(extra_names or ()):
        out.new_array(k, np.concatenate([at.arrays[k] for at in bodies]))
    out.info["cd_materials"] = [t[0] for t in table]
    out.info["cd_r0"] = [t[1] for t in table]
    out.info["bodies"] = infos
    if all(r is not None for r in rots):
        out.info["grain_rotations"] = np.concatenate(rots)
        out.info["grain_seeds"] = np.concatenate(seeds)
    _check_overlap(out, min_distance)
    _bbox_cell(out)
    return out


def _check_overlap(atoms, min_distance):
    """Refuse clusters of different bodies closer than ``min_distance (R_i + R_j)`` (one line)."""
    if min_distance <= 0 or len(atoms) < 2:
        return
    pos, rad, bid = atoms.positions, atoms.arrays["radius"], atoms.arrays["body"]
    reach = 2.0 * rad.max() * min_distance
    ids = np.unique(bid)
    boxes = {b: (pos[bid == b].min(axis=0) - reach, pos[bid == b].max(axis=0) + reach) for b in ids}
    for ia, a in enumerate(ids):
        ia_rows = np.flatnonzero(bid == a)
        tree = None
        for b in ids[ia + 1:]:
            lo = np.maximum(boxes[a][0], boxes[b][0])
            hi = np.minimum(boxes[a][1], boxes[b][1])
            if np.any(lo > hi):
                continue
            jb = np.flatnonzero(bid == b)
            jb = jb[np.all((pos[jb] >= lo) & (pos[jb] <= hi), axis=1)]
            if len(jb) == 0:
                continue
            if tree is None:
                tree = cKDTree(pos[ia_rows])
            d, k = tree.query(pos[jb], distance_upper_bound=reach)
            ok = np.isfinite(d)
            if not ok.any():
                continue
            i = ia_rows[k[ok]]
            j = jb[ok]
            lim = min_distance * (rad[i] + rad[j])
            bad = np.flatnonzero(d[ok] < lim * (1 - 1e-9))
            if len(bad):
                w = bad[np.argmin(d[ok][bad] / lim[bad])]
                raise InputError("bodies", f"bodies {a} and {b} overlapping",
                                 f"clusters of different bodies at least {min_distance:g} (R_i + R_j) apart "
                                 "(place them with place(..., gap=...))",
                                 hint=f"clusters {int(i[w])} and {int(j[w])} at {d[ok][w] / (2 * rad[i[w]]):.3g} r0")
