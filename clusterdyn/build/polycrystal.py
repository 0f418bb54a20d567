"""Polycrystals of clusters (CD, docs/theory.md 1.7): Voronoi grains of randomly oriented fcc packings.

Construction, step by step (every step is deterministic given ``seed``):

1. **Grain seeds.** ``n_grains`` points drawn uniformly inside the shape
   (rejection sampling in its bounding box), or the points given in
   ``seeds``.  With ``grain_size`` instead of ``n_grains``, the number of
   grains is ``round(V_shape / (pi/6 grain_size^3))``: ``grain_size`` is the
   diameter of the sphere of the mean grain volume.
2. **Orientations.** One rotation per grain, uniform on SO(3)
   (:meth:`scipy.spatial.transform.Rotation.random`), or those given in
   ``rotations``.  Convention as :func:`~clusterdyn.build.lattice.fcc_sites`:
   ``lab = R @ crystal`` (the columns of R are the cube axes in the lab).
3. **Voronoi cells.** A cluster belongs to the grain whose seed is nearest
   (minimum image across periodic axes).  The cells are computed exactly
   (Qhull, :class:`scipy.spatial.Voronoi`) on the seeds plus their periodic
   images (periodic axes) or mirror images (free faces of the bounding box),
   so every cell is bounded and clipped to the box.
4. **Filling.** Each grain's fcc lattice (nearest-neighbour distance r0,
   lattice origin at the corner of the cell's bounding box) is generated
   over the bounding box of its cell only, and the sites inside the cell
   (half-space tests against its Voronoi neighbours) are kept.  Across a
   periodic axis a cell may stick out of the box; its sites are wrapped back,
   so grains continue across periodic faces.  Non-box shapes are then carved
   with ``shape.contains``.
5. **Boundary rule.** Clusters of *different* grains closer than
   ``d_min * r0`` (and clusters of one grain closer than 0.99 r0, which only
   happens where a grain meets its own periodic image) are "close pairs".
   Close pairs are removed greedily: in each round every cluster whose key
   ``(number of close contacts, grain id, index)`` is larger than the keys of
   all its close partners is removed (so the cluster with the most close
   contacts goes first, ties go to the higher grain id), its pairs are
   dropped, and rounds repeat until no close pair is left.  This removes
   close to the fewest clusters needed, which keeps porosity low.
6. **Check.** The smallest distance between remaining clusters is measured
   and stored; it is >= ``d_min r0`` by construction.

The porosity is ``1 - rho/rho0 = 1 - N r0^3 / (sqrt(2) V_shape)``.  With
``target_porosity``, ``d_min`` is chosen by bisection in
``[D_MIN_RANGE[0], D_MIN_RANGE[1]]`` (in r0) to reach it; a target outside
the range the rule can reach is refused with that range.

The returned Atoms carries ``arrays['grain']`` (int64, the grain id = seed
index), ``info['grain_rotations']`` ((G, 3, 3) lab = R @ crystal),
``info['grain_seeds']`` ((G, 3), Angstrom) and ``info['polycrystal']`` (a dict
report: porosity, d_min, clusters removed, grain statistics, build time).
"""

import math
import time

import numpy as np
from scipy.spatial import Voronoi, cKDTree
from scipy.spatial.transform import Rotation

from .. import units
from ..errors import InputError, check_positive
from ..materials import get_material
from .lattice import SQRT2, fcc_sites, make_cluster_atoms
from .shapes import Box, Cylinder, Sphere

#: smallest grain size allowed (diameter of the equal-volume sphere), in r0
MIN_GRAIN_SIZE = 3.0
#: default minimum distance at grain boundaries, in r0
DEFAULT_D_MIN = 0.85
#: range of d_min (in r0) searched for a target porosity
D_MIN_RANGE = (0.6, 1.1)
#: same-grain pairs closer than this (in r0) are defects (a grain meeting its own periodic image)
_SAME_GRAIN_TOL = 0.99


