"""Grain orientations of fcc cluster packings: recovery, spglib check, misorientations.

* :func:`grain_orientation` recovers the lattice rotation of one grain from
  its interior clusters (nearest-neighbour vectors fitted to the ideal
  ``r0 <110>/sqrt(2)`` set, Kabsch), then confirms the lattice is fcc with
  spglib: the grain's interior clusters, folded into one conventional cubic
  cell of the fitted lattice and averaged per sublattice, must form space
  group Fm-3m (225) with a small scatter about the fitted sites.
* :func:`misorientation_angle` gives the disorientation angle of two
  rotations modulo the 24 proper rotations of the cube.
* :func:`neighbouring_grains` and :func:`misorientation_distribution` give the
  misorientations across grain boundaries and their histogram beside the
  random-texture (Mackenzie 1958) density :func:`mackenzie_pdf`.

Rotation convention everywhere (as :func:`~clusterdyn.build.lattice.fcc_sites`):
``lab = R @ crystal``; the columns of R are the cube axes in the lab frame.
"""

import functools
import itertools
import math
import warnings

import numpy as np
import spglib
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .lattice import _FCC_BASIS, SQRT2

#: the 12 nearest-neighbour directions of fcc (unit vectors, crystal frame)
FCC_NN = np.array([v for v in itertools.product((-1, 0, 1), repeat=3)
                   if sum(abs(c) for c in v) == 2], dtype=float) / SQRT2


@functools.lru_cache(maxsize=None)
def cubic_rotations():
    """The 24 proper rotations of the cube, (24, 3, 3) signed permutation matrices."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            m = np.zeros((3, 3))
            m[range(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(m)
    out = np.array(out)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=None)
def _cubic_quats_conj():
    q = Rotation.from_matrix(cubic_rotations()).as_quat()        # (x, y, z, w)
    # scalar part of p (x) s = p_w s_w - p_v . s_v  = p . (-s_x, -s_y, -s_z, s_w)
    c = q * np.array([-1.0, -1.0, -1.0, 1.0])
    c.setflags(write=False)
    return c


def _disorientation_of_quats(q):
    """Disorientation angle (radians) of rotations given as quaternions (n, 4), cubic symmetry."""
    w = np.abs(q @ _cubic_quats_conj().T).max(axis=1)
    return 2.0 * np.arccos(np.clip(w, 0.0, 1.0))


def misorientation_angle(rot_a, rot_b):
    """Misorientation (disorientation) angle between orientations, degrees.

    Parameters
    ----------
    rot_a, rot_b : (3, 3) or (n, 3, 3) arrays
        Orientations (``lab = R @ crystal``).

    Returns
    -------
    float or (n,) array
        ``min over the 24 cubic rotations S of angle(R_a^T R_b S)``, in [0, 62.8] degrees.
    """
    a = np.asarray(rot_a, dtype=float)
    b = np.asarray(rot_b, dtype=float)
    scalar = a.ndim == 2 and b.ndim == 2
    m = np.einsum("...ji,...jk->...ik", a, b).reshape(-1, 3, 3)
    ang = np.degrees(_disorientation_of_quats(Rotation.from_matrix(m).as_quat()))
    return float(ang[0]) if scalar else ang


#: largest disorientation angle between cubic crystals, degrees
MACKENZIE_MAX_DEG = math.degrees(2.0 * math.acos((2.0 + SQRT2) / 4.0))


@functools.lru_cache(maxsize=4)
def _axis_grid(n):
    """n nearly uniform unit vectors (Fibonacci sphere)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z ** 2)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def mackenzie_pdf(theta_deg, n_axes=4000):
    """Random-texture density of the cubic disorientation angle (Mackenzie 1958), per degree.

    For uniformly random orientations the rotation angle has density
    ``(1 - cos t)/pi`` on [0, pi]; with the 24 cubic symmetries the
    disorientation angle has density ``24/pi (1 - cos t) F(t)``, where F(t) is
    the fraction of rotation axes for which the rotation by t is its own
    disorientation (F = 1 below 45 degrees, 0 above 62.8).  F is evaluated by
    quadrature over ``n_axes`` axes (Fibonacci sphere), the error is the quadrature's
    (about 1e-3 relative with the default ``n_axes``).

    Parameters
    ----------
    theta_deg : float or array
        Angles, degrees.

    Returns
    -------
    array
        Probability density per degree (integrates to 1 over [0, 62.8]).
    """
    t = np.radians(np.atleast_1d(np.asarray(theta_deg, dtype=float)))
    axes = _axis_grid(n_axes)
    out = np.zeros_like(t)
    for i, ti in enumerate(t):
        if ti <= 0 or ti >= math.pi:
            continue
        q = np.column_stack([axes * math.sin(ti / 2), np.full(len(axes), math.cos(ti / 2))])
        own = _disorientation_of_quats(q) >= ti - 1e-12
        out[i] = 24.0 / math.pi * (1.0 - math.cos(ti)) * own.mean()
    out *= math.pi / 180.0
    return out if np.ndim(theta_deg) else float(out[0])


