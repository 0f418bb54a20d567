"""The cell grid of the neighbour list: wrapping into the periodic box, cell slots and keys,
binning, the box key and the cell check (:func:`check_cell`).

Cells are slots along the three axes (slot 0 slowest); a particle's cell key is its slot
triple flattened.  Positions are wrapped into the box by an offset (the caller's positions are
never changed).
"""

import math

import numpy as np
from numba import njit, prange

from ..errors import InputError


#: most cells per particle before the grid of the unsorted and full-stencil searches is coarsened
#: (dilute, exploding samples: their memory stays O(N))
MAX_CELLS_PER_PARTICLE = 4


#: a sorted half list uses a dense cell array while the bounding box has at most this many cells per
#: particle, else only the occupied cells (sparse); both O(N) memory
DENSE_CELLS_PER_PARTICLE = 2


@njit(cache=True)
def _bin_particles(wpos_nc, lo_c, inv_cs_c, ncell_c):
    n = wpos_nc.shape[0]
    ncell = ncell_c[0] * ncell_c[1] * ncell_c[2]
    cell_n = np.empty(n, np.int64)
    count = np.zeros(ncell + 1, np.int64)
    for i in range(n):
        c = 0
        for d in range(3):
            k = int(math.floor((wpos_nc[i, d] - lo_c[d]) * inv_cs_c[d]))
            if k < 0:
                k = 0
            elif k >= ncell_c[d]:
                k = ncell_c[d] - 1
            c = c * ncell_c[d] + k
        cell_n[i] = c
        count[c + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    start = count.copy()
    order = np.empty(n, np.int64)
    fill = count[:-1].copy()
    for i in range(n):
        c = cell_n[i]
        order[fill[c]] = i
        fill[c] += 1
    return cell_n, start, order


@njit(cache=True)
def _wrap(pos_nc, box_c, periodic_c, wpos_nc):
    n = pos_nc.shape[0]
    for i in range(n):
        for d in range(3):
            x = pos_nc[i, d]
            if periodic_c[d]:
                x -= math.floor(x / box_c[d]) * box_c[d]
                if x >= box_c[d]:
                    x -= box_c[d]
            wpos_nc[i, d] = x


@njit(inline="always")
def _wrap1(x, box, periodic):
    """A coordinate wrapped into [0, box) along a periodic axis (as :func:`_wrap`), else itself."""
    if periodic:
        x -= math.floor(x / box) * box
        if x >= box:
            x -= box
    return x


@njit(inline="always")
def _slot(w, lo, inv_cs, m):
    k = int(math.floor((w - lo) * inv_cs))
    return min(max(k, 0), m - 1)


@njit(inline="always")
def _cell_key(pos_nc, i, box_c, periodic_c, lo_c, inv_cs_c, ncell_c, axes):
    """Cell key (slot 0 slowest) of particle i: (k0 * n1 + k1) * n2 + k2."""
    a0 = axes[0]
    a1 = axes[1]
    a2 = axes[2]
    k0 = _slot(_wrap1(pos_nc[i, a0], box_c[a0], periodic_c[a0]), lo_c[a0], inv_cs_c[a0], ncell_c[a0])
    k1 = _slot(_wrap1(pos_nc[i, a1], box_c[a1], periodic_c[a1]), lo_c[a1], inv_cs_c[a1], ncell_c[a1])
    k2 = _slot(_wrap1(pos_nc[i, a2], box_c[a2], periodic_c[a2]), lo_c[a2], inv_cs_c[a2], ncell_c[a2])
    return (k0 * ncell_c[a1] + k1) * ncell_c[a2] + k2


@njit(cache=True, parallel=True)
def _cell_keys(pos_nc, box_c, periodic_c, lo_c, inv_cs_c, ncell_c, axes, key_n):
    """Cell key of every particle (:func:`_cell_key`), in parallel."""
    for i in prange(pos_nc.shape[0]):
        key_n[i] = _cell_key(pos_nc, i, box_c, periodic_c, lo_c, inv_cs_c, ncell_c, axes)


@njit(cache=True)
def _layer_rows(ukey, ustart, per):
    """The most rows in one layer of the slowest slot (cells ``per`` keys apart share a layer)."""
    best = 0
    q = 0
    nq = ukey.shape[0]
    while q < nq:
        g = ukey[q] // per
        r = q
        while r < nq and ukey[r] // per == g:
            r += 1
        best = max(best, ustart[r] - ustart[q])
        q = r
    return best


def _box_key(cell, pbc):
    """What :meth:`NeighborList.update` compares to tell whether the box changed since the build:
    the bytes of the cell's nine float64 values and of the three periodic flags (under 1 us;
    as tuples of Python values it took 4 us, a fiftieth of a step of 2 048 clusters).  A change of
    bits that leaves the values equal (-0.0 for 0.0) rebuilds the list once more than needed."""
    pbc = np.asarray(pbc, dtype=bool)
    if pbc.shape != (3,):
        pbc = np.broadcast_to(pbc, (3,))
    return np.ascontiguousarray(cell, dtype=np.float64).tobytes() + pbc.tobytes()


def check_cell(cell, pbc):
    """Return (box lengths, periodic flags) of an open or periodic orthorhombic cell.

    Raises InputError for a non-orthorhombic periodic cell or a periodic
    direction of zero length.
    """
    cell = np.asarray(cell, dtype=float).reshape(3, 3)
    pbc = np.broadcast_to(np.asarray(pbc, dtype=bool), (3,)).copy()
    if pbc.any():
        off = cell - np.diag(np.diag(cell))
        if np.abs(off).max() > 1e-10 * max(1.0, np.abs(cell).max()):
            raise InputError("cell", cell.round(6).tolist(),
                             "an orthorhombic (diagonal) cell when any direction is periodic",
                             hint="triclinic periodic cells are not supported")
        for d in range(3):
            if pbc[d] and not cell[d, d] > 0:
                raise InputError("cell", cell.round(6).tolist(),
                                 f"a positive length along periodic axis {'xyz'[d]}")
    return np.diag(cell).copy(), pbc