def shape_volume(shape):
    """Volume of a Box, Sphere or Cylinder (Angstrom^3)."""
    if isinstance(shape, Box):
        return float(np.prod(shape.hi - shape.lo))
    if isinstance(shape, Sphere):
        return 4.0 / 3.0 * math.pi * shape.radius ** 3
    if isinstance(shape, Cylinder):
        return math.pi * shape.radius ** 2 * shape.length
    raise InputError("shape", shape, "a Box, Plate, Sphere or Cylinder")


def _parse_shape(shape, size):
    if shape is not None and size is not None:
        raise InputError("size", size, "None when shape is given (give one of shape, size)")
    if shape is None:
        if size is None:
            raise InputError("shape", None, "a Box, Plate, Sphere or Cylinder, or size=(Lx, Ly, Lz)")
        s = np.asarray(size, dtype=float)
        if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise InputError("size", size, "three positive lengths (Angstrom)")
        return Box((0.0, 0.0, 0.0), s)
    if not isinstance(shape, (Box, Sphere, Cylinder)):
        raise InputError("shape", shape, "a Box, Plate, Sphere or Cylinder")
    return shape


def _parse_pbc(pbc, shape):
    p = np.broadcast_to(np.asarray(pbc, dtype=bool), (3,)).copy()
    if p.any() and not isinstance(shape, Box):
        raise InputError("pbc", pbc, "False for a Sphere or Cylinder (periodic axes need a Box or Plate)")
    return p


def _random_seeds(rng, shape, n):
    lo, hi = shape.bounds()
    out = np.empty((0, 3))
    while len(out) < n:
        pts = lo + rng.random((max(2 * n, 64), 3)) * (hi - lo)
        out = np.vstack([out, pts[shape.contains(pts)]])
    return out[:n]


def _rotation_matrices(rotations, n):
    if isinstance(rotations, Rotation):
        m = rotations.as_matrix().reshape(-1, 3, 3)
    else:
        m = np.asarray(rotations, dtype=float)
    if m.shape != (n, 3, 3):
        raise InputError("rotations", f"array of shape {m.shape}", f"{n} rotation matrices, shape ({n}, 3, 3)")
    if not np.allclose(np.einsum("gij,gkj->gik", m, m), np.eye(3), atol=1e-8) or \
            not np.allclose(np.linalg.det(m), 1.0, atol=1e-8):
        raise InputError("rotations", "matrices", "proper rotations (orthogonal, det = +1)")
    return m


def _extended_seeds(seeds, lo, hi, pbc, margin):
    """Seeds plus periodic images (periodic axes) or mirror images (free faces) within ``margin``."""
    pts = seeds.copy()
    src = np.arange(len(seeds))
    L = hi - lo
    for d in range(3):
        if pbc[d]:
            images = [(pts[:, d] + L[d], 1), (pts[:, d] - L[d], 1)]
        else:
            images = [(2 * lo[d] - pts[:, d], 0), (2 * hi[d] - pts[:, d], 0)]
        new_p, new_s = [pts], [src]
        for x, _ in images:
            keep = (x > lo[d] - margin) & (x < hi[d] + margin) & (np.abs(x - pts[:, d]) > 1e-9 * (1 + L[d]))
            q = pts[keep].copy()
            q[:, d] = x[keep]
            new_p.append(q)
            new_s.append(src[keep])
        pts = np.vstack(new_p)
        src = np.concatenate(new_s)
    return pts, src


