"""Set-up geometry of an MCA packing: pairs, contact areas S_ij, distances q_ij, volumes.

The contact areas and volumes come from the Voronoi tessellation of the
automaton centres (``scipy.spatial.Voronoi``; for equal sizes it is the
radical tessellation), computed once at set-up (docs/theory.md 2.1, 2.5):

* a *pair* is two automata whose Voronoi cells share a face; ``S_ij`` is the
  face area (3D) or edge length times unit thickness (2D); ``q_ij`` is the
  distance from centre i to the face plane (half the distance for Voronoi);
* ``Omega_i = (1/D) sum_j q_ij S_ij`` (D = 3 or 2) over the faces the
  automaton has with other automata: the volume of the pyramids on its faces
  (for an interior automaton, exactly its Voronoi cell volume);
* ``V_i``, the volume of the cell clipped at the sample surface, gives the mass.

Free surfaces: the sample is closed by *mirror images* of the automata
across the faces of the (orthorhombic) cell for open directions, and by
periodic images for periodic directions.  A mirror plane cuts the surface
cells where the next layer would be; faces with mirror images are dropped
(free surface), so surface automata keep the faces they have, with their
bulk areas.  This is exact for box samples built by :func:`mca_packing`
(lattices placed half a layer from the cell faces, random packings packed
against them); for other shapes carved from a box the surface cells are
closed at the box faces.
"""

import hashlib
import math

import numpy as np
from scipy.spatial import Voronoi

from ..errors import InputError


#: the last tessellation made, by a digest of its inputs: building an MCA sample tessellates the
#: same centres twice (the masses in ``mca_packing``, then the MCA state), and the second call
#: takes the first's result (copies of its arrays: the same numbers)
_LAST = {}


def _key(*arrays_and_values):
    h = hashlib.blake2b(digest_size=20)
    for a in arrays_and_values:
        if isinstance(a, np.ndarray):
            h.update(str((a.dtype, a.shape)).encode())
            h.update(np.ascontiguousarray(a).tobytes())
        else:
            h.update(repr(a).encode())
    return h.digest()


def _cached(kind, key, make):
    hit = _LAST.get(kind)
    if hit is None or hit[0] != key:
        _LAST.clear()              # one geometry held at a time
        hit = (key, make())
        _LAST[kind] = hit
    return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in hit[1].items()}



def _polygon_area_3d(pts, normal):
    """Area of a convex planar polygon given by unordered vertices (K, 3)."""
    c = pts.mean(axis=0)
    u = pts[0] - c
    if np.linalg.norm(u) == 0:
        u = pts[1] - c
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    x = (pts - c) @ u
    y = (pts - c) @ v
    order = np.argsort(np.arctan2(y, x))
    x, y = x[order], y[order]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def sample_planes(positions, radius, cell, pbc, dim):
    """Lower and upper faces of the sample per axis (the cell, or the bounding box + radius)."""
    cell = np.asarray(cell, float).reshape(3, 3)
    lo = np.zeros(3)
    hi = np.zeros(3)
    for a in range(dim):
        L = cell[a, a]
        if L > 0:
            lo[a], hi[a] = 0.0, L
        else:
            lo[a] = (positions[:, a] - radius).min()
            hi[a] = (positions[:, a] + radius).max()
    return lo, hi


def tessellate(positions, radius, cell, pbc, dim=3):
    """Voronoi pairs and geometry of a packing (see :func:`_tessellate`; the last result is
    reused for the same inputs)."""
    pos = np.asarray(positions, float)
    rad = np.asarray(radius, float)
    key = _key(pos, rad, np.asarray(cell, float), np.asarray(pbc, bool), int(dim))
    return _cached("box", key, lambda: _tessellate(pos, rad, cell, pbc, dim))


