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

Cost: scipy's Voronoi (qhull) and, per face, compiled passes over the ridges (:func:`_ridge_pass`,
:func:`_ridge_area_pass`, :func:`_ridge_sums`) that repeat :func:`_polygon_area_3d`'s numpy
operations in their order and rounding (the per-face Python loop they replace gave the same bits;
tests/mca/test_tessellation.py).  A 1e5-automaton fcc box: qhull about 40 s, the passes under 1 s.
"""

import hashlib
import itertools
import math

import numpy as np
from numba import njit
from scipy.spatial import Voronoi

from ..errors import InputError
from ..fma import fma


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
    """Area of a convex planar polygon given by unordered vertices (K, 3): the definition the
    compiled passes (:func:`_ridge_pass`, :func:`_ridge_area_pass`) follow operation by operation,
    and their fallback for the faces they leave."""
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
    return _box_geometry(vor, pts, kind, owner, n, dim, cell)


def _box_geometry(vor, pts, kind, owner, n, dim, cell):
    """The pairs and geometry of :func:`_tessellate` from the Voronoi diagram of the automata and
    their ghosts (compiled passes over the ridges, :func:`_ridge_pass`, :func:`_ridge_area_pass`,
    :func:`_ridge_sums`)."""
    rv = vor.ridge_vertices
    cnt = np.fromiter(map(len, rv), np.int64, count=len(rv))
    start = np.zeros(len(rv) + 1, np.int64)
    np.cumsum(cnt, out=start[1:])
    flat = np.fromiter(itertools.chain.from_iterable(rv), np.int64, count=int(start[-1]))
    rp = np.ascontiguousarray(vor.ridge_points, np.int64)
    vert = np.ascontiguousarray(vor.vertices, float)
    pts = np.ascontiguousarray(pts, float)
    kind = np.ascontiguousarray(kind, np.int8)
    xy = np.zeros((2, len(flat)))
    r_r = np.zeros(len(rv))
    area = np.zeros(len(rv))
    rows = np.zeros((len(rv), 2), np.int64)
    bad = _ridge_pass(pts, kind, rp, start, flat, vert, dim, rows, r_r, area, xy)
    if bad >= 0:
        raise InputError("atoms", f"automaton {rows[bad, 0]}",
                         "a packing whose Voronoi cells are closed by the ghost shell",
                         hint="is the sample inside its cell?")
    if dim == 3:
        ang = np.arctan2(xy[1], xy[0])   # numpy's arctan2 (its own, not libm's: the same bits as before)
        for k in np.nonzero(_ridge_area_pass(rows, start, xy, ang, area))[0]:
            area[k] = _polygon_area_3d(vert[flat[start[k]:start[k + 1]]], (pts[rows[k, 1]] - pts[rows[k, 0]])
                                       / r_r[k])
    vcell = np.zeros(n)
    key = np.full(len(rv), -1, np.int64)
    if _ridge_sums(kind, owner, rows, r_r, area, dim, vcell, key) >= 0:
        raise InputError("cell", cell.diagonal().tolist(), "periodic lengths of at least 3 automaton sizes")
    keys, first = np.unique(key, return_index=True)     # sorted (i, j); the first ridge of each pair
    if len(keys) and keys[0] < 0:
        keys, first = keys[1:], first[1:]
    i_p = keys // n
    j_p = keys - i_p * n
    S = area[first]
    q = 0.5 * r_r[first]
    q2 = np.stack([q, q], axis=1)
    omega = np.zeros(n)
    _pyramid_sums(i_p, j_p, S, q2, dim, omega)
    return {"i_p": i_p, "j_p": j_p, "S_p": S, "q_p2": q2, "omega_n": omega, "vcell_n": vcell}




@njit(cache=True)
def _dotfma(a0, a1, a2, b0, b1, b2):
    """``np.dot`` of two 3-vectors (OpenBLAS ddot): a fused chain from 0."""
    return fma(a2, b2, fma(a1, b1, a0 * b0))


@njit(cache=True)
def _ridge_pass(pts, kind, rp, start, flat, vert, dim, rows, r_r, area, xy):
    """Per ridge with a real automaton: its rows (the real one first), the distance of the two
    centres, and (3D) the face's vertices in the face's frame of :func:`_polygon_area_3d` (into
    ``xy``), (2D) the edge length into ``area``.  Rows of ridges between two ghosts are -1.
    Returns the first ridge with an unbounded vertex, or -1."""
    for k in range(rp.shape[0]):
        a = rp[k, 0]
        b = rp[k, 1]
        if kind[a] != 0 and kind[b] != 0:
            rows[k, 0] = -1
            rows[k, 1] = -1
            continue
        if kind[a] != 0:
            a, b = b, a
        rows[k, 0] = a
        rows[k, 1] = b
        s0 = start[k]
        s1 = start[k + 1]
        for m in range(s0, s1):
            if flat[m] < 0:
                return k
        if dim == 2:
            d0 = pts[b, 0] - pts[a, 0]
            d1 = pts[b, 1] - pts[a, 1]
            r_r[k] = math.sqrt(fma(d1, d1, d0 * d0))
            e0 = vert[flat[s0 + 1], 0] - vert[flat[s0], 0]
            e1 = vert[flat[s0 + 1], 1] - vert[flat[s0], 1]
            area[k] = math.sqrt(fma(e1, e1, e0 * e0))
            continue
        d0 = pts[b, 0] - pts[a, 0]
        d1 = pts[b, 1] - pts[a, 1]
        d2 = pts[b, 2] - pts[a, 2]
        r = math.sqrt(_dotfma(d0, d1, d2, d0, d1, d2))
        r_r[k] = r
        n0 = d0 / r
        n1 = d1 / r
        n2 = d2 / r
        K = s1 - s0
        c0 = vert[flat[s0], 0]
        c1 = vert[flat[s0], 1]
        c2 = vert[flat[s0], 2]
        for m in range(s0 + 1, s1):
            c0 = c0 + vert[flat[m], 0]
            c1 = c1 + vert[flat[m], 1]
            c2 = c2 + vert[flat[m], 2]
        c0 = c0 / K
        c1 = c1 / K
        c2 = c2 / K
        u0 = vert[flat[s0], 0] - c0
        u1 = vert[flat[s0], 1] - c1
        u2 = vert[flat[s0], 2] - c2
        un = math.sqrt(_dotfma(u0, u1, u2, u0, u1, u2))
        if un == 0.0:
            u0 = vert[flat[s0 + 1], 0] - c0
            u1 = vert[flat[s0 + 1], 1] - c1
            u2 = vert[flat[s0 + 1], 2] - c2
            un = math.sqrt(_dotfma(u0, u1, u2, u0, u1, u2))
        u0 = u0 / un
        u1 = u1 / un
        u2 = u2 / un
        v0 = n1 * u2 - n2 * u1
        v1 = n2 * u0 - n0 * u2
        v2 = n0 * u1 - n1 * u0
        for m in range(s0, s1):
            e0 = vert[flat[m], 0] - c0
            e1 = vert[flat[m], 1] - c1
            e2 = vert[flat[m], 2] - c2
            # (pts - c) @ u: OpenBLAS dgemv's fused order for three columns, added to y = +0
            # (a -0 becomes +0: it decides arctan2's -pi or +pi and so the vertex order)
            xy[0, m] = 0.0 + fma(e2, u2, fma(e0, u0, e1 * u1))
            xy[1, m] = 0.0 + fma(e2, v2, fma(e0, v0, e1 * v1))
    return -1


@njit(cache=True)
def _ridge_area_pass(rows, start, xy, ang, area):
    """3D face areas: the vertices sorted by angle, the shoelace sum as :func:`_polygon_area_3d`
    forms it.  Returns a mask of the ridges left to that function (16 or more vertices, where
    numpy's dot is another kernel, or two different vertices at the same angle, where the order
    numpy's sort gives is its own)."""
    nr = rows.shape[0]
    left = np.zeros(nr, np.bool_)
    order = np.empty(64, np.int64)
    for k in range(nr):
        if rows[k, 0] < 0:
            continue
        s0 = start[k]
        K = start[k + 1] - s0
        if K >= 16:
            left[k] = True
            continue
        for m in range(K):          # insertion sort by angle
            t = m
            while t > 0 and ang[s0 + order[t - 1]] > ang[s0 + m]:
                order[t] = order[t - 1]
                t -= 1
            order[t] = m
        tie = False
        for m in range(1, K):
            p = s0 + order[m - 1]
            q = s0 + order[m]
            if ang[p] == ang[q] and (xy[0, p] != xy[0, q] or xy[1, p] != xy[1, q]):
                tie = True
        if tie:
            left[k] = True
            continue
        dxy = 0.0
        dyx = 0.0
        for m in range(K):
            p = s0 + order[m]
            q = s0 + order[(m + 1) % K]
            dxy = fma(xy[1, q], xy[0, p], dxy)       # np.dot(x, np.roll(y, -1))
            dyx = fma(xy[0, q], xy[1, p], dyx)       # np.dot(y, np.roll(x, -1))
        area[k] = 0.5 * abs(dxy - dyx)
    return left


@njit(cache=True)
def _ridge_sums(kind, owner, rows, r_r, area, dim, vcell, key):
    """Clipped cell volumes ``vcell`` (pyramids of every face with an automaton, in ridge order)
    and per ridge the pair key ``min * n + max`` of its two automata (-1: a ghost-ghost or free
    surface face).  Returns the first ridge of an automaton with its own periodic image, or -1."""
    n = vcell.shape[0]
    for k in range(rows.shape[0]):
        a = rows[k, 0]
        if a < 0:
            continue
        b = rows[k, 1]
        q = 0.5 * r_r[k]
        vcell[a] += q * area[k] / dim
        kb = kind[b]
        if kb == 2:
            continue
        j = owner[b]
        if kb == 0:
            vcell[b] += q * area[k] / dim
        if j == a:
            return k
        key[k] = min(a, j) * n + max(a, j)
    return -1


@njit(cache=True)
def _pyramid_sums(i_p, j_p, S, q2, dim, omega):
    """``Omega_i = (1/D) sum_j q_ij S_ij`` in pair order."""
    for p in range(i_p.shape[0]):
        omega[i_p[p]] += q2[p, 0] * S[p] / dim
        omega[j_p[p]] += q2[p, 1] * S[p] / dim


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