def _voronoi_cells(seeds, lo, hi, pbc):
    """For each seed: (bbox lo, bbox hi, neighbour points) of its Voronoi cell (clipped/periodic)."""
    n = len(seeds)
    L = hi - lo
    spacing = (np.prod(L) / n) ** (1.0 / 3.0)
    margin = 3.0 * spacing
    while True:
        ext, _ = _extended_seeds(seeds, lo, hi, pbc, margin)
        if len(ext) < 5:
            raise InputError("n_grains", n, "enough grains for a 3-D Voronoi tessellation")
        vor = Voronoi(ext)
        cells = []
        ok = True
        neigh = [[] for _ in range(n)]
        for a, b in vor.ridge_points:
            if a < n:
                neigh[a].append(b)
            if b < n:
                neigh[b].append(a)
        for g in range(n):
            reg = vor.regions[vor.point_region[g]]
            if len(reg) == 0 or -1 in reg:
                ok = False
                break
            v = vor.vertices[reg]
            rho = np.linalg.norm(v - seeds[g], axis=1)[:, None]
            # exact only if every vertex's empty sphere lies where all images were included
            if np.any(v - rho < lo - margin) or np.any(v + rho > hi + margin):
                ok = False
                break
            cells.append((v.min(axis=0), v.max(axis=0), ext[np.array(neigh[g], dtype=np.int64)]))
        if ok or margin > 4 * L.max():
            if not ok:
                raise InputError("n_grains", n, "a tessellation Qhull can close (seeds too few or degenerate)")
            return cells
        margin *= 2.0


def _close_pairs(pos, grain, lo, hi, pbc, r0, d_max):
    """Pairs closer than d_max*r0 that count at a boundary, with their distances (r0 units)."""
    box = np.where(pbc, hi - lo, 0.0)
    rel = pos - lo
    if pbc.any():
        rel = np.where(pbc, np.mod(rel, np.where(pbc, hi - lo, 1.0)), rel)
    tree = cKDTree(rel, boxsize=box if pbc.any() else None)
    pairs = tree.query_pairs(d_max * r0, output_type="ndarray")
    if len(pairs) == 0:
        return pairs.reshape(0, 2), np.zeros(0)
    d = rel[pairs[:, 1]] - rel[pairs[:, 0]]
    if pbc.any():
        Lp = np.where(pbc, hi - lo, np.inf)
        d = np.where(pbc, d - np.round(d / np.where(pbc, Lp, 1.0)) * np.where(pbc, Lp, 0.0), d)
    r = np.linalg.norm(d, axis=1) / r0
    same = grain[pairs[:, 0]] == grain[pairs[:, 1]]
    keep = ~same | (r < _SAME_GRAIN_TOL)
    return pairs[keep], r[keep]


def _greedy_removal(n, pairs):
    """Clusters to remove so that no pair is left (rounds of local maxima of the contact count)."""
    removed = np.zeros(n, dtype=bool)
    p = pairs
    while len(p):
        deg = np.bincount(p.ravel(), minlength=n).astype(np.int64)
        key = deg * n + np.arange(n)            # index order = (grain, position) order: ties -> higher grain
        best = np.zeros(n, dtype=np.int64) - 1
        np.maximum.at(best, p[:, 0], key[p[:, 1]])
        np.maximum.at(best, p[:, 1], key[p[:, 0]])
        top = (deg > 0) & (key > best)
        removed |= top
        p = p[~(top[p[:, 0]] | top[p[:, 1]])]
    return removed


def _fill_grains(r0, seeds, rots, lo, hi, pbc, cells):
    pos_list, grain_list = [], []
    L = hi - lo
    for g, (clo, chi, nb) in enumerate(cells):
        pts = fcc_sites(r0, rots[g], clo, chi + 1e-6 * r0)
        if len(pts) and len(nb):
            s = seeds[g]
            # p in cell g  <=>  2 p.(n - s) < |n|^2 - |s|^2 for every Voronoi neighbour n
            lhs = 2.0 * (pts - s) @ (nb - s).T
            rhs = ((nb - s) ** 2).sum(axis=1)
            pts = pts[np.all(lhs < rhs[None, :], axis=1)]
        pos_list.append(pts)
        grain_list.append(np.full(len(pts), g, dtype=np.int64))
    pos = np.vstack(pos_list)
    grain = np.concatenate(grain_list)
    if pbc.any():
        rel = pos - lo
        rel = np.where(pbc, np.mod(rel, np.where(pbc, L, 1.0)), rel)
        pos = rel + lo
    inside = np.all(np.where(pbc, True, (pos >= lo - 1e-9 * r0) & (pos < hi - 1e-9 * r0)), axis=1)
    return pos[inside], grain[inside]