def _kabsch(ideal, measured):
    """Rotation R minimising sum |R ideal_k - measured_k|^2 (rows are vectors)."""
    h = ideal.T @ measured
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def fit_fcc_rotation(nn_vectors, seed_vectors=None, iterations=3):
    """Fit the rotation of an fcc lattice to nearest-neighbour vectors.

    Parameters
    ----------
    nn_vectors : (m, 3) array
        Nearest-neighbour vectors of the lattice (any length, lab frame).
    seed_vectors : (12, 3) array, optional
        The neighbours of one cluster, used for the first guess (default: the
        first 12 rows).
    iterations : int
        Refinement passes (assign each vector to the nearest ideal direction,
        then Kabsch).

    Returns
    -------
    R : (3, 3) array
        ``lab = R @ crystal`` (defined modulo the cubic rotations).
    rms_deg : float
        RMS angle between the vectors and their fitted ideal directions, degrees.
    """
    v = np.asarray(nn_vectors, dtype=float)
    v = v / np.linalg.norm(v, axis=1)[:, None]
    s = v[:12] if seed_vectors is None else np.asarray(seed_vectors, float)
    s = s / np.linalg.norm(s, axis=1)[:, None]
    # first guess: v1 and a neighbour v2 at 60 degrees map to (110)/sqrt2 and one of its 60-degree partners
    v1 = s[0]
    cos = s @ v1
    j = int(np.argmin(np.abs(cos - 0.5)))
    v2 = s[j]
    e1 = FCC_NN[np.argmax(FCC_NN @ np.array([1.0, 1.0, 0.0]))]
    partners = FCC_NN[np.abs(FCC_NN @ e1 - 0.5) < 1e-9]
    best = None
    for e2 in partners:
        R = _kabsch(np.array([e1, e2, np.cross(e1, e2)]), np.array([v1, v2, np.cross(v1, v2)]))
        score = (s @ (FCC_NN @ R.T).T).max(axis=1).sum()
        if best is None or score > best[0]:
            best = (score, R)
    R = best[1]
    for _ in range(iterations):
        ideal = FCC_NN[np.argmax(v @ (FCC_NN @ R.T).T, axis=1)]
        R = _kabsch(ideal, v)
    ideal = FCC_NN[np.argmax(v @ (FCC_NN @ R.T).T, axis=1)] @ R.T
    rms = math.degrees(math.sqrt(np.mean(np.arccos(np.clip((ideal * v).sum(axis=1), -1, 1)) ** 2)))
    return R, rms