def _tessellate(positions, radius, cell, pbc, dim=3):
    """Voronoi pairs and geometry of a packing.

    Parameters
    ----------
    positions : (N, 3) float64, Angstrom
    radius : (N,) float64, Angstrom (sets the ghost-shell width)
    cell : (3, 3) orthorhombic; pbc : 3 bools
    dim : 3, or 2 for plane strain (z ignored, S per unit thickness)

    Returns
    -------
    dict with ``i_p, j_p`` (P,) int64 rows (i < j), ``S_p`` (P,), ``q_p2`` (P, 2)
    distances from i and j to the face, ``omega_n`` (N,) pyramid volume,
    ``vcell_n`` (N,) clipped cell volume.
    """
    pos = np.asarray(positions, float)[:, :dim]
    n = len(pos)
    if n < dim + 2:
        raise InputError("atoms", f"{n} automata", f"at least {dim + 2} automata for a tessellation")
    pbc = np.asarray(pbc, bool).reshape(3)
    cell = np.asarray(cell, float).reshape(3, 3)
    dmax = 2.0 * float(np.max(radius))
    for a in range(dim):
        if pbc[a] and cell[a, a] < 3.0 * dmax - 1e-9:
            raise InputError("cell", cell.diagonal().tolist(),
                             f"periodic lengths of at least 3 automaton sizes ({3 * dmax:.4g} A) along "
                             f"{'xyz'[a]}: pairs are found by minimum image")
    lo, hi = sample_planes(np.asarray(positions, float), np.asarray(radius, float), cell, pbc, dim)
    width = 3.0 * float(np.max(radius)) * 2.0
    # ghost shell: kind 0 real, 1 periodic image (owner = original row), 2 mirror
    pts = pos.copy()
    owner = np.arange(n)
    kind = np.zeros(n, np.int8)
    for a in range(dim):
        if pbc[a]:
            L = cell[a, a]
            sel_lo = pts[:, a] < lo[a] + width
            sel_hi = pts[:, a] > hi[a] - width
            add_p = pts[sel_lo].copy()
            add_p[:, a] += L
            add_m = pts[sel_hi].copy()
            add_m[:, a] -= L
            k_p = np.where(kind[sel_lo] == 0, 1, kind[sel_lo])
            k_m = np.where(kind[sel_hi] == 0, 1, kind[sel_hi])
            pts = np.vstack([pts, add_p, add_m])
            owner = np.concatenate([owner, owner[sel_lo], owner[sel_hi]])
            kind = np.concatenate([kind, k_p, k_m])
        else:
            sel_lo = pts[:, a] < lo[a] + width
            sel_hi = pts[:, a] > hi[a] - width
            add_l = pts[sel_lo].copy()
            add_l[:, a] = 2 * lo[a] - add_l[:, a]
            add_h = pts[sel_hi].copy()
            add_h[:, a] = 2 * hi[a] - add_h[:, a]
            pts = np.vstack([pts, add_l, add_h])
            owner = np.concatenate([owner, owner[sel_lo], owner[sel_hi]])
            kind = np.concatenate([kind, np.full(sel_lo.sum() + sel_hi.sum(), 2, np.int8)])
    vor = Voronoi(pts)
    vert = vor.vertices
    pairs = {}
    vcell = np.zeros(n)
    omega = np.zeros(n)
    for (a, b), rv in zip(vor.ridge_points, vor.ridge_vertices):
        ka, kb = kind[a], kind[b]
        if ka != 0 and kb != 0:
            continue
        if ka != 0:          # make a the real one
            a, b, ka, kb = b, a, kb, ka
        d = pts[b] - pts[a]
        r = float(np.linalg.norm(d))
        nvec = d / r
        if -1 in rv:
            raise InputError("atoms", f"automaton {a}",
                             "a packing whose Voronoi cells are closed by the ghost shell",
                             hint="is the sample inside its cell?")
        vv = vert[rv]
        if dim == 3:
            area = _polygon_area_3d(vv, nvec)
        else:
            area = float(np.linalg.norm(vv[1] - vv[0]))
        q = 0.5 * r
        vcell[a] += q * area / dim
        if kb == 2:
            continue            # free surface: a face with a mirror image
        j = owner[b]
        if kb == 0:
            vcell[b] += q * area / dim
        if j == a:
            raise InputError("cell", cell.diagonal().tolist(),
                             "periodic lengths of at least 3 automaton sizes")
        key = (min(a, j), max(a, j))
        if key in pairs:
            continue
        pairs[key] = (area, q, q)
    keys = np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)
    S = np.array([pairs[tuple(k)][0] for k in keys])
    q2 = np.array([pairs[tuple(k)][1:] for k in keys]).reshape(-1, 2)
    for (i, j), s, (qi, qj) in zip(keys, S, q2):
        omega[i] += qi * s / dim
        omega[j] += qj * s / dim
    return {"i_p": keys[:, 0].copy(), "j_p": keys[:, 1].copy(), "S_p": S, "q_p2": q2,
            "omega_n": omega, "vcell_n": vcell}