def grain_statistics(atoms, r0=None):
    """Grain statistics of a sample with ``arrays['grain']``.

    Returns a dict: number of grains with clusters, clusters per grain (mean,
    std, min, max), mean equivalent grain diameter (in r0 and um), from
    ``N_g r0^3/sqrt(2) = pi/6 d^3``.
    """
    if "grain" not in atoms.arrays:
        raise InputError("atoms", "Atoms without 'grain'", "a polycrystal (arrays['grain'])")
    r0 = float(atoms.info["cd_r0"][0]) if r0 is None else r0
    counts = np.bincount(atoms.arrays["grain"])
    counts = counts[counts > 0]
    d = (6.0 / math.pi * counts / SQRT2) ** (1.0 / 3.0)          # in r0
    return {"n_grains": int(len(counts)),
            "clusters_per_grain_mean": float(counts.mean()),
            "clusters_per_grain_std": float(counts.std()),
            "clusters_per_grain_min": int(counts.min()),
            "clusters_per_grain_max": int(counts.max()),
            "grain_diameter_mean_r0": float(d.mean()),
            "grain_diameter_mean_um": float(d.mean() * r0 / units.um)}


def polycrystal(material, r0, shape=None, *, size=None, n_grains=None, grain_size=None, seed=None,
                pbc=False, seeds=None, rotations=None, d_min=DEFAULT_D_MIN, target_porosity=None,
                porosity_tol=0.002):
    """Polycrystal of fcc clusters in Voronoi grains of random orientation.

    Parameters
    ----------
    material : Material or str
    r0 : float
        Cluster size (nearest-neighbour distance), Angstrom.
    shape : Box | Plate | Sphere | Cylinder, optional
        Region to fill (a Cylinder along x is a Taylor rod).  Or give ``size``.
    size : (3,) floats, optional
        Box lengths (Angstrom), box from the origin.
    n_grains : int, optional
        Number of grains (>= 1).  Give exactly one of ``n_grains``,
        ``grain_size`` or ``seeds``.
    grain_size : float, optional
        Mean grain diameter (Angstrom): diameter of the sphere of the mean
        grain volume; >= 3 r0 and no larger than the shape holds.
    seed : int, optional
        Random seed (seeds, then rotations are drawn from one generator).
    pbc : bool or 3 bools
        Periodic axes (Box/Plate only); grains continue across periodic faces.
    seeds : (G, 3) array, optional
        Grain seed points (Angstrom) instead of random ones.
    rotations : (G, 3, 3) array or scipy Rotation, optional
        Grain orientations (``lab = R @ crystal``) instead of random ones.
    d_min : float
        Minimum distance at grain boundaries, in r0 (see module docstring).
    target_porosity : float, optional
        Choose ``d_min`` by bisection to reach this porosity (within
        ``porosity_tol``, or as close as the rule allows).

    Returns
    -------
    ase.Atoms
        Arrays ``material``, ``radius``, ``id``, ``grain``; info
        ``grain_rotations``, ``grain_seeds``, ``polycrystal`` (report dict).

    Raises
    ------
    InputError
        Zero or negative grains, grain size below 3 r0, a shape smaller than
        one grain, bad rotations, an unreachable target porosity.
    """
    t0 = time.perf_counter()
    mat = get_material(material)
    r0 = check_positive("r0", r0)
    shape = _parse_shape(shape, size)
    pbc = _parse_pbc(pbc, shape)
    vol = shape_volume(shape)
    d_min = check_positive("d_min", d_min)
    if not D_MIN_RANGE[0] <= d_min <= D_MIN_RANGE[1]:
        raise InputError("d_min", d_min, f"a distance in [{D_MIN_RANGE[0]}, {D_MIN_RANGE[1]}] r0")
    n_grains, seeds = _grain_count(r0, vol, n_grains, grain_size, seeds)

    rng = np.random.default_rng(seed)
    if seeds is None:
        seeds = _random_seeds(rng, shape, n_grains)
    lo, hi = shape.bounds()
    if np.any(seeds < lo) or np.any(seeds >= hi):
        raise InputError("seeds", "points outside the shape's bounds", f"points in [{lo.tolist()}, {hi.tolist()})")
    rots = (_rotation_matrices(rotations, n_grains) if rotations is not None
            else Rotation.random(n_grains, rng=rng).as_matrix().reshape(n_grains, 3, 3))
    pos, grain = _grain_sites(r0, shape, pbc, seeds, rots)
    n_sites = len(pos)
    removed, d_min = _boundary_removal(pos, grain, shape, pbc, r0, d_min, target_porosity, porosity_tol)
    target_porosity = None if target_porosity is None else float(target_porosity)
    pos, grain = pos[~removed], grain[~removed]
    if len(pos) == 0:
        raise InputError("shape", shape, f"a shape that holds at least one cluster of r0={r0:.4g} A")
    r_near = _nearest_distance(pos, lo, hi, pbc) / r0

    cell = np.diag(hi - lo)
    atoms = make_cluster_atoms(pos, [mat], [r0], cell=cell, pbc=pbc)
    if isinstance(shape, Box) and np.any(lo != 0):
        atoms.info["origin"] = lo.tolist()
    atoms.new_array("grain", grain)
    atoms.info["grain_rotations"] = rots
    atoms.info["grain_seeds"] = seeds
    porosity = 1.0 - len(pos) * (r0 ** 3 / SQRT2) / vol
    report = {"porosity": porosity,
              "density_g_cm3": mat.rho0 * (1.0 - porosity) / units.g_cm3,
              "d_min_r0": float(d_min),
              "target_porosity": target_porosity,
              "n_sites_before_removal": int(n_sites),
              "n_removed": int(n_sites - len(pos)),
              "n_clusters": int(len(pos)),
              "nearest_distance_r0": r_near,
              "n_seeds": n_grains,
              "shape_volume_A3": vol,
              "pbc": pbc.tolist()}
    report.update(grain_statistics(atoms, r0))
    report["build_time_s"] = time.perf_counter() - t0
    atoms.info["polycrystal"] = report
    return atoms