def _tree(atoms):
    pos = atoms.get_positions()
    pbc = np.asarray(atoms.pbc, bool)
    if pbc.any():
        if not atoms.cell.orthorhombic:
            raise InputError("atoms.cell", atoms.cell, "an orthorhombic cell (periodic axes)")
        L = atoms.cell.lengths()
        origin = np.asarray(atoms.info.get("origin", np.zeros(3)), float)
        rel = pos - origin
        rel = np.where(pbc, np.mod(rel, np.where(pbc, L, 1.0)), rel)
        return cKDTree(rel, boxsize=np.where(pbc, L, 0.0)), rel, np.where(pbc, L, 0.0)
    return cKDTree(pos), pos, np.zeros(3)


def _min_image(d, box):
    return d - np.round(d / np.where(box > 0, box, 1.0)) * box


def _r0_of(atoms):
    """The packing's r0: ``info['cd_r0']`` of clusterdyn's builders, else the nearest-neighbour distance
    (so Atoms from ``ase.build.bulk`` work too)."""
    try:
        return float(atoms.info["cd_r0"][0])
    except (KeyError, IndexError, TypeError):
        pass
    if len(atoms) < 2:
        raise InputError("atoms", f"{len(atoms)} atom(s) without info['cd_r0']",
                         "at least two particles (the nearest-neighbour distance sets r0)")
    tree, rel, _ = _tree(atoms)
    d, _ = tree.query(rel, k=2)
    return float(np.min(d[:, 1]))


def _grains(atoms):
    """``arrays['grain']``, or one grain 0 for Atoms without it (a single crystal, e.g. ``ase.build.bulk``)."""
    if "grain" in atoms.arrays:
        return atoms.arrays["grain"]
    return np.zeros(len(atoms), dtype=np.int64)


def spacegroup(atoms, symprec=1e-3):
    """spglib's space group of ``atoms`` with ``symprec`` in units of the packing's r0.

    spglib's tolerance is an absolute length.  A packing's cell is 1e4-1e6 Angstrom
    across, and spglib's search misses the symmetry of a perfect packing at a tolerance
    that is small in r0 but large in Angstrom (a [111] fcc packing at r0 = 5 um: Fm-3m at
    ``symprec=1e-5`` Angstrom, no symmetry at 1e-3 r0 = 50 Angstrom); so the cell is
    handed to spglib in units of r0 (``info['cd_r0']``, else the nearest-neighbour distance).

    Returns
    -------
    str or None
        e.g. ``'Fm-3m (225)'``; None where spglib finds no symmetry.
    """
    if not np.asarray(atoms.pbc, bool).all():
        raise InputError("atoms.pbc", tuple(bool(p) for p in atoms.pbc),
                         "a periodic cell on every axis (spglib needs a crystal)")
    r0 = _r0_of(atoms)
    cell = (atoms.cell[:] / r0, atoms.get_scaled_positions(), atoms.get_atomic_numbers())
    with warnings.catch_warnings():          # spglib 2.5 deprecates returning None on failure
        warnings.simplefilter("ignore", DeprecationWarning)
        return spglib.get_spacegroup(cell, symprec=symprec)