def consistency(geom, positions, cell, pbc, dim=3):
    """Per automaton, ``(sum_j q S n n)/Omega``: the identity inside the body (diagnostic)."""
    pos = np.asarray(positions, float)
    i, j = geom["i_p"], geom["j_p"]
    d = pos[j] - pos[i]
    L = np.diag(np.asarray(cell, float).reshape(3, 3))
    for a in range(3):
        if pbc[a]:
            d[:, a] -= L[a] * np.round(d[:, a] / L[a])
    nrm = d / np.linalg.norm(d, axis=1)[:, None]
    A = np.zeros((len(pos), 3, 3))
    w = geom["S_p"][:, None, None] * np.einsum("pa,pb->pab", nrm, nrm)
    np.add.at(A, i, w * geom["q_p2"][:, 0, None, None])
    np.add.at(A, j, w * geom["q_p2"][:, 1, None, None])
    return A / geom["omega_n"][:, None, None]


_DIRS26 = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)
                    if (a, b, c) != (0, 0, 0)], float)
_DIRS26 /= np.linalg.norm(_DIRS26, axis=1)[:, None]


def surface_ghosts(pos, d, dim=3, gap=0.85):
    """Ghost points closing a body of any shape: candidates at distance ``d`` from every
    automaton along the 26 (2D: 8) lattice directions, kept where no automaton is within
    ``gap * d`` (empty space), thinned to one per cell of size 0.35 d; plus a coarse far
    shell (spacing 2 d, 4 d beyond the bounding box) so that every cell is bounded."""
    from scipy.spatial import cKDTree
    dirs = _DIRS26 if dim == 3 else _DIRS26[_DIRS26[:, 2] == 0][:, :2] / 1.0
    if dim == 2:
        dirs = dirs / np.linalg.norm(dirs, axis=1)[:, None]
    tree = cKDTree(pos)
    cand = (pos[:, None, :] + d * dirs[None, :, :]).reshape(-1, dim)
    dist, _ = tree.query(cand, k=1)
    cand = cand[dist >= gap * d]
    if len(cand):
        key = np.floor(cand / (0.35 * d)).astype(np.int64)
        _, first = np.unique(key, axis=0, return_index=True)
        cand = cand[np.sort(first)]
    lo = pos.min(axis=0) - 4.0 * d
    hi = pos.max(axis=0) + 4.0 * d
    axes = [np.linspace(lo[a], hi[a], max(2, int(np.ceil((hi[a] - lo[a]) / (2.0 * d))) + 1))
            for a in range(dim)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    on_shell = np.zeros(len(grid), bool)
    for a in range(dim):
        on_shell |= np.isclose(grid[:, a], lo[a]) | np.isclose(grid[:, a], hi[a])
    return np.vstack([cand, grid[on_shell]])


def _ridge_areas(ridge_vertices, vert, normals, dim):
    """Areas of the ridges (convex polygons, 3D) or lengths (2D), vectorised; NaN where unbounded."""
    cnt = np.array([len(v) for v in ridge_vertices], np.int64)
    flat = np.fromiter((x for v in ridge_vertices for x in v), np.int64, count=int(cnt.sum()))
    rid = np.repeat(np.arange(len(cnt)), cnt)
    bad = np.zeros(len(cnt), bool)
    np.logical_or.at(bad, rid, flat < 0)
    flat = np.where(flat < 0, 0, flat)
    pts = vert[flat][:, :dim]
    if dim == 2:
        first = np.cumsum(cnt) - cnt
        out = np.linalg.norm(pts[first + 1] - pts[first], axis=1)
        out[bad] = np.nan
        return out
    cen = np.zeros((len(cnt), 3))
    np.add.at(cen, rid, pts)
    cen /= cnt[:, None]
    rel = pts - cen[rid]
    first = np.cumsum(cnt) - cnt
    u = rel[first]
    u /= np.maximum(np.linalg.norm(u, axis=1), 1e-300)[:, None]
    w = np.cross(normals, u)
    x = np.einsum("ka,ka->k", rel, u[rid])
    y = np.einsum("ka,ka->k", rel, w[rid])
    order = np.lexsort((np.arctan2(y, x), rid))
    x, y = x[order], y[order]
    # the next vertex around each polygon (wrapping within its ridge)
    nxt = np.arange(len(x)) + 1
    last = np.cumsum(cnt) - 1
    nxt[last] = first
    out = np.zeros(len(cnt))
    np.add.at(out, rid, x * y[nxt] - y * x[nxt])
    out = 0.5 * np.abs(out)
    out[bad] = np.nan
    return out


def tessellate_body(positions, radius, dim=3, gap=0.85):
    """Voronoi pairs and geometry of a body of any shape (see :func:`_tessellate_body`; the last
    result is reused for the same inputs)."""
    pos = np.asarray(positions, float)
    rad = np.asarray(radius, float)
    key = _key(pos, rad, int(dim), float(gap))
    return _cached("body", key, lambda: _tessellate_body(pos, rad, dim, gap))


def _tessellate_body(positions, radius, dim=3, gap=0.85):
    """Voronoi pairs and geometry of a deformed body of any shape (no periodic axes).

    The re-tessellation of large-strain MCA (docs/theory.md 2.7): the body is
    closed by :func:`surface_ghosts` instead of mirror planes; faces with ghosts
    are the free surface (dropped), and ``vcell_n`` (the cell volume, faces with
    ghosts included) is the automaton's current volume.  Returns the dict of
    :func:`tessellate` (``q_p2`` = r/2 on both sides: Voronoi faces bisect) plus
    ``r_p`` the distances.
    """
    pos = np.asarray(positions, float)[:, :dim]
    n = len(pos)
    if n < dim + 2:
        raise InputError("atoms", f"{n} automata", f"at least {dim + 2} automata for a tessellation")
    d = 2.0 * float(np.mean(radius))
    ghosts = surface_ghosts(pos, d, dim, gap)
    pts = np.vstack([pos, ghosts])
    vor = Voronoi(pts)
    rp = vor.ridge_points
    real = rp < n
    sel = real[:, 0] | real[:, 1]
    rp = rp[sel]
    rv = [vor.ridge_vertices[k] for k in np.nonzero(sel)[0]]
    vert = vor.vertices
    a = rp[:, 0]
    b = rp[:, 1]
    dvec = pts[b] - pts[a]
    r = np.linalg.norm(dvec, axis=1)
    area = _ridge_areas(rv, vert, dvec / r[:, None], dim)
    if np.any(np.isnan(area)):
        k = int(np.nonzero(np.isnan(area))[0][0])
        raise InputError("atoms", f"automaton {min(a[k], b[k])}",
                         "a body closed by its ghost shell (an unbounded Voronoi cell)")
    q = 0.5 * r
    vcell = np.zeros(n)
    ra, rb = a < n, b < n
    np.add.at(vcell, a[ra], q[ra] * area[ra] / dim)
    np.add.at(vcell, b[rb], q[rb] * area[rb] / dim)
    both = ra & rb
    i = np.minimum(a[both], b[both])
    j = np.maximum(a[both], b[both])
    order = np.lexsort((j, i))
    i, j = i[order], j[order]
    S = area[both][order]
    rr = r[both][order]
    q2 = np.stack([0.5 * rr, 0.5 * rr], axis=1)
    omega = np.zeros(n)
    np.add.at(omega, i, q2[:, 0] * S / dim)
    np.add.at(omega, j, q2[:, 1] * S / dim)
    return {"i_p": i.astype(np.int64), "j_p": j.astype(np.int64), "S_p": S, "q_p2": q2,
            "omega_n": omega, "vcell_n": vcell, "r_p": rr}