def _grain_count(r0, vol, n_grains, grain_size, seeds):
    """The number of grains from exactly one of ``n_grains``, ``grain_size`` or ``seeds`` (checked
    against the shape's volume ``vol``): returns (n_grains, seeds as an array or None)."""
    given = [x is not None for x in (n_grains, grain_size, seeds)]
    if sum(given) != 1 and not (seeds is not None and n_grains is not None and sum(given) == 2):
        raise InputError("n_grains", n_grains, "exactly one of n_grains, grain_size or seeds")
    if grain_size is not None:
        grain_size = check_positive("grain_size", grain_size)
        if grain_size < MIN_GRAIN_SIZE * r0 * (1 - 1e-9):
            raise InputError("grain_size", grain_size, f">= {MIN_GRAIN_SIZE:g} r0 = {MIN_GRAIN_SIZE * r0:.6g} A",
                             hint=f"{grain_size / r0:.3g} r0 given")
        v_grain = math.pi / 6.0 * grain_size ** 3
        if v_grain > vol * (1 + 1e-9):
            raise InputError("grain_size", grain_size,
                             f"a grain no larger than the shape (volume {vol:.4g} A^3 holds a grain of "
                             f"diameter <= {(6 * vol / math.pi) ** (1 / 3):.4g} A)")
        n_grains = max(1, int(round(vol / v_grain)))
    if seeds is not None:
        seeds = np.asarray(seeds, dtype=float)
        if seeds.ndim != 2 or seeds.shape[1] != 3 or len(seeds) == 0:
            raise InputError("seeds", f"array of shape {seeds.shape}", "(G, 3) points with G >= 1")
        if n_grains is not None and int(n_grains) != len(seeds):
            raise InputError("n_grains", n_grains, f"len(seeds) = {len(seeds)}")
        n_grains = len(seeds)
    if isinstance(n_grains, bool) or not isinstance(n_grains, (int, np.integer)) or n_grains < 1:
        raise InputError("n_grains", n_grains, "an integer >= 1")
    n_grains = int(n_grains)
    d_equiv = (6.0 * vol / (math.pi * n_grains)) ** (1.0 / 3.0)
    if d_equiv < MIN_GRAIN_SIZE * r0 * (1 - 1e-9):
        raise InputError("n_grains", n_grains,
                         f"at most {int(vol / (math.pi / 6 * (MIN_GRAIN_SIZE * r0) ** 3))} grains in this shape",
                         hint=f"mean grain diameter would be {d_equiv / r0:.3g} r0 < {MIN_GRAIN_SIZE:g} r0")
    return n_grains, seeds


