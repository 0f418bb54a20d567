"""Fragments: connected components of the bond graph, for Cluster Dynamics and MCA alike.

A *bond* joins two particles

* in Cluster Dynamics, when they are closer than ``b r0_ab`` (the pair's
  cluster size ``r0_ab = (r0_a + r0_b)/2`` for two materials a and b; by
  default ``b = rc``, the calculator's cutoff, so a fragment is what the
  potential still holds together);
* in MCA, when the pair is linked (the MCA state's ``linked_p == 1``), or
  for any explicit list of pairs ``(i_p, j_p)`` (rows of the Atoms).

A fragment is a connected component of that graph.  Every analysis here
goes through one implementation: a numba union-find over a pair list.  For
Cluster Dynamics the pair list is the project's cell list
(:class:`clusterdyn.neighbors.NeighborList`, sorted, half list, no skin),
so periodic axes join fragments across faces with the images the cell list
found; an explicit pair list takes each pair at its minimum image.

Per fragment: the number of particles g, the mass, the centre of mass, the
velocity (momentum / mass), the volume (sum of the particle volumes) and the
equivalent diameter ``(6 V / pi)^(1/3)``.  A cluster's volume is
``r0^3 / sqrt 2`` (its cell in the fcc packing), so a one-material CD
fragment has ``V = g r0^3 / sqrt 2``; an MCA automaton's is its cell volume
held by the MCA state.

Centre of mass across periodic faces
------------------------------------
The union-find carries, for every particle, the integer lattice image that
places it next to its bonded partners (a *weighted* union-find: each link
stores the image of a particle relative to its parent, and the bonds' own
images, from the cell list or the minimum image, fix them).  The fragment is
thereby unwrapped through its own bonds, its centre of mass taken, and the
centre wrapped back into the box.  A fragment bonded to its own periodic
image along an axis (a slab spanning a periodic box: a cycle of bonds whose
images do not add to zero) has no unique centre along that axis; it is
flagged in ``percolating[f, axis]``, and its centre along that axis is the
mass-weighted mean of the wrapped coordinates (the box centre for a
uniform slab).

This module holds the graph: the union-find kernels, the bond sources and
:class:`FragmentFinder`; :mod:`clusterdyn.analysis.fragment_spectra` the result
(:class:`~clusterdyn.analysis.fragment_spectra.Fragments`) and its spectra;
:mod:`clusterdyn.analysis.fragments` the entry points.
"""

import math
import time

import numpy as np
from numba import njit

from ..errors import InputError
from ..neighbors import NeighborList, check_cell
from ..parallel import use_threads
from .fragment_spectra import Fragments

__all__ = ["FragmentFinder", "IMG_BITS", "IMG_LIMIT"]

SQRT2 = math.sqrt(2.0)


# ----------------------------------------------------------------------------- numba kernels
# One union-find: _find / _union are shared by both pair sources (cell list, explicit pairs).
# A particle's lattice image relative to its parent is packed in one int64, three signed
# 21-bit fields (x * 2^42 + y * 2^21 + z): packed images add as integers, so path halving
# costs one extra add and store.  |image| < 2^20 per axis (checked by the caller).

IMG_BITS = 21
IMG_LIMIT = 1 << (IMG_BITS - 1)


@njit(inline="always")
def _pack(k0, k1, k2):
    return (k0 << 42) + (k1 << 21) + k2


@njit(inline="always")
def _unpack(k):
    """(k0, k1, k2) of a packed image (signed fields)."""
    h = np.int64(1 << 20)
    m = np.int64((1 << 21) - 1)
    k2 = ((k + h) & m) - h
    r = (k - k2) >> 21
    k1 = ((r + h) & m) - h
    k0 = (r - k1) >> 21
    return k0, k1, k2


@njit(inline="always")
def _find(parent_n, off_n, i):
    """Root of ``i`` and the packed image of ``i`` relative to it (path halving keeps offsets exact)."""
    k = np.int64(0)
    while True:
        p = parent_n[i]
        if p == i:
            return i, k
        gp = parent_n[p]
        if gp != p:
            off_n[i] += off_n[p]
            parent_n[i] = gp
        k += off_n[i]
        i = parent_n[i]


