"""Sorting the particles into cell order: the counting sort (dense grid), the radix sort
(sparse: occupied cells only), and the gathers of the positions into the sorted row order.

Row k of a sorted list is particle ``perm[k]``; the sort is stable in the caller's order, so
the same positions always give the same rows.
"""

import numpy as np
from numba import njit, prange

from ..parallel import STREAM_BLOCK as BLOCK
from .grid import _cell_keys, _wrap1


@njit(cache=True, parallel=True)
def _gather_sorted(pos_nc, box_c, periodic_c, perm, xs_nc, offs_nc, row_n):
    """Sorted wrapped positions of the rows of ``perm``, and each particle's wrap offset and row
    (caller's order: ``offs_nc[i]``, ``row_n[i]``), in parallel.  The rows are ``pos + offset``,
    the sum :func:`gather_positions` makes, so that they are the step's sorted positions bit
    for bit (the calculator does not gather them again after a build)."""
    for k in prange(perm.shape[0]):
        i = perm[k]
        row_n[i] = k
        for d in range(3):
            o = _wrap1(pos_nc[i, d], box_c[d], periodic_c[d]) - pos_nc[i, d]
            offs_nc[i, d] = o
            xs_nc[k, d] = pos_nc[i, d] + o


@njit(cache=True)
def _count_sort(cell_n, ncell, perm):
    """Stable counting sort of the keys ``cell_n`` (< ncell) into ``perm``; returns the occupied
    cells ``(ukey, ustart)`` and the dense row starts (ncell + 1).  One array of the grid's size
    (up to :data:`DENSE_CELLS_PER_PARTICLE` x 8 bytes a particle): the cells' ends, counted down
    to their starts by a backward fill (which keeps equal keys in their order)."""
    n = cell_n.shape[0]
    end = np.zeros(ncell + 2, np.int64)     # end[c + 1]: rows up to the end of cell c
    for i in range(n):
        end[cell_n[i] + 1] += 1
    m = 0
    for c in range(ncell):
        if end[c + 1] > 0:
            m += 1
        end[c + 1] += end[c]
    for i in range(n - 1, -1, -1):
        c = cell_n[i] + 1
        end[c] -= 1
        perm[end[c]] = i
    end[ncell + 1] = n
    start = end[1:]                         # start[c]: first row of cell c; start[ncell] = n
    ukey = np.empty(m, np.int64)
    ustart = np.empty(m + 1, np.int64)
    q = 0
    for c in range(ncell):
        if start[c + 1] > start[c]:
            ukey[q] = c
            ustart[q] = start[c]
            q += 1
    ustart[m] = n
    return ukey, ustart, start


#: bits per digit of the radix sort of sparse cell keys
RADIX_BITS = 11


@njit(cache=True)
def _radix_sort(key, perm, scr):
    """Stable LSD radix sort of the keys ``key`` (>= 0) into ``perm``; returns the occupied cells
    ``(ukey, ustart)``.  Allocates nothing of N's size but ``ustart``: the passes go back and
    forth between (``key``, ``perm``) and two halves of ``scr`` (at least 2 N int64; the caller
    lends the wrap offsets' buffer, written only after the sort), and ``ukey`` is a view of
    ``key`` (the distinct keys, compacted at its start), valid until ``key`` is written again."""
    n = key.shape[0]
    key0 = key
    idx = perm
    kmax = 0
    for i in range(n):
        idx[i] = i
        kmax = max(kmax, key[i])
    nbits = 0
    while nbits < 63 and (kmax >> nbits) > 0:
        nbits += 1
    key2 = scr[:n]
    idx2 = scr[n:2 * n]
    nd = 1 << RADIX_BITS
    mask = nd - 1
    count = np.empty(nd + 1, np.int64)
    sh = 0
    while sh < nbits:                       # LSD: stable, so equal keys keep the original order
        count[:] = 0
        for i in range(n):
            count[((key[i] >> sh) & mask) + 1] += 1
        for d in range(nd):
            count[d + 1] += count[d]
        for i in range(n):
            d = (key[i] >> sh) & mask
            q = count[d]
            count[d] += 1
            key2[q] = key[i]
            idx2[q] = idx[i]
        key, key2 = key2, key
        idx, idx2 = idx2, idx
        sh += RADIX_BITS
    m = 0
    for k in range(n):
        if k == 0 or key[k] != key[k - 1]:
            m += 1
    ustart = np.empty(m + 1, np.int64)
    q = 0
    last = -1
    for k in range(n):
        c = key[k]
        if k == 0 or c != last:
            key0[q] = c                     # q <= k: in place when the sorted keys are key0
            ustart[q] = k
            q += 1
        last = c
        perm[k] = idx[k]
    ustart[m] = n
    return key0[:m], ustart


def _sort_rows(pos_nc, box_c, periodic_c, lo_c, inv_cs_c, ncell_c, axes, perm, xs_nc, offs_nc, row_n, key_n,
               sparse):
    """Sort of the particles by cell (slot 0 slowest), stable in the original order: a counting
    sort over the dense grid, or with ``sparse`` a radix sort of the cell keys (memory O(N)
    whatever the number of cells of the bounding box; the same order).  Fills ``perm`` (sorted
    row k is particle perm[k]), the sorted wrapped positions ``xs_nc``, and the particles' wrap
    offsets ``offs_nc`` and rows ``row_n`` (both in the caller's order); returns the occupied
    cells ``(ukey, ustart)`` (ascending keys; cell ukey[q] holds rows ustart[q]..ustart[q+1])
    and the dense row starts (ncell + 1; empty with ``sparse``).
    The keys (into the scratch ``key_n``) and the gather run in parallel, the sort in one thread."""
    _cell_keys(pos_nc, box_c, periodic_c, lo_c, inv_cs_c, ncell_c, axes, key_n)
    if sparse:
        ukey, ustart = _radix_sort(key_n, perm, offs_nc.reshape(-1).view(np.int64))
        dstart = np.empty(0, np.int64)
    else:
        ukey, ustart, dstart = _count_sort(key_n, int(ncell_c[0] * ncell_c[1] * ncell_c[2]), perm)
    _gather_sorted(pos_nc, box_c, periodic_c, perm, xs_nc, offs_nc, row_n)
    return ukey, ustart, dstart


@njit(cache=True, parallel=True)
def gather_positions(pos_nc, perm, offs_nc, xs_nc):
    """xs[k] = pos[i] + offset[i], i = perm[k]: sorted wrapped positions for the kernels."""
    n = perm.shape[0]
    for b in prange((n + BLOCK - 1) // BLOCK):
        for k in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            i = np.uint64(perm[k])
            xs_nc[k, 0] = pos_nc[i, 0] + offs_nc[i, 0]
            xs_nc[k, 1] = pos_nc[i, 1] + offs_nc[i, 1]
            xs_nc[k, 2] = pos_nc[i, 2] + offs_nc[i, 2]


@njit(cache=True)
def _is_identity(perm_n):
    for k in range(perm_n.shape[0]):
        if perm_n[k] != k:
            return False
    return True


@njit(cache=True)
def _identity(perm_n):
    for k in range(perm_n.shape[0]):
        perm_n[k] = k