def _grain_sites(r0, shape, pbc, seeds, rots):
    """The fcc sites of every grain within the shape, sorted by grain then position: (pos, grain)."""
    lo, hi = shape.bounds()
    if len(seeds) == 1:
        cells = [(lo, hi, np.zeros((0, 3)))]
    else:
        cells = _voronoi_cells(seeds, lo, hi, pbc)
    pos, grain = _fill_grains(r0, seeds, rots, lo, hi, pbc, cells)
    if not isinstance(shape, Box):
        keep = shape.contains(pos)
        pos, grain = pos[keep], grain[keep]
    order = np.lexsort((pos[:, 2], pos[:, 1], pos[:, 0], grain))
    return pos[order], grain[order]


def _boundary_removal(pos, grain, shape, pbc, r0, d_min, target_porosity, porosity_tol):
    """The boundary rule: which sites go (bool mask) and the ``d_min`` used (``target_porosity``:
    chosen by bisection in :data:`D_MIN_RANGE` to reach it within ``porosity_tol``, or as
    close as the rule allows)."""
    if target_porosity is not None:
        target_porosity = float(target_porosity)
        if not 0.0 <= target_porosity < 1.0:
            raise InputError("target_porosity", target_porosity, "a fraction in [0, 1)")
    lo, hi = shape.bounds()
    vol = shape_volume(shape)
    n_sites = len(pos)
    d_hi = D_MIN_RANGE[1] if target_porosity is not None else d_min
    pairs_all, r_all = _close_pairs(pos, grain, lo, hi, pbc, r0, d_hi)
    v_cluster = r0 ** 3 / SQRT2

    def porosity_of(n):
        return 1.0 - n * v_cluster / vol

    def remove(dm):
        sel = r_all < dm
        return _greedy_removal(n_sites, pairs_all[sel])

    if target_porosity is None:
        return remove(d_min), d_min
    a, b = D_MIN_RANGE
    rem_a, rem_b = remove(a), remove(b)
    p_a, p_b = porosity_of(n_sites - rem_a.sum()), porosity_of(n_sites - rem_b.sum())
    if not p_a - porosity_tol <= target_porosity <= p_b + porosity_tol:
        raise InputError("target_porosity", target_porosity,
                         f"a porosity this boundary rule reaches here: [{p_a:.4f}, {p_b:.4f}] "
                         f"(d_min in [{a}, {b}] r0)")
    removed, d_min = (rem_a, a) if abs(p_a - target_porosity) < abs(p_b - target_porosity) else (rem_b, b)
    for _ in range(30):
        if abs(porosity_of(n_sites - removed.sum()) - target_porosity) <= porosity_tol:
            break
        m = 0.5 * (a + b)
        rem_m = remove(m)
        p_m = porosity_of(n_sites - rem_m.sum())
        if abs(p_m - target_porosity) < abs(porosity_of(n_sites - removed.sum()) - target_porosity):
            removed, d_min = rem_m, m
        if p_m < target_porosity:
            a = m
        else:
            b = m
    return removed, d_min