@njit(inline="always")
def _union(parent_n, size_n, off_n, perc_n, i, j, s):
    """Join i and j, bonded with j at packed image s relative to i (k_j - k_i = s)."""
    ri, a = _find(parent_n, off_n, i)
    rj, b = _find(parent_n, off_n, j)
    if ri == rj:
        # a cycle: its images must add to zero, else the fragment meets its own image
        if b - a != s:
            d0, d1, d2 = _unpack(b - a - s)
            perc_n[ri] |= (d0 != 0) | ((d1 != 0) << 1) | ((d2 != 0) << 2)
        return
    if size_n[ri] >= size_n[rj]:
        # rj under ri: in ri's frame k_j = a + s, and k_j = off[rj] + b
        parent_n[rj] = ri
        off_n[rj] = a + s - b
        size_n[ri] += size_n[rj]
        perc_n[ri] |= perc_n[rj]
    else:
        parent_n[ri] = rj
        off_n[ri] = b - s - a
        size_n[rj] += size_n[ri]
        perc_n[rj] |= perc_n[ri]


@njit(cache=True)
def _union_csr(xs_nc, type_n, cut2_tt, first_n, j_p, img_p, image_sc, shift_s,
               parent_n, size_n, off_n, perc_n):
    """Union over a CSR cell list: bond when ``|d| < sqrt(cut2_tt[t_i, t_j])``; returns the bonds.

    xs_nc : (N, 3) wrapped positions in the list's row order; type_n : (N,) material ids of
    the rows; first_n, j_p, img_p, image_sc : the list (:class:`NeighborList`);
    shift_s : (S,) packed integer lattice image of each image code.
    """
    n = xs_nc.shape[0]
    nb = 0
    for i in range(n):
        ti = type_n[i]
        x0 = xs_nc[i, 0]
        x1 = xs_nc[i, 1]
        x2 = xs_nc[i, 2]
        for p in range(first_n[i], first_n[i + 1]):
            j = j_p[p]
            c = img_p[p]
            dx = xs_nc[j, 0] - x0 + image_sc[c, 0]
            dy = xs_nc[j, 1] - x1 + image_sc[c, 1]
            dz = xs_nc[j, 2] - x2 + image_sc[c, 2]
            if dx * dx + dy * dy + dz * dz < cut2_tt[ti, type_n[j]]:
                nb += 1
                _union(parent_n, size_n, off_n, perc_n, i, j, shift_s[c])
    return nb


@njit(cache=True)
def _union_pairs(w_nc, box_c, periodic_c, i_p, j_p, parent_n, size_n, off_n, perc_n):
    """Union over explicit pairs, each at its minimum image (w_nc: wrapped positions)."""
    for p in range(i_p.shape[0]):
        i = i_p[p]
        j = j_p[p]
        s0 = 0
        s1 = 0
        s2 = 0
        if periodic_c[0]:
            s0 = -int(round((w_nc[j, 0] - w_nc[i, 0]) / box_c[0]))
        if periodic_c[1]:
            s1 = -int(round((w_nc[j, 1] - w_nc[i, 1]) / box_c[1]))
        if periodic_c[2]:
            s2 = -int(round((w_nc[j, 2] - w_nc[i, 2]) / box_c[2]))
        _union(parent_n, size_n, off_n, perc_n, i, j, _pack(s0, s1, s2))
    return i_p.shape[0]


@njit(cache=True)
def _label(parent_n, off_n, perc_n, row_n, label_n, k_n3):
    """Fragment index of each particle (caller order; ``row_n[i]``: its union-find row).

    Fragments are numbered in order of their first particle (as
    scipy.sparse.csgraph.connected_components does); ``k_n3`` receives each
    particle's lattice image relative to its fragment's root.  Returns the
    per-fragment percolation flags (F, 3).
    """
    nr = parent_n.shape[0]
    # compress every path in row order first (sequential), so the caller-order pass is one hop
    for r in range(nr):
        q, k = _find(parent_n, off_n, r)
        parent_n[r] = q
        off_n[r] = k
    n = row_n.shape[0]
    lab_r = np.full(nr, -1, np.int64)
    perc_f3 = np.zeros((n, 3), np.bool_)
    nf = 0
    for i in range(n):
        r = row_n[i]
        q = parent_n[r]
        f = lab_r[q]
        if f < 0:
            f = nf
            lab_r[q] = f
            for d in range(3):
                perc_f3[f, d] = (perc_n[q] >> d) & 1
            nf += 1
        label_n[i] = f
        k0, k1, k2 = _unpack(off_n[r])
        k_n3[i, 0] = k0
        k_n3[i, 1] = k1
        k_n3[i, 2] = k2
    return perc_f3[:nf]