def grain_orientation(atoms, grain, shell=(0.8, 1.2), depth=2, symprec=0.2, details=False):
    """Recover a grain's lattice rotation and confirm with spglib that it is fcc (Fm-3m, 225).

    Interior clusters are those with exactly 12 neighbours of the same grain in
    ``shell`` (in r0) and none of another grain; ``depth`` >= 2 also requires
    their neighbours to be such (two shells away from the boundary), falling
    back to fewer shells in a grain too small for that.  Their neighbour
    vectors give the rotation (:func:`fit_fcc_rotation`) and the lattice
    constant ``a = sqrt(2) <r_nn>``.  The interior clusters are then folded into
    one conventional cubic cell of that lattice: each is assigned to the
    nearest site of the four fcc sublattices, and the cell built from the four
    mean positions (actual positions, averaged over the grain, so thermal noise
    averages out) must be space group 225 for spglib at ``symprec`` (in r0),
    with every sublattice occupied and the clusters' rms scatter about the
    fitted lattice below ``symprec/2`` (an hcp grain, with every third layer
    0.58 r0 off the fcc sites, fails here).

    Parameters
    ----------
    atoms : ase.Atoms
        Clusters with ``arrays['grain']`` and ``info['cd_r0']``; without ``grain`` every
        particle is grain 0 (a single crystal), without ``cd_r0`` r0 is the
        nearest-neighbour distance, so Atoms from ``ase.build.bulk`` work too.
    grain : int
        Grain id.
    details : bool
        Also return a dict (spacegroup, number of interior clusters, shells
        used, rms angular fit error in degrees, measured neighbour distance,
        scatter about the fitted lattice in r0).

    Returns
    -------
    R : (3, 3) array
        ``lab = R @ crystal``, modulo the cubic rotations.

    Raises
    ------
    InputError
        No such grain, too few interior clusters, or not fcc according to spglib.
    """
    gid = _grains(atoms)
    mine = np.flatnonzero(gid == grain)
    if len(mine) == 0:
        raise InputError("grain", grain, f"a grain id present in atoms (0..{gid.max()})")
    r0 = _r0_of(atoms)
    tree, rel, box = _tree(atoms)
    lists = tree.query_ball_point(rel[mine], shell[1] * r0)
    nn_vec, interior = {}, []
    for i, lst in zip(mine, lists):
        lst = np.array([j for j in lst if j != i], dtype=np.int64)
        if len(lst) == 0:
            continue
        d = _min_image(rel[lst] - rel[i], box)
        r = np.linalg.norm(d, axis=1)
        same = gid[lst] == grain
        ok = (r > shell[0] * r0)
        if same.all() and ok.all() and len(lst) == 12:
            nn_vec[i] = d
            interior.append(i)
    used_depth = 1
    for _ in range(depth - 1):
        s = set(interior)
        deep = [i for i in interior
                if all(j == i or j in s for j in tree.query_ball_point(rel[i], shell[1] * r0))]
        if len(deep) < 2:          # a small grain: keep the shallower interior
            break
        interior, used_depth = deep, used_depth + 1
    if len(interior) < 2:
        raise InputError("grain", grain, "a grain with interior clusters (12 same-grain neighbours, "
                         "1 shell from its boundary)", hint=f"found {len(interior)}")
    vecs = np.vstack([nn_vec[i] for i in interior])
    R, rms = fit_fcc_rotation(vecs, seed_vectors=nn_vec[interior[0]])
    r_nn = float(np.linalg.norm(vecs, axis=1).mean())
    a = SQRT2 * r_nn

    # fold the interior clusters into one conventional cell of the fitted lattice
    centre = rel[interior].mean(axis=0)
    k0 = interior[int(np.argmin(np.linalg.norm(_min_image(rel[interior] - centre, box), axis=1)))]
    c = _min_image(rel[interior] - rel[k0], box) @ R / a          # crystal coordinates, cube edges
    cand = np.round(c[:, None, :] - _FCC_BASIS[None]) + _FCC_BASIS[None]   # nearest site of each sublattice
    dev = c[:, None, :] - cand
    site = np.argmin((dev ** 2).sum(axis=2), axis=1)
    res = dev[np.arange(len(c)), site]                             # residual from the nearest fcc site
    scatter = float(np.sqrt((res ** 2).sum(axis=1).mean()) * a / r0)
    counts = np.bincount(site, minlength=4)
    mean_res = np.array([res[site == b].mean(axis=0) if counts[b] else np.zeros(3) for b in range(4)])
    frac = np.mod(_FCC_BASIS + mean_res - mean_res.mean(axis=0), 1.0)
    cell = ((a / r0) * R.T, frac, np.ones(4, dtype=int))           # rows: cube edges (lab), in r0
    with warnings.catch_warnings():          # spglib 2.5 deprecates returning None on failure
        warnings.simplefilter("ignore", DeprecationWarning)
        dataset = spglib.get_symmetry_dataset(cell, symprec=symprec)
    number = None if dataset is None else dataset.number
    if number != 225 or counts.min() == 0 or scatter > 0.5 * symprec:
        got = "no symmetry" if dataset is None else f"{dataset.international} ({dataset.number})"
        raise InputError("grain", grain, "an fcc grain (spglib space group Fm-3m, 225)",
                         hint=f"folded cell: {got}, clusters per sublattice {counts.tolist()}, scatter "
                              f"{scatter:.3f} r0 about the fitted lattice (limit {0.5 * symprec:g}); "
                              f"rms fit {rms:.2f} deg")
    if details:
        return R, {"spacegroup": f"{dataset.international} ({dataset.number})", "n_interior": len(interior),
                   "depth": used_depth, "rms_deg": rms, "nn_distance": r_nn, "scatter_r0": scatter}
    return R