def _nearest_distance(pos, lo, hi, pbc):
    """The smallest distance between two clusters (periodic where ``pbc``), Angstrom."""
    rel = pos - lo
    box = np.where(pbc, hi - lo, 0.0)
    tree = cKDTree(rel, boxsize=box if pbc.any() else None)
    dist, _ = tree.query(rel, k=2) if len(pos) > 1 else (np.array([[0.0, np.inf]]), None)
    return float(dist[:, 1].min())


def polycrystal_summary(atoms):
    """One-paragraph text summary of ``atoms.info['polycrystal']``."""
    r = atoms.info["polycrystal"]
    return (f"polycrystal: {r['n_clusters']} clusters in {r['n_grains']} grains "
            f"({r['clusters_per_grain_mean']:.1f} +- {r['clusters_per_grain_std']:.1f} clusters per grain, "
            f"min {r['clusters_per_grain_min']}, max {r['clusters_per_grain_max']}; mean diameter "
            f"{r['grain_diameter_mean_r0']:.2f} r0 = {r['grain_diameter_mean_um']:.3g} um); "
            f"porosity {100 * r['porosity']:.2f}% (density {r['density_g_cm3']:.4g} g/cm3), "
            f"d_min {r['d_min_r0']:.3f} r0, removed {r['n_removed']} of {r['n_sites_before_removal']}, "
            f"nearest distance {r['nearest_distance_r0']:.3f} r0; built in {r['build_time_s']:.2f} s")


# --------------------------------------------------------------------------- packings and presets
#: Named packings of a CD polycrystal (``--set packing=NAME`` in the impact scenes and studies).
#: ``grain_size`` in r0 (the equal-volume diameter), ``porosity`` the target of the builder,
#: ``rc`` in r0, ``boundaries`` "bonded" (the CD paper's: boundary pairs attract like any pair),
#: "repulsive" (set-up bonds inside grains only) or "law" (the boundary pair law of
#: clusterdyn.md.boundary with the parameters ``law``: sigma_t and tau_c in GPa, G_c in J/m^2 or
#: ductility = delta_f/delta_0 (the same response at every r0), mu, select).  "paper" is the default and the CD paper's packing.  Material presets are
#: CALIBRATED: their law parameters were tuned (``clusterdyn study calibrate``) to the targets
#: they name; ``achieved`` gives what the material-point tests measured (docs/polycrystal.md).
PACKINGS = {
    "paper": {"grain_size": 11.0, "porosity": 0.14, "rc": 1.15, "boundaries": "bonded",
              "description": "the CD paper's Taylor-rod packing (14% porosity, grains of 11 r0 at r0 = 100 um)"},
    "repulsive": {"grain_size": 5.0, "porosity": 0.20, "rc": 1.10, "boundaries": "repulsive",
                  "description": "the flow-stress study's lowest packing: cohesionless grain boundaries"},
    # CALIBRATED (tuned): clusterdyn study calibrate --set flow_stress=0.3GPa --set selects=all
    # --set sigma_ts=2,4,8,16 (cube 16 r0, r0 = 100 um, seed 1; docs/polycrystal.md)
    "6061-T6": {"grain_size": 5.0, "porosity": 0.14, "rc": 1.15, "boundaries": "law", "material": "Al-6061-T6",
                "law": {"sigma_t": 2.928, "ductility": 8.0, "tau_c": 0.0, "mu": 0.0, "select": "all"},
                "description": "6061-T6, calibrated (tuned) to its flow stress 0.3 GPa (unconfined); its spall "
                               "strength is far below the metal's (no packing of the law reaches both)",
                "targets": {"flow_stress": 0.3}, "calibrated": True,
                "achieved": {"flow_stress": 0.271, "spall_strength": 0.175, "confined_flow": 0.446,
                             "E_young": 10.5, "M_long": 14.4}},
    # CALIBRATED (tuned): clusterdyn study calibrate --set spall_strength=1.3GPa --set selects=all
    # --set sigma_ts=2,4,8,16 (same cube; docs/polycrystal.md)
    "6061-T6-spall": {"grain_size": 5.0, "porosity": 0.14, "rc": 1.15, "boundaries": "law",
                      "material": "Al-6061-T6",
                      "law": {"sigma_t": 9.67, "ductility": 8.0, "tau_c": 0.0, "mu": 0.0, "select": "all"},
                      "description": "6061-T6, calibrated (tuned) to its spall strength 1.3 GPa; its flow stress "
                                     "is far above the metal's (no packing of the law reaches both)",
                      "targets": {"spall_strength": 1.3}, "calibrated": True,
                      "achieved": {"flow_stress": 1.924, "spall_strength": 1.465, "confined_flow": 2.039,
                                   "E_young": 36.5, "M_long": 41.2}},
}