@njit(cache=True)
def _sums(label_n, nf, m_n, p_nc, w_nc, k_n3, box_c, vol_n):
    """Per fragment: count, mass, momentum, sum m*unwrapped x, sum m*wrapped x, volume."""
    g_f = np.zeros(nf, np.int64)
    m_f = np.zeros(nf)
    p_f3 = np.zeros((nf, 3))
    mu_f3 = np.zeros((nf, 3))
    mw_f3 = np.zeros((nf, 3))
    v_f = np.zeros(nf)
    for i in range(label_n.shape[0]):
        f = label_n[i]
        m = m_n[i]
        g_f[f] += 1
        m_f[f] += m
        v_f[f] += vol_n[i]
        for d in range(3):
            p_f3[f, d] += p_nc[i, d]
            mw_f3[f, d] += m * w_nc[i, d]
            mu_f3[f, d] += m * (w_nc[i, d] + k_n3[i, d] * box_c[d])
    return g_f, m_f, p_f3, mu_f3, mw_f3, v_f



def _is_mca_state(obj):
    return hasattr(obj, "linked_p") and hasattr(obj, "pair_rows")


def _material_ids(atoms):
    mid = atoms.arrays.get("material")
    if mid is None:
        return np.zeros(len(atoms), np.int64)
    return np.ascontiguousarray(mid, dtype=np.int64)


def _r0_per_material(atoms, r0, nmat):
    """r0 per material id (Angstrom) from the argument, the Atoms or their calculator, or None."""
    src = r0
    if src is None:
        src = atoms.info.get("cd_r0")
    if src is None:
        src = _calc_parameter(atoms, "r0")
    if src is None:
        return None
    r = np.atleast_1d(np.asarray(src, dtype=float))
    if len(r) == 1 and nmat > 1:
        r = np.repeat(r, nmat)
    if r.ndim != 1 or len(r) < nmat or not np.all(np.isfinite(r)) or not np.all(r > 0):
        raise InputError("r0", src, f"one positive cluster size (Angstrom) or one per material id "
                                    f"(ids 0..{nmat - 1})")
    return r


def _calc_parameter(atoms, name):
    """A parameter of the Atoms' calculator (ASE ``calc.parameters``), or None."""
    params = getattr(atoms.calc, "parameters", None) if atoms.calc is not None else None
    return params.get(name) if isinstance(params, dict) else None


def _bond_factor(atoms, b):
    if b is None:
        b = _calc_parameter(atoms, "rc")
    if b is None:
        raise InputError("b", None, "a bond distance as a multiple of r0 (default: the cutoff rc of "
                                    "the Atoms' ClusterDynamics calculator, which these Atoms lack)",
                         hint="for MCA give pairs= (the MCA state or linked pair rows)")
    try:
        bf = float(b)
    except (TypeError, ValueError):
        raise InputError("b", b, "a number > 0 (multiple of r0)") from None
    if not (math.isfinite(bf) and bf > 0):
        raise InputError("b", b, "a number > 0 (multiple of r0)")
    return bf


def _check_pairs(pairs, n):
    try:
        i_p, j_p = pairs
    except (TypeError, ValueError):
        raise InputError("pairs", type(pairs).__name__, "None, an MCA state, or two arrays (i_p, j_p) "
                                                         "of particle rows") from None
    i_p = np.ascontiguousarray(i_p, dtype=np.int64).ravel()
    j_p = np.ascontiguousarray(j_p, dtype=np.int64).ravel()
    if i_p.shape != j_p.shape:
        raise InputError("pairs", f"{len(i_p)} and {len(j_p)} rows", "two arrays of equal length")
    if len(i_p) and (min(i_p.min(), j_p.min()) < 0 or max(i_p.max(), j_p.max()) >= n):
        raise InputError("pairs", f"rows {min(i_p.min(), j_p.min())}..{max(i_p.max(), j_p.max())}",
                         f"particle rows in 0..{n - 1}")
    return i_p, j_p


def _check_images(ns, step_c, box_c, periodic_c):
    """Refuse a graph whose lattice images could overflow the packed fields.

    A particle's image relative to its fragment's root is that of a path of at
    most ``ns`` bonds, each moving at most ``step_c`` along an axis, so it is
    below ``ns * step_c / L + 1`` box lengths.
    """
    for d in range(3):
        if periodic_c[d] and ns * min(step_c[d], 0.5 * box_c[d]) / box_c[d] + 2 >= IMG_LIMIT:
            raise InputError("atoms", f"{ns} particles in a periodic box {box_c.round(6).tolist()}",
                             f"fewer than {IMG_LIMIT} bond lengths across each periodic axis "
                             "(fragment images are held in 21-bit fields)")


def _wrapped(pos, box_c, periodic_c):
    w = np.array(pos, dtype=np.float64, order="C")
    for d in range(3):
        if periodic_c[d]:
            w[:, d] -= np.floor(w[:, d] / box_c[d]) * box_c[d]
            w[w[:, d] >= box_c[d], d] -= box_c[d]
    return w