def neighbouring_grains(atoms, cutoff=1.15):
    """Pairs of grains in contact: clusters of both closer than ``cutoff`` r0.

    Returns
    -------
    pairs : (m, 2) int array
        Grain ids, ``a < b``, unique.
    contacts : (m,) int array
        Number of cluster pairs across each boundary (a measure of its area).
    """
    if "grain" not in atoms.arrays:
        raise InputError("atoms", "Atoms without 'grain'", "a polycrystal (arrays['grain'])")
    r0 = _r0_of(atoms)
    tree, _, _ = _tree(atoms)
    p = tree.query_pairs(cutoff * r0, output_type="ndarray")
    g = atoms.arrays["grain"][p] if len(p) else np.zeros((0, 2), np.int64)
    g = g[g[:, 0] != g[:, 1]]
    g.sort(axis=1)
    pairs, contacts = np.unique(g, axis=0, return_counts=True)
    return pairs.reshape(-1, 2), contacts


def misorientation_distribution(atoms, bins=None, rotations=None, cutoff=1.15):
    """Misorientation angles across grain boundaries and their histogram vs Mackenzie.

    Parameters
    ----------
    atoms : ase.Atoms
        Polycrystal (``arrays['grain']``).
    bins : array, optional
        Bin edges in degrees (default 0, 2.5, ..., 65).
    rotations : (G, 3, 3) array, optional
        Grain orientations; default ``atoms.info['grain_rotations']``.  Pass
        recovered ones (:func:`grain_orientation`) to check the sample itself.

    Returns
    -------
    dict
        ``pairs`` (m, 2), ``angles_deg`` (m,), ``edges``, ``centres``,
        ``density`` (histogram, per degree), ``mackenzie`` (random-texture
        density at the centres, per degree), ``mean_deg`` and
        ``mackenzie_mean_deg`` (40.7 for cubic).
    """
    rots = np.asarray(atoms.info["grain_rotations"] if rotations is None else rotations, float)
    pairs, contacts = neighbouring_grains(atoms, cutoff)
    ang = misorientation_angle(rots[pairs[:, 0]], rots[pairs[:, 1]]) if len(pairs) else np.zeros(0)
    edges = np.arange(0.0, 65.01, 2.5) if bins is None else np.asarray(bins, float)
    hist, _ = np.histogram(ang, bins=edges, density=len(ang) > 0)
    centres = 0.5 * (edges[1:] + edges[:-1])
    fine = np.linspace(0, 63, 631)
    pdf = mackenzie_pdf(fine)
    return {"pairs": pairs, "contacts": contacts, "angles_deg": ang, "edges": edges, "centres": centres,
            "density": hist, "mackenzie": mackenzie_pdf(centres),
            "mean_deg": float(ang.mean()) if len(ang) else float("nan"),
            "mackenzie_mean_deg": float(np.trapezoid(fine * pdf, fine))}