#: keys of a packing and the allowed boundary kinds
PACKING_KEYS = ("grain_size", "porosity", "rc", "boundaries", "law", "description", "material", "targets",
                "achieved", "calibrated")
BOUNDARY_KINDS = ("bonded", "repulsive", "law")


def packing_spec(packing):
    """A packing as a dict: a name of :data:`PACKINGS`, a path to a JSON file of the same keys,
    or a dict.  Checked (one-line InputError naming the key) before any work."""
    import json
    import os
    if isinstance(packing, dict):
        spec = dict(packing)
        where = "packing"
    elif isinstance(packing, str) and packing in PACKINGS:
        spec = dict(PACKINGS[packing], name=packing)
        where = f"packing={packing}"
    elif isinstance(packing, (str, os.PathLike)) and os.path.isfile(packing):
        try:
            with open(packing) as fh:
                spec = json.load(fh)
        except (OSError, ValueError) as exc:
            raise InputError("packing", str(packing), f"a JSON file of packing keys ({exc})") from None
        if not isinstance(spec, dict):
            raise InputError("packing", str(packing), "a JSON object of packing keys")
        spec.setdefault("name", os.path.basename(str(packing)))
        where = f"packing file {packing}"
    else:
        raise InputError("packing", packing, "one of " + ", ".join(PACKINGS) + ", or a JSON file of packing keys")
    bad = [k for k in spec if k not in PACKING_KEYS + ("name",)]
    if bad:
        raise InputError(f"{where}: key", bad[0], ", ".join(PACKING_KEYS))
    for k, lo, hi in (("grain_size", MIN_GRAIN_SIZE, math.inf), ("porosity", 0.0, 0.5), ("rc", 1.0, math.sqrt(2))):
        if k not in spec:
            raise InputError(f"{where}: {k}", None, "a value (every packing names grain_size, porosity, rc, "
                             "boundaries)")
        try:
            x = float(spec[k])
        except (TypeError, ValueError):
            raise InputError(f"{where}: {k}", spec[k], f"a number in [{lo:g}, {hi:g}]") from None
        if not lo <= x <= hi:
            raise InputError(f"{where}: {k}", spec[k], f"a number in [{lo:g}, {hi:g}]")
        spec[k] = x
    if spec.get("boundaries") not in BOUNDARY_KINDS:
        raise InputError(f"{where}: boundaries", spec.get("boundaries"), " or ".join(BOUNDARY_KINDS))
    if spec["boundaries"] == "law":
        law = spec.get("law")
        if not isinstance(law, dict) or "sigma_t" not in law or (("G_c" in law) == ("ductility" in law)):
            raise InputError(f"{where}: law", law, "a dict with sigma_t (GPa) and G_c (J/m^2) or ductility "
                             "(delta_f/delta_0), optionally tau_c (GPa), mu, kt_ratio, select")
    return spec