class FragmentFinder:
    """Reusable fragment finder (keeps its cell list and work arrays between calls).

    :func:`fragments` makes one per call; :class:`FragmentAnalysis` and
    :class:`FragmentObserver` keep one across frames.  Parameters as
    :func:`fragments`.
    """

    def __init__(self, b=None, *, r0=None, pairs=None, volumes=None, exclude=None):
        self.b = b
        self.r0 = r0
        self.pairs = pairs
        self.volumes = volumes
        self.exclude = exclude
        self._nl = None

    def __call__(self, atoms):
        return self.find(atoms)

    def find(self, atoms, pairs=None):
        """The :class:`Fragments` of ``atoms`` (``pairs`` overrides the finder's)."""
        pairs = self.pairs if pairs is None else pairs
        if callable(pairs) and not _is_mca_state(pairs):
            pairs = pairs(atoms)
        n = len(atoms)
        box_c, periodic_c = check_cell(atoms.cell.array, atoms.pbc)
        mid = _material_ids(atoms)
        if n and mid.min() < 0:
            raise InputError("atoms.arrays['material']", int(mid.min()), "material ids >= 0")
        nmat = int(mid.max()) + 1 if n else 1
        keep = self._keep(atoms)
        vol = self._volumes(atoms, pairs, mid, nmat)
        if pairs is None:
            bf = _bond_factor(atoms, self.b)
            r0m = _r0_per_material(atoms, self.r0, nmat)
            if r0m is None:
                raise InputError("r0", None, "cluster sizes: r0= or Atoms from a clusterdyn builder "
                                             "(atoms.info['cd_r0'])")
            bond = f"distance b*r0_ab (b={bf:g})"
        else:
            bf = r0m = None
            if _is_mca_state(pairs):
                i_p, j_p = pairs.pair_rows(atoms)[:2]
                lk = np.asarray(pairs.linked_p) == 1
                i_p, j_p = _check_pairs((i_p[lk], j_p[lk]), n)
                bond = "linked pairs (MCA state)"
            else:
                i_p, j_p = _check_pairs(pairs, n)
                bond = "pairs"
        pos, masses, mom = atoms.get_positions(), atoms.get_masses(), atoms.get_momenta()
        sel = None
        if keep is not None:
            sel = np.nonzero(keep)[0]
            pos, masses, mom, vol, mid = pos[sel], masses[sel], mom[sel], vol[sel], mid[sel]
            if pairs is not None:
                new = np.full(n, -1, np.int64)
                new[sel] = np.arange(len(sel))
                ok = keep[i_p] & keep[j_p]
                i_p, j_p = new[i_p[ok]], new[j_p[ok]]
        t0 = time.perf_counter()
        if pairs is None:
            graph = self._distance_graph(atoms, pos, mid, bf, r0m, box_c, periodic_c)
        else:
            graph = self._pair_graph(pos, i_p, j_p, box_c, periodic_c)
        parent, off, perc, row, w, nbonds, meta = graph
        ns = len(pos)
        lab = np.empty(ns, np.int64)
        k = np.empty((ns, 3), np.int64)
        perc_f = _label(parent, off, perc, row, lab, k)
        t1 = time.perf_counter()
        g, m, p, mu, mw, v = _sums(lab, len(perc_f), np.ascontiguousarray(masses, dtype=np.float64),
                                   np.ascontiguousarray(mom, dtype=np.float64), w, k, box_c,
                                   np.ascontiguousarray(vol, dtype=np.float64))
        with np.errstate(invalid="ignore", divide="ignore"):
            com = np.where(perc_f, mw, mu) / m[:, None]
            vel = p / m[:, None]
        for d in range(3):
            if periodic_c[d]:
                com[:, d] -= np.floor(com[:, d] / box_c[d]) * box_c[d]
        labels = lab
        if sel is not None:
            labels = np.full(n, -1, np.int64)
            labels[sel] = lab
        t_search = meta.pop("t_search", 0.0)
        meta["timings_s"] = {"pair_search": t_search, "union_find": t1 - t0 - t_search,
                             "properties": time.perf_counter() - t1}
        step = atoms.info.get("step")
        t_info = atoms.info.get("time")
        return Fragments(labels=labels, g=g, mass=m, com=com, velocity=vel, volume=v,
                         diameter=np.cbrt(6.0 * v / math.pi), percolating=perc_f, nbonds=int(nbonds),
                         bond=bond, b=bf, step=None if step is None else int(step),
                         time=None if t_info is None else float(t_info), meta=meta)

    @staticmethod
    def _forest(ns):
        """Union-find arrays: parent, size, packed image to the parent, percolation bits."""
        return (np.arange(ns, dtype=np.int64), np.ones(ns, np.int64), np.zeros(ns, np.int64),
                np.zeros(ns, np.int8))

    def _distance_graph(self, atoms, pos, mid, bf, r0m, box_c, periodic_c):
        """CD bonds: pairs of the cell list closer than ``b r0_ab``."""
        t0 = time.perf_counter()
        ns = len(pos)
        cut = bf * 0.5 * (r0m[:, None] + r0m[None, :])
        _check_images(ns, np.full(3, cut.max()), box_c, periodic_c)
        parent, size, off, perc = self._forest(ns)
        if ns == 0:
            return parent, off, perc, parent, np.zeros((0, 3)), 0, {}
        if self._nl is None or self._nl.cutoff != float(cut.max()):
            self._nl = NeighborList(float(cut.max()), 0.0, half=True, sort=True)
        nl = self._nl
        use_threads(ns)
        nl.build(pos, atoms.cell.array, atoms.pbc)
        xs = nl.sorted_positions(pos)
        t_search = time.perf_counter() - t0
        shift3 = np.zeros(nl.image_sc.shape, np.int64)
        for d in range(3):
            if periodic_c[d]:
                shift3[:, d] = np.rint(nl.image_sc[:, d] / box_c[d]).astype(np.int64)
        shift = (shift3[:, 0] << 42) + (shift3[:, 1] << 21) + shift3[:, 2]
        perm = nl.perm_n
        nbonds = _union_csr(xs, np.ascontiguousarray(mid[perm]), np.ascontiguousarray(cut * cut),
                            nl.first_n, nl.j_p, nl.img_p, nl.image_sc, shift, parent, size, off, perc)
        row = np.empty(ns, np.int64)
        row[perm] = np.arange(ns)
        w = np.empty_like(xs)
        w[perm] = xs
        return parent, off, perc, row, w, nbonds, {"npairs_searched": nl.npairs, "t_search": t_search}

    def _pair_graph(self, pos, i_p, j_p, box_c, periodic_c):
        """Bonds given as pairs of rows, each at its minimum image."""
        ns = len(pos)
        w = _wrapped(pos, box_c, periodic_c)
        step_c = 0.5 * box_c
        if ns // 2 + 2 >= IMG_LIMIT and len(i_p):
            d = np.abs(w[j_p] - w[i_p])
            step_c = np.minimum(d, box_c - d).max(axis=0)
        _check_images(ns, step_c, box_c, periodic_c)
        parent, size, off, perc = self._forest(ns)
        nbonds = _union_pairs(w, box_c, periodic_c, i_p, j_p, parent, size, off, perc)
        return parent, off, perc, np.arange(ns, dtype=np.int64), w, nbonds, {}

    def _keep(self, atoms):
        """Bool mask of the particles analysed (None: all)."""
        if self.exclude is None:
            return None
        n = len(atoms)
        ex = self.exclude(atoms) if callable(self.exclude) else self.exclude
        ex = np.asarray(ex)
        if ex.dtype != bool or ex.shape != (n,):
            raise InputError("exclude", f"{ex.dtype} array of shape {ex.shape}",
                             f"a bool mask of shape ({n},) or a callable returning one")
        return ~ex

    def _volumes(self, atoms, pairs, mid, nmat):
        """Particle volumes, Angstrom^3: given; MCA cell volumes; r0^3/sqrt 2; (2 radius)^3/sqrt 2."""
        n = len(atoms)
        vol = self.volumes
        if callable(vol):
            vol = vol(atoms)
        if vol is not None:
            vol = np.asarray(vol, dtype=float)
            if vol.shape != (n,) or not np.all(np.isfinite(vol)) or np.any(vol < 0):
                raise InputError("volumes", f"array of shape {vol.shape}",
                                 f"({n},) finite volumes >= 0, Angstrom^3")
            return vol
        if pairs is not None and _is_mca_state(pairs):
            return np.asarray(pairs.per_atom("omega_n", atoms), dtype=float)
        r0m = _r0_per_material(atoms, self.r0, nmat)
        if r0m is not None and pairs is None:
            return r0m[mid] ** 3 / SQRT2
        if "radius" in atoms.arrays:
            return (2.0 * np.asarray(atoms.arrays["radius"], float)) ** 3 / SQRT2
        if r0m is not None:
            return r0m[mid] ** 3 / SQRT2
        raise InputError("volumes", None, "particle volumes: volumes=, r0=, an MCA state or an "
                                          "atoms.arrays['radius']")
