"""Cell list + Verlet list with skin, numba kernels (open and periodic orthorhombic boxes).

The list is CSR over particles (like ASE's ``first_neighbors``):
pairs of particle ``i`` are ``p in range(first_n[i], first_n[i+1])`` with
partner ``j_p[p]`` and image code ``img_p[p]``.  The separation vector
used by every kernel is

    d = (pos[j] + offset[j]) - (pos[i] + offset[i]) + image_sc[img_p[p]]

where ``offset_nc`` wraps each particle into the periodic box at build time
(positions themselves are never changed) and ``image_sc`` holds the
Cartesian lattice translations.  A half list stores every unordered pair once
(``i < j``, or ``i == j`` with a positive image for boxes narrower than the
cutoff); a full list stores both directions.

The list is rebuilt when any particle has moved more than ``skin/2`` since
the last build (or, with ``centered=True``, when in addition the spread of
the displacements exceeds it), or when the cell or pbc changed.

With ``sort=True`` (the Cluster Dynamics calculator's list) the particles are
held in cell order: row k of the list is particle ``perm_n[k]``, positions
are gathered into that order every step (:func:`gather_positions`) and the
half list is built in a single pass over the own cell and the 13 forward
cells of the 3x3x3 stencil.  The caller's arrays are never reordered.
"""

import math

import numba
import numpy as np
from numba import njit, prange

from ..buffers import PERMUTE_WORDS, grown, permute
from ..errors import InputError
from ..parallel import STREAM_BLOCK as BLOCK, blocks_max, max_take, use_threads

#: blocks of the displacement check (fixed: the result does not depend on the thread count)
DISP_BLOCKS = 16
#: most cells per particle before the grid of the unsorted and full-stencil searches is coarsened
#: (dilute, exploding samples: their memory stays O(N))
MAX_CELLS_PER_PARTICLE = 4
#: a sorted half list uses a dense cell array while the bounding box has at most this many cells per
#: particle, else only the occupied cells (sparse); both O(N) memory
DENSE_CELLS_PER_PARTICLE = 2
#: rows per block of the half-list build (the unit of work of a thread and of a slab)
FILL_BLOCK_ROWS = 4096
#: a block's slab of the pair pool: its previous need times this (plus 64)
SLAB_MARGIN = 1.2
#: bit of the image code in a packed half-list pair ``j | code << HALF_SHIFT`` (27 codes; N < 2**27)
HALF_SHIFT = 27


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
def _keep(i, j, ix, iy, iz, half):
    if j == i and ix == 0 and iy == 0 and iz == 0:
        return False
    if not half:
        return True
    if j > i:
        return True
    if j < i:
        return False
    # j == i: keep the positive image only
    if ix != 0:
        return ix > 0
    if iy != 0:
        return iy > 0
    return iz > 0


@njit(cache=True, parallel=True)
def _search(wpos_nc, cell_n, start, order, ncell_c, krange_c, periodic_c, box_c, rcut2,
            half, count_only, first_n, j_p, img_p):
    """Count (count_only) or fill the pairs of every particle."""
    n = wpos_nc.shape[0]
    nimg_x = 2 * krange_c[0] + 1
    nimg_y = 2 * krange_c[1] + 1
    for i in prange(n):
        c = cell_n[i]
        cz = c % ncell_c[2]
        cy = (c // ncell_c[2]) % ncell_c[1]
        cx = c // (ncell_c[2] * ncell_c[1])
        cnt = 0
        pos = 0
        if not count_only:
            pos = first_n[i]
        xi0 = wpos_nc[i, 0]
        xi1 = wpos_nc[i, 1]
        xi2 = wpos_nc[i, 2]
        for ox in range(-krange_c[0], krange_c[0] + 1):
            gx = cx + ox
            ix = 0
            if periodic_c[0]:
                ix = gx // ncell_c[0]
                gx -= ix * ncell_c[0]
            elif gx < 0 or gx >= ncell_c[0]:
                continue
            for oy in range(-krange_c[1], krange_c[1] + 1):
                gy = cy + oy
                iy = 0
                if periodic_c[1]:
                    iy = gy // ncell_c[1]
                    gy -= iy * ncell_c[1]
                elif gy < 0 or gy >= ncell_c[1]:
                    continue
                for oz in range(-krange_c[2], krange_c[2] + 1):
                    gz = cz + oz
                    iz = 0
                    if periodic_c[2]:
                        iz = gz // ncell_c[2]
                        gz -= iz * ncell_c[2]
                    elif gz < 0 or gz >= ncell_c[2]:
                        continue
                    cc = (gx * ncell_c[1] + gy) * ncell_c[2] + gz
                    sx = ix * box_c[0]
                    sy = iy * box_c[1]
                    sz = iz * box_c[2]
                    code = ((ix + krange_c[0]) * nimg_y + (iy + krange_c[1])) * (2 * krange_c[2] + 1) \
                        + (iz + krange_c[2])
                    for q in range(start[cc], start[cc + 1]):
                        j = order[q]
                        if not _keep(i, j, ix, iy, iz, half):
                            continue
                        dx = wpos_nc[j, 0] + sx - xi0
                        dy = wpos_nc[j, 1] + sy - xi1
                        dz = wpos_nc[j, 2] + sz - xi2
                        if dx * dx + dy * dy + dz * dz < rcut2:
                            if count_only:
                                cnt += 1
                            else:
                                j_p[pos] = j
                                img_p[pos] = code
                                pos += 1
        if count_only:
            first_n[i + 1] = cnt
    return nimg_x


@njit(cache=True, parallel=True)
def _max_disp2(pos_nc, ref_nc):
    n = pos_nc.shape[0]
    m = np.zeros(n)
    for i in prange(n):
        dx = pos_nc[i, 0] - ref_nc[i, 0]
        dy = pos_nc[i, 1] - ref_nc[i, 1]
        dz = pos_nc[i, 2] - ref_nc[i, 2]
        m[i] = dx * dx + dy * dy + dz * dz
    return m.max() if n > 0 else 0.0


# -- sorted lists (cell order, half stencil, single pass) ----------------------------------------

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


@njit(inline="always")
def _lower(ukey, target, cur, r):
    """First q with ukey[q] >= target; ``cur[r]`` is the run's cursor (its last answer): the
    targets of a run mostly increase from cell to cell, so a short forward walk finds it,
    else a binary search."""
    m = ukey.shape[0]
    c = cur[r]
    ok = c >= 0 and (c == 0 or ukey[c - 1] < target)
    if ok:
        steps = 0
        while c < m and ukey[c] < target and steps < 8:
            c += 1
            steps += 1
        ok = c >= m or ukey[c] >= target
    if not ok:
        lo = 0
        hi = m
        while lo < hi:
            mid = (lo + hi) >> 1
            if ukey[mid] < target:
                lo = mid + 1
            else:
                hi = mid
        c = lo
    cur[r] = c
    return c


@njit(inline="always")
def _scan_rows(xs_nc, a0, a1, bx, by, bz, bp, hit, nbuf, rcut2, pool_p, pos, end, first_n):
    """Partners of the cell's rows a0..a1 among its stencil's candidates ``b*[:nbuf]`` (the
    own cell's rows first, from row a0 on: row i's candidates are ``b*[i - a0 + 1:nbuf]``),
    written as ``bp[u]`` one row after another into ``pool_p[pos:end]`` (counted beyond
    ``end``, not written); returns the next free position.  Two passes a row: the distance
    test into ``hit`` (contiguous arrays: LLVM vectorises it), then a branch-free compaction
    (every candidate is written at the next free slot, which only a hit keeps)."""
    nbu = np.uint64(nbuf)
    for i in range(a0, a1):
        u0 = np.uint64(i - a0 + 1)
        xi = xs_nc[i, 0]
        yi = xs_nc[i, 1]
        zi = xs_nc[i, 2]
        for u in range(u0, nbu):
            dx = bx[u] - xi
            dy = by[u] - yi
            dz = bz[u] - zi
            hit[u] = np.uint32(1) if dx * dx + dy * dy + dz * dz < rcut2 else np.uint32(0)
        cnt = np.uint64(0)
        pu = np.uint64(pos)
        room = max(end - pos, 0)
        if nbuf - (i - a0 + 1) <= room:
            for u in range(u0, nbu):
                pool_p[pu + cnt] = bp[u]
                cnt += np.uint64(hit[u])
        else:
            roomu = np.uint64(room)
            for u in range(u0, nbu):
                if cnt < roomu:
                    pool_p[pu + cnt] = bp[u]
                cnt += np.uint64(hit[u])
        k = np.int64(cnt)
        first_n[i + 1] = k
        pos += k
    return pos


@njit(cache=True, parallel=True)
def _fill_slabs(xs_nc, ukey, ustart, dstart, sparse, nslot, periodic_s, runs_r4, slotbox_s3, slotmult_s,
                rcut2, shift, cblk_b, slab_b, maxrows, pool_p, first_n, need_b):
    """Half list over sorted particles in one pass: own cell (j > i) + 13 forward cells.

    Cells are indexed in "slot" order (slot 0 slowest); ``nslot``/``periodic_s`` are
    the cell counts and periodicity per slot, ``slotbox_s3`` the Cartesian box
    vector of each slot's axis and ``slotmult_s`` its weight in the 3x3x3 image
    code.  Valid when every periodic slot has >= 3 cells of size >= the cut-off.
    The forward stencil is walked as runs of cells along the fastest slot
    (``runs_r4`` = d0, d1, first and last d2; :data:`HALF_RUNS`, whose first run
    starts at the own cell): cells of a run are consecutive rows, so a run is one
    segment of rows unless it wraps a periodic face.  The rows of a segment are
    found in the dense starts ``dstart`` or, with ``sparse``, among the occupied
    cells ``ukey`` (a cursor per run walks them forward).

    For each occupied cell the segments' rows are copied, in stencil order, into
    contiguous candidate arrays (at most the stencil's 14 cells times
    ``maxrows``, the most rows of a cell), each with its periodic image added to
    its position, and each of the cell's rows is tested against them in one scan
    (:func:`_scan_rows`): one long loop a row instead of a short one per segment,
    with the distance test vectorised.

    Work is split into blocks of occupied cells (``cblk_b``); block b writes its
    rows' partners, in stencil order, one after the other into its slab
    ``pool_p[slab_b[b]:slab_b[b+1]]`` as ``j | code << shift`` (uint32), row i's
    count into ``first_n[i + 1]`` and what it needed into ``need_b[b]``: a block
    that needs more than its slab counts its pairs without writing them, and the
    caller retries with more room.
    """
    m0 = nslot[0]
    m1 = nslot[1]
    m2 = nslot[2]
    nr = runs_r4.shape[0]
    nq = ukey.shape[0]
    nblk = cblk_b.shape[0] - 1
    ncand = 0
    for r in range(nr):
        ncand += runs_r4[r, 3] - runs_r4[r, 2] + 1
    bcap = ncand * maxrows
    for b in prange(nblk):
        bx = np.empty(bcap)
        by = np.empty(bcap)
        bz = np.empty(bcap)
        bp = np.empty(bcap, np.uint32)
        hit = np.empty(bcap, np.uint32)
        cur = np.full(nr, -1, np.int64)
        pos = slab_b[b]
        end = slab_b[b + 1]
        for q in range(cblk_b[b], cblk_b[b + 1]):
            c = ukey[q]
            g2 = c % m2
            g1 = (c // m2) % m1
            g0 = c // (m2 * m1)
            nbuf = 0
            for r in range(nr):
                h0 = g0 + runs_r4[r, 0]
                h1 = g1 + runs_r4[r, 1]
                i0 = 0
                i1 = 0
                if h0 < 0 or h0 >= m0:
                    if not periodic_s[0]:
                        continue
                    i0 = -1 if h0 < 0 else 1
                    h0 -= i0 * m0
                if h1 < 0 or h1 >= m1:
                    if not periodic_s[1]:
                        continue
                    i1 = -1 if h1 < 0 else 1
                    h1 -= i1 * m1
                base = (h0 * m1 + h1) * m2
                # segments of consecutive cells with one image along the fastest slot
                seg_lo = -1
                seg_hi = -1
                seg_i2 = 0
                for d2 in range(runs_r4[r, 2], runs_r4[r, 3] + 2):
                    last = d2 == runs_r4[r, 3] + 1
                    h2 = 0
                    i2 = 0
                    ok = False
                    if not last:
                        h2 = g2 + d2
                        ok = True
                        if h2 < 0 or h2 >= m2:
                            if periodic_s[2]:
                                i2 = -1 if h2 < 0 else 1
                                h2 -= i2 * m2
                            else:
                                ok = False
                    if ok and seg_lo >= 0 and i2 == seg_i2 and h2 == seg_hi + 1:
                        seg_hi = h2
                        continue
                    if seg_lo >= 0:
                        if sparse:
                            q0 = _lower(ukey, base + seg_lo, cur, r)
                            q1 = q0
                            while q1 < nq and ukey[q1] <= base + seg_hi:
                                q1 += 1
                            b0 = ustart[q0]
                            b1 = ustart[q1]
                        else:
                            b0 = dstart[base + seg_lo]
                            b1 = dstart[base + seg_hi + 1]
                        sx = i0 * slotbox_s3[0, 0] + i1 * slotbox_s3[1, 0] + seg_i2 * slotbox_s3[2, 0]
                        sy = i0 * slotbox_s3[0, 1] + i1 * slotbox_s3[1, 1] + seg_i2 * slotbox_s3[2, 1]
                        sz = i0 * slotbox_s3[0, 2] + i1 * slotbox_s3[1, 2] + seg_i2 * slotbox_s3[2, 2]
                        code = 13 + i0 * slotmult_s[0] + i1 * slotmult_s[1] + seg_i2 * slotmult_s[2]
                        bits = np.uint32(code) << np.uint32(shift)
                        for j in range(b0, b1):
                            ju = np.uint64(j)
                            w = np.uint64(nbuf)
                            bx[w] = xs_nc[ju, 0] + sx
                            by[w] = xs_nc[ju, 1] + sy
                            bz[w] = xs_nc[ju, 2] + sz
                            bp[w] = np.uint32(j) | bits
                            nbuf += 1
                    seg_lo = -1
                    if ok:
                        seg_lo = h2
                        seg_hi = h2
                        seg_i2 = i2
            pos = _scan_rows(xs_nc, ustart[q], ustart[q + 1], bx, by, bz, bp, hit, nbuf, rcut2, pool_p, pos, end,
                             first_n)
        need_b[b] = pos - slab_b[b]


def _carried_need(need_b, rows_b, new_rows_b, mean):
    """Slab sizes for new blocks after the particle count changed (particles removed): each new
    block gets its rows times the densest pairs-per-row of the old blocks over the same share of
    the rows (one block wider on each side), times the margin, so the pool needs no more room
    than before and is not reallocated (the fill retries a block that needs more)."""
    dens = need_b / np.maximum(rows_b, 1)
    ostart = np.concatenate([[0], np.cumsum(rows_b)])
    nstart = np.concatenate([[0], np.cumsum(new_rows_b)])
    scale = ostart[-1] / max(nstart[-1], 1)
    lo = np.clip(np.searchsorted(ostart, nstart[:-1] * scale, side="right") - 2, 0, dens.shape[0] - 1)
    hi = np.clip(np.searchsorted(ostart, nstart[1:] * scale, side="left") + 1, lo + 1, dens.shape[0])
    top = np.array([dens[a:b].max() for a, b in zip(lo, hi)])
    return np.maximum((new_rows_b * top * SLAB_MARGIN).astype(np.int64), (new_rows_b * mean).astype(np.int64))


@njit(cache=True)
def _close_slabs(pool_p, slab_b, need_b, first_n):
    """Move the slabs' pairs together (in place, in block order) and turn the row counts in
    ``first_n[1:]`` into CSR offsets; returns the number of pairs."""
    dst = 0
    for b in range(need_b.shape[0]):
        src = slab_b[b]
        m = need_b[b]
        if src != dst:
            for u in range(m):
                pool_p[dst + u] = pool_p[src + u]
        dst += m
    first_n[0] = 0
    for i in range(first_n.shape[0] - 1):
        first_n[i + 1] += first_n[i]
    return dst


@njit(cache=True)
def _cell_blocks(ustart, rows):
    """Blocks of consecutive occupied cells of about ``rows`` rows each: (cblk_b, rows_b, maxrows)."""
    nq = ustart.shape[0] - 1
    n = ustart[nq]
    nblk = max(1, (n + rows - 1) // rows)
    cblk = np.zeros(nblk + 1, np.int64)
    b = 1
    maxrows = 1
    for q in range(nq):
        maxrows = max(maxrows, ustart[q + 1] - ustart[q])
        while b < nblk and ustart[q + 1] >= b * rows:
            cblk[b] = q + 1
            b += 1
    for k in range(b, nblk + 1):
        cblk[k] = nq
    rows_b = np.empty(nblk, np.int64)
    for k in range(nblk):
        rows_b[k] = ustart[cblk[k + 1]] - ustart[cblk[k]]
    return cblk, rows_b, maxrows


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


@njit(cache=True, parallel=True)
def _pack(j_p, img_p, shift, out_p):
    for p in prange(j_p.shape[0]):
        out_p[p] = np.uint32(j_p[p]) | (np.uint32(img_p[p]) << np.uint32(shift))


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


@njit(cache=True, parallel=True)
def gather_velocities(p_nc, invm_n, perm, vs_nc):
    """vs[k] = p[perm[k]] / m[perm[k]]."""
    n = perm.shape[0]
    for b in prange((n + BLOCK - 1) // BLOCK):
        for k in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            i = np.uint64(perm[k])
            w = invm_n[i]
            vs_nc[k, 0] = p_nc[i, 0] * w
            vs_nc[k, 1] = p_nc[i, 1] * w
            vs_nc[k, 2] = p_nc[i, 2] * w


#: start of a block's displacement bounds: (max |d|^2, min dx, dy, dz, max dx, dy, dz)
@njit(inline="always")
def _disp_start():
    return (0.0, 1e300, 1e300, 1e300, -1e300, -1e300, -1e300)


@njit(inline="always")
def _disp_add(acc, dx, dy, dz):
    """The bounds ``acc`` with one more displacement (a NaN makes the max inf)."""
    m, lx, ly, lz, hx, hy, hz = acc
    r2 = dx * dx + dy * dy + dz * dz
    if r2 != r2:
        m = np.inf
    return (max(m, r2), min(lx, dx), min(ly, dy), min(lz, dz), max(hx, dx), max(hy, dy), max(hz, dz))


@njit(inline="always")
def _disp_result(rows_b7):
    """(max |d|^2, squared half-diagonal of the bounding box) over blocks, in block order."""
    m = 0.0
    lo = np.full(3, 1e300)
    hi = np.full(3, -1e300)
    for t in range(rows_b7.shape[0]):
        m = max(m, rows_b7[t, 0])
        for d in range(3):
            lo[d] = min(lo[d], rows_b7[t, 1 + d])
            hi[d] = max(hi[d], rows_b7[t, 4 + d])
    h2 = 0.0
    for d in range(3):
        h2 += 0.25 * (hi[d] - lo[d]) ** 2
    if m == np.inf:
        h2 = np.inf
    return m, h2


@njit(cache=True, parallel=True)
def kick_drift_gather(p_nc, f_nc, x_nc, invm_n, h, dt, row_n, offs_nc, ref_nc, xs_nc, vs_nc, bstat_b9):
    """The first half of a velocity-Verlet step fused with the pair loop's gathers.

    For particle i, of sorted row k = row_n[i]: ``p[i] += h f[i]``, ``x[i] += dt p[i]/m[i]``,
    then ``xs[k] = x[i] + offs[i]`` (as :func:`gather_positions`) and, when
    ``vs_nc`` has rows, ``vs[k] = p[i]/m[i]`` (as :func:`gather_velocities`).  The
    arithmetic per particle is that of the separate kick, drift and gathers, so
    the results are the same bit for bit.  Returns (max v^2, its particle,
    ``max |x - ref|^2``, squared half-diagonal of the displacements' bounding box):
    the speed check and the list's rebuild test (:meth:`NeighborList.update`
    with ``displacement=``) without another pass.  Maxima are over fixed blocks
    in block order (independent of the thread count); a NaN speed or
    displacement comes back as the maximum (inf for the displacement).

    The pass runs in the caller's order, so that the particles' arrays (momenta, forces,
    positions, masses, reference positions, offsets) stream and only the sorted rows are
    written at scattered places: about 6% off the 128k slab's step against the same pass in row
    order (docs/performance.md, stop 25).
    """
    n = row_n.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    damp = vs_nc.shape[0] > 0
    for b in prange(nb):
        m = -1.0
        kk = -1
        acc = _disp_start()
        for i in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            k = np.uint64(row_n[i])
            p_nc[i, 0] += h * f_nc[i, 0]
            p_nc[i, 1] += h * f_nc[i, 1]
            p_nc[i, 2] += h * f_nc[i, 2]
            w = invm_n[i]
            vx = p_nc[i, 0] * w
            vy = p_nc[i, 1] * w
            vz = p_nc[i, 2] * w
            x = x_nc[i, 0] + dt * vx
            y = x_nc[i, 1] + dt * vy
            z = x_nc[i, 2] + dt * vz
            x_nc[i, 0] = x
            x_nc[i, 1] = y
            x_nc[i, 2] = z
            xs_nc[k, 0] = x + offs_nc[i, 0]
            xs_nc[k, 1] = y + offs_nc[i, 1]
            xs_nc[k, 2] = z + offs_nc[i, 2]
            if damp:
                vs_nc[k, 0] = vx
                vs_nc[k, 1] = vy
                vs_nc[k, 2] = vz
            m, kk = max_take(m, kk, vx * vx + vy * vy + vz * vz, i)
            acc = _disp_add(acc, x - ref_nc[i, 0], y - ref_nc[i, 1], z - ref_nc[i, 2])
        bstat_b9[b, 0] = m
        bstat_b9[b, 1] = kk
        for c in range(7):
            bstat_b9[b, 2 + c] = acc[c]
    if n == 0:
        return 0.0, -1, 0.0, 0.0
    m, kk = blocks_max(bstat_b9[:, 0], bstat_b9[:, 1])
    md, h2 = _disp_result(bstat_b9[:, 2:])
    return m, int(kk), md, h2


@njit(cache=True, parallel=True)
def _displacement(pos_nc, ref_nc, out2):
    """(max |d|^2, squared half-diagonal of the bounding box of the displacements d).

    Every pair's separation changed by at most 2 min(max|d|, max|d - c|) for any
    vector c; the bounding-box centre gives max|d - c| <= half-diagonal.  A
    block moving as a whole (material behind a shock front) therefore costs no
    rebuilds of its own.
    """
    n = pos_nc.shape[0]
    nt = out2.shape[0]
    for t in prange(nt):
        acc = _disp_start()
        for i in range(t * n // nt, (t + 1) * n // nt):
            acc = _disp_add(acc, pos_nc[i, 0] - ref_nc[i, 0], pos_nc[i, 1] - ref_nc[i, 1],
                            pos_nc[i, 2] - ref_nc[i, 2])
        for c in range(7):
            out2[t, c] = acc[c]
    return _disp_result(out2)


# -- the local rebuild test: bricks -----------------------------------------------------------------

#: most occupied bricks of the local rebuild test: this many, or one per
#: :data:`PARTICLES_PER_BRICK` particles if more (bricks double in size until they fit)
MAX_BRICKS = 512
PARTICLES_PER_BRICK = 16
#: smallest side of a brick, in cut-offs (cutoff + skin)
BRICK_SIDE = 8.0
#: widest neighbourhood of bricks (cubes each way) the local test walks; farther reach rebuilds
MAX_BRICK_REACH = 3


def _brick_chunks():
    """Particle chunks of the brick passes: one per thread.  Their results are minima and maxima,
    exact in any grouping, so they do not depend on the thread count."""
    return max(1, min(64, int(numba.config.NUMBA_NUM_THREADS)))


@njit(cache=True, parallel=True)
def _brick_keys(pos_nc, box_c, periodic_c, lo_c, csz_c, nb_c, key_n):
    """Key of the cube (sides ``csz_c``, over the box along periodic axes, from ``lo_c`` along
    open ones) of every particle."""
    for i in prange(pos_nc.shape[0]):
        key = 0
        for d in range(3):
            w = _wrap1(pos_nc[i, d], box_c[d], periodic_c[d])
            k = min(max(int(math.floor((w - lo_c[d]) / csz_c[d])), 0), nb_c[d] - 1)
            key = key * nb_c[d] + k
        key_n[i] = key


@njit(cache=True)
def _number_bricks(key_n, maxb, brick_n, bkey_b):
    """Each particle's brick, numbered in order of first appearance, into ``brick_n``, and each
    brick's key into ``bkey_b``; returns the number of bricks, or -1 beyond ``maxb``.  A particle
    in its predecessor's brick (most, in a sample built lattice by lattice) skips the hash table."""
    n = key_n.shape[0]
    h = 4
    while h < 4 * maxb:
        h *= 2
    hkey = np.full(h, -1, np.int64)
    hval = np.empty(h, np.int64)
    m = 0
    last = -1
    lastb = 0
    for i in range(n):
        key = key_n[i]
        if key == last:
            brick_n[i] = lastb
            continue
        s = int((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)) & (h - 1)   # Fibonacci hashing
        while hkey[s] != -1 and hkey[s] != key:
            s = (s + 1) & (h - 1)
        if hkey[s] == -1:
            if m == maxb:
                return -1
            hkey[s] = key
            hval[s] = m
            bkey_b[m] = key
            m += 1
        last = key
        lastb = hval[s]
        brick_n[i] = lastb
    return m


@njit(inline="always")
def _minmax_clear(acc_tb6, t):
    """Empty the bounds of chunk t (min in columns 0-2, max in 3-5) for every brick."""
    for b in range(acc_tb6.shape[1]):
        for d in range(3):
            acc_tb6[t, b, d] = np.inf
            acc_tb6[t, b, 3 + d] = -np.inf


@njit(inline="always")
def _minmax_take(acc_tb6, t, b, d, x):
    acc_tb6[t, b, d] = min(acc_tb6[t, b, d], x)
    acc_tb6[t, b, 3 + d] = max(acc_tb6[t, b, 3 + d], x)


@njit(cache=True)
def _minmax_reduce(acc_tb6, lo_b3, hi_b3):
    """Bounds of each brick over the chunks (fixed particle chunks: the result does not depend
    on the thread count)."""
    for b in range(lo_b3.shape[0]):
        for d in range(3):
            lo = np.inf
            hi = -np.inf
            for t in range(acc_tb6.shape[0]):
                lo = min(lo, acc_tb6[t, b, d])
                hi = max(hi, acc_tb6[t, b, 3 + d])
            lo_b3[b, d] = lo
            hi_b3[b, d] = hi


@njit(cache=True, parallel=True)
def _brick_boxes(pos_nc, box_c, periodic_c, brick_n, acc_tb6, lo_b3, hi_b3):
    """Per brick, the bounding box of its particles' wrapped positions (at a build)."""
    n = pos_nc.shape[0]
    nt = acc_tb6.shape[0]
    for t in prange(nt):
        _minmax_clear(acc_tb6, t)
        for i in range(t * n // nt, (t + 1) * n // nt):
            for d in range(3):
                _minmax_take(acc_tb6, t, brick_n[i], d, _wrap1(pos_nc[i, d], box_c[d], periodic_c[d]))
    _minmax_reduce(acc_tb6, lo_b3, hi_b3)


@njit(cache=True, parallel=True)
def _brick_displacement_boxes(pos_nc, ref_nc, brick_n, acc_tb6, lo_b3, hi_b3):
    """Per brick, the bounding box of its particles' displacements ``pos - ref`` (at each local
    test: a loop of its own, with no per-element choice between the two kinds of box)."""
    n = pos_nc.shape[0]
    nt = acc_tb6.shape[0]
    for t in prange(nt):
        _minmax_clear(acc_tb6, t)
        for i in range(t * n // nt, (t + 1) * n // nt):
            for d in range(3):
                _minmax_take(acc_tb6, t, brick_n[i], d, pos_nc[i, d] - ref_nc[i, d])
    _minmax_reduce(acc_tb6, lo_b3, hi_b3)


def _assign_bricks(pos_nc, box_c, periodic_c, lo_c, csz_c, nb_c, maxb, brick_n, blo_b3, bhi_b3, bkey_b, key_n):
    """Cubes of sides ``csz_c`` over the box (open axes from ``lo_c``): each particle's brick
    (numbered in order of first appearance) into ``brick_n``, each brick's key into ``bkey_b`` and
    its bounding box of the wrapped positions into ``blo_b3[:m]``, ``bhi_b3[:m]``; returns the
    number m of occupied bricks, or -1 beyond ``maxb``.  The keys (into the scratch ``key_n``)
    and the boxes in parallel, the numbering in one thread."""
    _brick_keys(pos_nc, box_c, periodic_c, lo_c, csz_c, nb_c, key_n)
    m = _number_bricks(key_n, maxb, brick_n, bkey_b)
    if m > 0:
        _brick_boxes(pos_nc, box_c, periodic_c, brick_n, np.empty((_brick_chunks(), m, 6)), blo_b3[:m], bhi_b3[:m])
    return m


def _brick_centres(pos_nc, ref_nc, brick_n, acc_tb6, hi_b3, mid_b3):
    """Centre of the bounding box of the displacements ``pos - ref`` of each brick into ``mid_b3``
    (``hi_b3``: scratch of its shape)."""
    _brick_displacement_boxes(pos_nc, ref_nc, brick_n, acc_tb6, mid_b3, hi_b3)
    mid_b3 += hi_b3
    mid_b3 *= 0.5


@njit(cache=True, parallel=True)
def _brick_radii(pos_nc, ref_nc, brick_n, mid_b3, acc_tb2, out_b2):
    """The two largest distances of a brick's displacements from the centre of its displacement
    box (``mid_b3`` of :func:`_brick_centres`): (largest, second largest) per brick.

    A sphere about the box's centre through the farthest displacement bounds them as the box's
    half-diagonal does, but tighter (up to sqrt 3 for thermal motion, whose extremes along x, y
    and z are different particles); two particles of one brick moved apart by at most the sum
    of the two largest distances.
    """
    n = pos_nc.shape[0]
    nt = acc_tb2.shape[0]
    nb = mid_b3.shape[0]
    for t in prange(nt):
        for b in range(nb):
            acc_tb2[t, b, 0] = 0.0
            acc_tb2[t, b, 1] = 0.0
        for i in range(t * n // nt, (t + 1) * n // nt):
            b = brick_n[i]
            r2 = 0.0
            for d in range(3):
                x = pos_nc[i, d] - ref_nc[i, d] - mid_b3[b, d]
                r2 += x * x
            if r2 != r2:
                r2 = np.inf
            if r2 > acc_tb2[t, b, 0]:
                acc_tb2[t, b, 1] = acc_tb2[t, b, 0]
                acc_tb2[t, b, 0] = r2
            elif r2 > acc_tb2[t, b, 1]:
                acc_tb2[t, b, 1] = r2
    for b in range(nb):
        r1 = 0.0
        r2 = 0.0
        for t in range(nt):
            for c in range(2):
                x = acc_tb2[t, b, c]
                if x > r1:
                    r2 = r1
                    r1 = x
                elif x > r2:
                    r2 = x
        out_b2[b, 0] = math.sqrt(r1)
        out_b2[b, 1] = math.sqrt(r2)


@njit(inline="always")
def _brick_pair_safe(a, b, mid_b3, rad_b2, blo_b3, bhi_b3, box_c, periodic_c, skin, rc):
    """The test of :func:`_bricks_safe` for the bricks a and b."""
    s2 = 0.0
    c2 = 0.0
    for d in range(3):
        g = max(0.0, blo_b3[b, d] - bhi_b3[a, d], blo_b3[a, d] - bhi_b3[b, d])
        if periodic_c[d]:
            g = min(g, max(0.0, blo_b3[a, d] + box_c[d] - bhi_b3[b, d]),
                    max(0.0, blo_b3[b, d] + box_c[d] - bhi_b3[a, d]))
        s2 += g * g
        c2 += (mid_b3[a, d] - mid_b3[b, d]) ** 2
    bound = math.sqrt(c2) + rad_b2[a, 0] + rad_b2[b, 0]
    return bound <= max(skin, math.sqrt(s2) - rc)


@njit(inline="always")
def _brick_cube(o, g, k, full, n, periodic):
    """Cube index of offset o along an axis of n cubes from cube g (every cube once when
    ``full``, else g - k + o), wrapped along a periodic axis; -1 off an open axis' grid."""
    h = o if full else g - k + o
    if h < 0 or h >= n:
        if not periodic:
            return -1
        h %= n
    return h


@njit(cache=True)
def _bricks_safe(mid_b3, rad_b2, blo_b3, bhi_b3, skey_b, sid_b, nb_c, csz_c, box_c, periodic_c, skin, rc,
                 maxreach):
    """True when no pair can have come within ``rc`` unlisted: for every two bricks a, b,
    |centre_a - centre_b| + R_a + R_b (the centres of their displacement boxes and the largest
    distances from them, :func:`_brick_radii`, bound any |d_i - d_j|; within one brick the two
    largest distances) is at most max(skin, S_ab - rc), S_ab the distance between their
    position boxes at the build (a pair not listed was at least cutoff + skin and at least
    S_ab apart).

    Only bricks near each other are compared.  With E = max_a |centre_a - c| + R_a about the
    middle c of the centres, the bound of any two bricks is at most 2E, so two bricks whose
    cubes (sides ``csz_c``, ``nb_c`` a side) are more than rc + 2E apart pass unseen; the
    others are found among the bricks sorted by cube key (``skey_b``, brick ids ``sid_b``), a
    cursor per row of the neighbourhood (one brick per cube).  False (a rebuild) when that reach exceeds
    ``maxreach`` cubes along an axis."""
    nb = mid_b3.shape[0]
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for a in range(nb):
        if not rad_b2[a, 0] + rad_b2[a, 1] <= skin:
            return False
        for d in range(3):
            lo[d] = min(lo[d], mid_b3[a, d])
            hi[d] = max(hi[d], mid_b3[a, d])
    e = 0.0
    for a in range(nb):
        r2 = 0.0
        for d in range(3):
            r2 += (mid_b3[a, d] - 0.5 * (lo[d] + hi[d])) ** 2
        e = max(e, math.sqrt(r2) + rad_b2[a, 0])
    reach = rc + 2.0 * e
    kk = np.zeros(3, np.int64)
    full = np.zeros(3, np.bool_)
    span = np.zeros(3, np.int64)
    for d in range(3):
        if periodic_c[d] and nb_c[d] <= 2 * maxreach + 1 and reach >= 0.5 * (nb_c[d] - 1) * csz_c[d]:
            full[d] = True          # every cube along the axis, once
        elif not reach <= maxreach * csz_c[d]:
            return False
        else:
            kk[d] = int(reach / csz_c[d]) + 1
            full[d] = periodic_c[d] and 2 * kk[d] + 1 >= nb_c[d]
        span[d] = nb_c[d] if full[d] else 2 * kk[d] + 1
    n1 = nb_c[1]
    n2 = nb_c[2]
    cur = np.full(span[0] * span[1], -1, np.int64)
    for u in range(nb):
        key = skey_b[u]
        a = sid_b[u]
        g0 = key // (n2 * n1)
        g1 = (key // n2) % n1
        g2 = key % n2
        for o0 in range(span[0]):
            c0 = _brick_cube(o0, g0, kk[0], full[0], nb_c[0], periodic_c[0])
            if c0 < 0:
                continue
            for o1 in range(span[1]):
                c1 = _brick_cube(o1, g1, kk[1], full[1], n1, periodic_c[1])
                if c1 < 0:
                    continue
                q = -1
                prev = -1
                for o2 in range(span[2]):
                    c2 = _brick_cube(o2, g2, kk[2], full[2], n2, periodic_c[2])
                    if c2 < 0:
                        continue
                    target = (c0 * n1 + c1) * n2 + c2
                    if q < 0 or target < prev:          # a row's first cube, or past a periodic face
                        q = _lower(skey_b, target, cur, o0 * span[1] + o1)
                    else:                               # the next cube along the row: walk on
                        while q < nb and skey_b[q] < target:
                            q += 1
                    prev = target
                    if q < nb and skey_b[q] == target:
                        b = sid_b[q]
                        if b > a and not _brick_pair_safe(a, b, mid_b3, rad_b2, blo_b3, bhi_b3, box_c,
                                                          periodic_c, skin, rc):
                            return False
    return True


@njit(cache=True)
def _compact_rows(keep_n, perm_n, row_n, first_n, pool_p, jmask, xs_nc, offs_nc, ref_nc, brick_n, rmap_r):
    """Drop the particles where ``keep_n`` is False from a sorted list, in place (see
    :meth:`NeighborList.remove`): the kept rows keep their order, the pairs of a dropped row
    or partner go, the kept partners are renumbered; the caller-order arrays (``offs_nc``,
    ``ref_nc``, ``brick_n`` when it has rows) keep the kept particles' order.  ``rmap_r``:
    scratch of n int64 (new row of each old row, -1 dropped).  Every write goes to an index at
    or before the one read, so one forward pass needs no copy.  Returns (rows, pairs) kept."""
    n = keep_n.shape[0]
    c = 0
    for r in range(n):
        if keep_n[perm_n[r]]:
            rmap_r[r] = c
            c += 1
        else:
            rmap_r[r] = -1
    m = c
    notmask = ~jmask
    w = 0
    lo = first_n[0]
    for r in range(n):
        hi = first_n[r + 1]
        k = rmap_r[r]
        if k >= 0:
            first_n[k] = w
            for p in range(lo, hi):
                v = pool_p[p]
                kj = rmap_r[v & jmask]
                if kj >= 0:
                    pool_p[w] = (v & notmask) | np.uint32(kj)
                    w += 1
            for d in range(3):
                xs_nc[k, d] = xs_nc[r, d]
        lo = hi
    first_n[m] = w
    bricks = brick_n.shape[0] == n
    c = 0
    for i in range(n):
        if keep_n[i]:
            row_n[c] = rmap_r[row_n[i]]
            for d in range(3):
                offs_nc[c, d] = offs_nc[i, d]
                ref_nc[c, d] = ref_nc[i, d]
            if bricks:
                brick_n[c] = brick_n[i]
            c += 1
    for c in range(m):
        perm_n[row_n[c]] = c
    return m, w


@njit(cache=True)
def _renumber_bricks(brick_n, nb):
    """Occupied bricks of ``brick_n`` renumbered in their order, in place; returns the new
    number of each old brick (-1: emptied)."""
    newb = np.zeros(nb, np.int64)
    for i in range(brick_n.shape[0]):
        newb[brick_n[i]] = 1
    c = 0
    for b in range(nb):
        if newb[b]:
            newb[b] = c
            c += 1
        else:
            newb[b] = -1
    for i in range(brick_n.shape[0]):
        brick_n[i] = newb[brick_n[i]]
    return newb


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


#: the forward half of the 3x3x3 cell stencil (own cell and the 13 cells after it in slot
#: order) as runs along the fastest slot: (d0, d1, first d2, last d2); the first run starts
#: at the own cell (partners j > i there)
HALF_RUNS = np.array([[0, 0, 0, 1], [0, 1, -1, 1], [1, -1, -1, 1], [1, 0, -1, 1], [1, 1, -1, 1]],
                     dtype=np.int64)


class NeighborList:
    """Verlet list with skin, built on a cell list (numba).

    Parameters
    ----------
    cutoff : float
        Interaction cutoff, Angstrom (largest over pair types).
    skin : float, default 0
        Extra radius; the list stays valid while no pair separation can have
        changed by more than ``skin``.
    half : bool, default True
        Store each unordered pair once (``True``) or both directions.
    sort : bool, default False
        Hold the particles in cell order (:attr:`perm_n`): the list, the wrap
        offsets and the kernels' positions are over sorted rows, so a pair
        loop reads memory nearly in sequence.  The Atoms are never reordered;
        :meth:`pairs` and :attr:`offset_nc` answer in the caller's order.  A
        sorted half list on a grid with >= 3 cells along every periodic axis is
        built in one pass over the own cell and 13 forward cells, its pairs
        packed as ``j | image code << shift`` (:attr:`jp_p`).
    centered : bool, default False
        Rebuild test.  False: when a particle moved more than ``skin/2`` since
        the last build.  True: when both that and the half-diagonal of the
        bounding box of all displacements exceed ``skin/2`` (any common
        translation is subtracted, so a block moving as a whole, e.g. the
        material behind a shock front, triggers no rebuild of its own).  Both
        are rigorous: no pair closer than the cutoff is ever missing.
    cells : {"auto", "dense", "sparse"}
        Cell structure of a sorted list.  "dense": an array over every cell of
        the bounding box; "sparse": only the occupied cells, sorted by key
        (radix sort), their neighbours found by a forward walk over them, so
        memory and time are O(N) however far the particles spread.  "auto"
        (default): dense while the bounding box has at most
        :data:`DENSE_CELLS_PER_PARTICLE` cells per particle, else sparse.  Both
        give the same list in the same order.

    Attributes
    ----------
    first_n : (N+1,) int64
        CSR offsets (see module docstring); over sorted rows when ``sort``.
    j_p : (P,) int32, img_p : (P,) int16
        Partner and image code of each pair (decoded from :attr:`jp_p` for sorted lists).
    jp_p : (P,) uint32 or None
        Sorted lists: ``j | img << img_shift`` (the form the kernels read).
    img_shift : int
        Bit position of the image code in :attr:`jp_p` (27 for the half-stencil list).
    perm_n : (N,) int64 or None
        With ``sort``: sorted row k is particle ``perm_n[k]``.
    row_n : (N,) int64 or None
        With ``sort``: the inverse, particle i is sorted row ``row_n[i]``.
    offs_nc : (N, 3) float64
        Wrap offsets of the particles at the last build (caller's order; the array
        behind :attr:`offset_nc`; with ``sort`` a buffer kept across builds).
    xs_nc : (N, 3) float64
        With ``sort``: a buffer of sorted positions (wrapped positions at the
        build; the Cluster Dynamics calculator gathers each step's into it).
    offset_nc : (N, 3) float64
        Wrap of each particle into the box at the last build (caller's order).
    image_sc : (S, 3) float64
        Cartesian lattice translations indexed by the image codes.
    nbuilds : int
        Number of builds so far.
    version : int
        Builds and compactions (:meth:`remove`) so far: the list's arrays change with it.
    nremovals : int
        Compactions so far.
    layer_rows : int
        With ``sort``: the most rows in one layer of cells across the slowest
        cell axis at the last build (rows beyond it, a layer on, are the
        farthest a row's partners sit in a half list); 0 otherwise.
    last_cells : str
        "dense", "sparse" or "coarse" (the unsorted or full-stencil search on a
        grid coarsened to at most :data:`MAX_CELLS_PER_PARTICLE` cells per particle).
    """

    def __init__(self, cutoff, skin=0.0, half=True, sort=False, centered=False, cells="auto"):
        if not (float(cutoff) > 0):
            raise InputError("cutoff", cutoff, "a positive distance")
        if not (float(skin) >= 0):
            raise InputError("skin", skin, "a distance >= 0")
        if cells not in ("auto", "dense", "sparse"):
            raise InputError("cells", cells, "'auto', 'dense' or 'sparse'")
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.half = bool(half)
        self.sort = bool(sort)
        self.centered = bool(centered)
        self.cells = cells
        self.nbuilds = 0
        self.version = 0                # builds and compactions (remove)
        self.nremovals = 0
        self.compacted = False          # removals since the last build (see remove)
        self.ref_nc = None
        self._ref_store = None          # buffers behind ref_nc and the sorted rows' arrays (grow only)
        self._store = None
        self._key_store = None
        self.perm_n = None
        self.row_n = None
        self.layer_rows = 0
        self.jp_p = None
        self.img_shift = 0
        self.xs_nc = None
        self.offs_nc = None
        self.last_cells = None
        self._j_p = None
        self._img_p = None
        self._key = None
        self._pool = np.empty(0, np.uint32)
        self._slab_need = None
        self._slab_rows = None
        self._ppr = (8.0, 8.0)          # pairs per row at the last build: mean, largest of a block
        self._bricks = None             # the local rebuild test (centered lists): see _set_bricks
        self._brick_store = None
        self._brick_side = 0.0
        self.nlocal = 0                 # rebuilds the local test saved
        self._disp = np.zeros((DISP_BLOCKS, 7))

    def update(self, positions, cell, pbc, displacement=None):
        """Rebuild if needed; return True when rebuilt.

        ``displacement``: (``max |x - ref|^2``, squared half-diagonal) of the
        current positions against :attr:`ref_nc`, when the caller already has
        them (:func:`kick_drift_gather`); saves the check's own pass.
        """
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        cell = np.asarray(cell, dtype=float).reshape(3, 3)
        pbc = np.asarray(pbc, dtype=bool)
        if pbc.shape != (3,):
            pbc = np.broadcast_to(pbc, (3,))
        use_threads(pos.shape[0])
        key = _box_key(cell, pbc)
        if (self.ref_nc is None or self.ref_nc.shape != pos.shape or key != self._key
                or (pos.shape[0] and self._moved(pos, displacement))):
            self.build(pos, cell, pbc)
            return True
        return False

    def _moved(self, pos, displacement=None):
        lim = (0.5 * self.skin) ** 2
        if displacement is not None:
            m, h2 = displacement
            if not self.centered:
                return not m <= lim
        elif not self.centered:
            m = _max_disp2(pos, self.ref_nc)
            return not m <= lim
        else:
            m, h2 = _displacement(pos, self.ref_nc, self._disp)
        if m <= lim or h2 <= lim:
            return False
        if self._bricks is not None and math.isfinite(m) and math.isfinite(h2):
            brick_n, blo, bhi, box, periodic_c, acc, mid, hi, acc2, rad, skey, sid, nb_c, csz = self._bricks
            _brick_centres(pos, self.ref_nc, brick_n, acc, hi, mid)
            _brick_radii(pos, self.ref_nc, brick_n, mid, acc2, rad)
            if _bricks_safe(mid, rad, blo, bhi, skey, sid, nb_c, csz, box, periodic_c, self.skin, self.cutoff,
                            MAX_BRICK_REACH):
                self.nlocal += 1
                return False
        return True

    def _grid(self, pos, cell, pbc):
        """Cells of side >= cutoff + skin over the box (periodic axes) and the bounding box (open
        ones): (lo, cell sizes, cell counts, stencil reach, periodic flags, periodic box, rcut)."""
        box_c, periodic_c = check_cell(cell, pbc)
        n = pos.shape[0]
        if not np.all(np.isfinite(pos)):
            bad = np.nonzero(~np.isfinite(pos).all(axis=1))[0]
            raise InputError("positions", f"non-finite at particles {bad[:5].tolist()}", "finite values")
        rcut = self.cutoff + self.skin
        lo = np.zeros(3)
        ext = np.zeros(3)
        for d in range(3):
            if periodic_c[d]:
                ext[d] = box_c[d]
            elif n:
                lo[d] = pos[:, d].min()
                ext[d] = pos[:, d].max() - lo[d]
        ncell = np.ones(3, np.int64)
        for d in range(3):
            ncell[d] = max(1, int(min(math.floor(ext[d] / rcut), 2 ** 62))) if ext[d] > 0 else 1
        return lo, ext, ncell, periodic_c, np.where(periodic_c, box_c, 0.0), rcut

    @staticmethod
    def _sizes(ext, ncell, periodic_c, rcut):
        """Cell sizes and stencil reach for the cell counts ``ncell``."""
        cs = np.ones(3)
        krange = np.ones(3, np.int64)
        for d in range(3):
            cs[d] = ext[d] / ncell[d] if ext[d] > 0 else rcut
            if not periodic_c[d]:
                cs[d] = max(cs[d], rcut)
            krange[d] = max(1, int(math.ceil(rcut / cs[d] - 1e-12)))
            if not periodic_c[d]:
                krange[d] = 1
        return cs, krange

    @staticmethod
    def _coarsen(ncell, limit):
        """Halve the largest cell count until the grid has at most ``limit`` cells (dilute,
        exploding samples on the dense and unsorted paths)."""
        ncell = ncell.copy()
        while float(np.prod(ncell.astype(float))) > limit:
            big = np.argmax(ncell)
            ncell[big] = max(1, ncell[big] // 2)
        return ncell

    def build(self, positions, cell, pbc):
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        geo = self._grid(pos, cell, pbc)
        if pos.shape[0] >= 2 ** 31:
            raise InputError("positions", f"{pos.shape[0]} particles", "fewer than 2**31 per list")
        if self.sort:
            self._build_sorted(pos, *geo)
        else:
            self._build_unsorted(pos, *geo)
        if self.centered:
            self._set_bricks(pos, geo)
        self._ref_store = grown(self._ref_store, pos.shape[0])
        self.ref_nc = self._ref_store[:pos.shape[0]]
        np.copyto(self.ref_nc, pos)
        self._key = _box_key(cell, pbc)
        self.nbuilds += 1
        self.version += 1
        self.compacted = False

    def _set_bricks(self, pos, geo):
        """The local rebuild test's bricks: cubes of at least :data:`BRICK_SIDE` (cutoff + skin)
        (along a periodic axis the box divided evenly), doubled until at most
        max(:data:`MAX_BRICKS`, N / :data:`PARTICLES_PER_BRICK`) are occupied.

        The global test (:meth:`_moved`) bounds every pair's change by the spread of all
        displacements; when it fails, the bricks bound it pair of bricks by pair of bricks,
        using how far apart the bricks were at the build (:func:`_bricks_safe`): an expanding
        cloud whose neighbourhoods move together keeps its list.  Brick of each particle: 4
        bytes; each brick about 100 bytes and 64 per thread.
        """
        lo, ext, ncell, periodic_c, box, rcut = geo
        n = pos.shape[0]
        self._bricks = None
        if n < 2:
            return
        side = BRICK_SIDE * rcut   # from the positions alone: a restart rebuilds the same bricks
        boxw = np.where(periodic_c, box, 1.0)
        maxb = max(MAX_BRICKS, n // PARTICLES_PER_BRICK)
        st = self._brick_store or (None,) * 4
        st = (grown(st[0], n, (), np.int32), grown(st[1], maxb), grown(st[2], maxb), grown(st[3], maxb, (), np.int64))
        self._brick_store = st
        brick_n, blo, bhi, bkey = st[0][:n], st[1], st[2], st[3]
        while True:
            nb_c = np.ones(3, np.int64)
            csz = np.empty(3)
            for d in range(3):
                if periodic_c[d]:
                    nb_c[d] = max(1, int(min(math.floor(box[d] / side), 2 ** 20)))
                    csz[d] = box[d] / nb_c[d]
                else:
                    nb_c[d] = max(1, int(min(math.floor(ext[d] / side), 2 ** 20)) + 1)
                    csz[d] = side
            if float(np.prod(nb_c.astype(float))) < 2.0 ** 62:
                m = _assign_bricks(pos, boxw, periodic_c, lo, csz, nb_c, maxb, brick_n, blo, bhi, bkey,
                                   self._keys(n))
                if m > 0:
                    break
            side *= 2.0
        self._brick_side = side
        if m < 2:
            return
        order = np.argsort(bkey[:m], kind="stable")
        nt = _brick_chunks()
        self._bricks = (brick_n, blo[:m], bhi[:m], box.astype(float), periodic_c,
                        np.empty((nt, m, 6)), np.empty((m, 3)), np.empty((m, 3)), np.empty((nt, m, 2)),
                        np.empty((m, 2)), bkey[:m][order], order.astype(np.int64), nb_c, csz)

    def _reserve_pool(self, size):
        """A pair pool of at least ``size`` entries (a build rewrites all of it).  When it must grow,
        the old pool and the list's view of it are let go first, so the two are never held together
        (they would add about 35 bytes a particle to the peak), and it grows by an eighth more than
        asked, so that a slowly densifying sample does not reallocate at every build."""
        if self._pool.shape[0] >= size:
            return
        self.jp_p = None
        self._pool = np.empty(0, np.uint32)
        self._pool = np.empty(size + size // 8, np.uint32)

    def _image_table(self, krange, box):
        kx, ky, kz = krange
        ii = np.arange(-kx, kx + 1)
        jj = np.arange(-ky, ky + 1)
        ll = np.arange(-kz, kz + 1)
        img = np.array(np.meshgrid(ii, jj, ll, indexing="ij")).reshape(3, -1).T
        return np.ascontiguousarray(img * box[None, :])

    def _count_and_fill(self, xs, cell_n, start, order, ncell, krange, periodic_c, box, rcut, first_n):
        """The full-stencil search in two passes: count each row's pairs into ``first_n`` (zeroed,
        (n + 1,)), turn the counts into row offsets, then fill the partner rows and image codes.

        Returns (j_p (P,) int32, img_p (P,) int16)."""
        _search(xs, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, True, first_n, np.empty(0, np.int32), np.empty(0, np.int16))
        np.cumsum(first_n, out=first_n)
        npairs = int(first_n[-1])
        j_p = np.empty(npairs, np.int32)
        img_p = np.empty(npairs, np.int16)
        _search(xs, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, False, first_n, j_p, img_p)
        return j_p, img_p

    def _build_unsorted(self, pos, lo, ext, ncell, periodic_c, box, rcut):
        n = pos.shape[0]
        ncell = self._coarsen(ncell, MAX_CELLS_PER_PARTICLE * max(n, 1) + 27)
        cs, krange = self._sizes(ext, ncell, periodic_c, rcut)
        wpos = np.empty_like(pos)
        _wrap(pos, np.where(periodic_c, box, 1.0), periodic_c, wpos)
        cell_n, start, order = _bin_particles(wpos, lo, 1.0 / cs, ncell)
        first_n = np.zeros(n + 1, np.int64)
        j_p, img_p = self._count_and_fill(wpos, cell_n, start, order, ncell, krange, periodic_c, box, rcut,
                                          first_n)
        self.image_sc = self._image_table(krange, box)
        self.first_n, self._j_p, self._img_p = first_n, j_p, img_p
        self.jp_p = None
        self.perm_n = None
        self.row_n = None
        self.layer_rows = 0
        self.offs_nc = wpos - pos
        self.last_cells = "coarse"

    def _keys(self, n):
        """Scratch of n int64 (the cell and brick keys of a build), kept across builds (grows only):
        allocating it per build fragments the heap (about 80 bytes per particle held after a few
        hundred builds)."""
        self._key_store = grown(self._key_store, n, (), np.int64)
        return self._key_store[:n]

    def _sorted_buffers(self, n):
        """The sorted rows' arrays for n particles: views of buffers kept across builds, which
        grow but never shrink, so that removing particles allocates nothing (every build writes
        every row of them)."""
        xs, offs, perm, first, row = self._store or (None,) * 5
        self._store = (grown(xs, n), grown(offs, n), grown(perm, n, (), np.int64), grown(first, n + 1, (), np.int64),
                       grown(row, n, (), np.int64))
        xs, offs, perm, first, row = self._store
        self.xs_nc, self.offs_nc, self.perm_n, self.first_n = xs[:n], offs[:n], perm[:n], first[:n + 1]
        self.row_n = row[:n]
        return self.perm_n, self.xs_nc, self.offs_nc, self.row_n

    def _build_sorted(self, pos, lo, ext, ncell, periodic_c, box, rcut):
        n = pos.shape[0]
        perm, xs, offs, row = self._sorted_buffers(n)
        boxw = np.where(periodic_c, box, 1.0)
        fast = self.half and all(ncell[d] >= 3 for d in range(3) if periodic_c[d])
        if fast:
            # keys of (k0 n1 + k1) n2 + k2 must fit in int64: for spreads beyond 2^62 cells the widest
            # axes get wider cells (a bounded key space, not a bounded memory: sparse memory is O(N))
            ncell = self._coarsen(ncell, 2.0 ** 62)
        cs, krange = self._sizes(ext, ncell, periodic_c, rcut)
        fast = fast and bool(np.all(krange == 1))
        # slowest-varying cell axis: the one with most cells (thinnest layers, so a
        # contiguous block of rows touches few rows outside itself)
        axes = np.array(sorted(range(3), key=lambda d: (-ncell[d], d)), np.int64)
        if not fast:
            self._build_sorted_search(pos, lo, ext, ncell, periodic_c, box, rcut, axes)
            return
        dense_cells = float(np.prod(ncell.astype(float)))
        sparse = (self.cells == "sparse"
                  or (self.cells == "auto" and dense_cells > DENSE_CELLS_PER_PARTICLE * max(n, 1) + 27))
        ukey, ustart, dstart = _sort_rows(pos, boxw, periodic_c, lo, 1.0 / cs, ncell, axes, perm, xs, offs, row,
                                          self._keys(n), sparse)
        if n >= 2 ** HALF_SHIFT:
            raise InputError("positions", f"{n} particles", f"fewer than 2**{HALF_SHIFT} in a sorted half list")
        nslot = ncell[axes]
        self.layer_rows = int(_layer_rows(ukey, ustart, nslot[1] * nslot[2]))
        periodic_s = periodic_c[axes].copy()
        slotbox = np.zeros((3, 3))
        for q, d in enumerate(axes):
            slotbox[q, d] = box[d]
        slotmult = np.array([9, 3, 1], np.int64)[axes]
        cblk, rows_b, maxrows = _cell_blocks(ustart, FILL_BLOCK_ROWS)
        need = self._slab_need
        first_n = self.first_n
        nblk = rows_b.shape[0]
        mean, top = self._ppr
        if need is not None and need.shape[0] == nblk:
            est = np.maximum((need * SLAB_MARGIN).astype(np.int64), (rows_b * mean).astype(np.int64))
        elif need is not None:
            est = _carried_need(need, self._slab_rows, rows_b, mean)
        else:
            est = (rows_b * (top * 1.1)).astype(np.int64)
        est += 64
        while True:
            slab = np.zeros(nblk + 1, np.int64)
            np.cumsum(est, out=slab[1:])
            self._reserve_pool(int(slab[-1]))
            need_b = np.empty(nblk, np.int64)
            _fill_slabs(xs, ukey, ustart, dstart, sparse, nslot, periodic_s, HALF_RUNS, slotbox, slotmult,
                        rcut * rcut, HALF_SHIFT, cblk, slab, maxrows, self._pool, first_n, need_b)
            if np.any(need_b > est):
                est = np.maximum(est, (need_b * SLAB_MARGIN).astype(np.int64) + 64)
            else:
                break
        self._slab_need = need_b
        self._slab_rows = rows_b
        self._ppr = (float(need_b.sum() / max(n, 1)), float((need_b / np.maximum(rows_b, 1)).max()))
        npairs = _close_slabs(self._pool, slab, need_b, first_n)
        self.jp_p = self._pool[:npairs]
        self.img_shift = HALF_SHIFT
        self._j_p = self._img_p = None
        self.image_sc = self._image_table(np.ones(3, np.int64), box)
        self.last_cells = "sparse" if sparse else "dense"

    def _build_sorted_search(self, pos, lo, ext, ncell, periodic_c, box, rcut, axes):
        """Sorted list by the full-stencil search (thin periodic boxes, full lists)."""
        n = pos.shape[0]
        perm, xs, offs, row = self._sorted_buffers(n)
        boxw = np.where(periodic_c, box, 1.0)
        ncell = self._coarsen(ncell, MAX_CELLS_PER_PARTICLE * max(n, 1) + 27)
        cs, krange = self._sizes(ext, ncell, periodic_c, rcut)
        axes = np.array(sorted(range(3), key=lambda d: (-ncell[d], d)), np.int64)
        ukey, ustart, _ = _sort_rows(pos, boxw, periodic_c, lo, 1.0 / cs, ncell, axes, perm, xs, offs, row,
                                     self._keys(n), False)
        self.layer_rows = int(_layer_rows(ukey, ustart, ncell[axes[1]] * ncell[axes[2]]))
        first_n = self.first_n
        first_n[:] = 0
        # _search decodes cells with x slowest: re-bin the sorted rows that way
        cell_x, start_x, order_x = _bin_particles(xs, lo, 1.0 / cs, ncell)
        j_p, img_p = self._count_and_fill(xs, cell_x, start_x, order_x, ncell, krange, periodic_c, box, rcut,
                                          first_n)
        npairs = j_p.shape[0]
        self.image_sc = self._image_table(krange, box)
        nimg = self.image_sc.shape[0]
        shift = 32 - max(1, int(nimg - 1).bit_length())
        if n > 2 ** shift:
            raise InputError("positions", f"{n} particles", f"at most 2**{shift} with {nimg} periodic images "
                             "(a box thinner than two cut-offs along a periodic axis)")
        self._reserve_pool(npairs)
        _pack(j_p, img_p, shift, self._pool)
        self.jp_p = self._pool[:npairs]
        self.img_shift = shift
        self._j_p, self._img_p = j_p, img_p
        self.last_cells = "coarse"

    @property
    def j_p(self):
        """(P,) int32 partner rows of the pairs."""
        if self._j_p is None and self.jp_p is not None:
            self._j_p = (self.jp_p & np.uint32((1 << self.img_shift) - 1)).astype(np.int32)
        return self._j_p

    @property
    def img_p(self):
        """(P,) int16 image codes of the pairs (rows of :attr:`image_sc`)."""
        if self._img_p is None and self.jp_p is not None:
            self._img_p = (self.jp_p >> np.uint32(self.img_shift)).astype(np.int16)
        return self._img_p

    @property
    def j_mask(self):
        """Mask of the partner row in :attr:`jp_p`."""
        return np.uint32((1 << self.img_shift) - 1)

    @property
    def offset_nc(self):
        """Wrap offsets at the last build, in the caller's particle order (a copy: a sorted
        list's buffer is rewritten by the next build)."""
        return self.offs_nc.copy()

    def renumber(self, scratch):
        """The caller has reordered its particles into the list's row order (new particle k is
        old particle ``perm_n[k]``).  The list stays valid without a rebuild: its rows, pairs and
        sorted arrays are untouched; the reference positions, the wrap offsets and the bricks of
        the local test follow, and the row permutation and its inverse become the identity.  ``scratch``: a
        :func:`clusterdyn.buffers.grown` buffer for :func:`clusterdyn.buffers.permute`."""
        if self.ref_nc is None or self.perm_n is None or self.ref_nc.shape[0] != self.perm_n.shape[0]:
            raise InputError("renumber", "a list not built over the current particles", "a built, sorted list")
        permute(self.ref_nc, self.perm_n, scratch)
        permute(self.offs_nc, self.perm_n, scratch)
        if self._bricks is not None:
            permute(self._bricks[0], self.perm_n, scratch)
        _identity(self.perm_n)
        _identity(self.row_n)

    @property
    def in_order(self):
        """True when the rows are in the caller's order (the permutation is the identity): after
        :meth:`renumber`, after a build that found them so, and through compactions of either.
        Read from the permutation (one pass, stopping at the first row out of place)."""
        return self.perm_n is not None and bool(_is_identity(self.perm_n))

    def remove(self, keep_n):
        """The caller drops the particles where ``keep_n`` is False (the others keeping their
        order, as ``atoms[keep_n]`` does).  A sorted list built over the current particles stays
        valid without a rebuild: the dropped rows and every pair with a dropped partner go, the
        kept rows keep their order and their pairs (:func:`_compact_rows`, one pass, in place:
        nothing of N's size is allocated); the reference positions, wrap offsets and the local
        test's bricks follow (emptied bricks are dropped, the others' build boxes are taken
        again over the particles kept).  Returns False, changing nothing, for a list that can
        not be compacted (unsorted, or not built over these particles): the caller rebuilds.
        :attr:`version` counts builds and compactions (what users of the list's arrays key on);
        rows in the caller's order (:attr:`in_order`) stay so.

        The compacted list holds the pairs a build from the kept reference positions would
        hold, but its rows are in the old build's order (a build sorts them over the kept
        particles' own bounding box), so pair sums add in another order: :attr:`compacted`
        says so until the next build (a checkpoint rebuilds from the reference positions
        first, as its restart does)."""
        keep = np.asarray(keep_n)
        if (self.perm_n is None or self.ref_nc is None or keep.dtype != np.bool_ or keep.ndim != 1
                or self.ref_nc.shape[0] != keep.shape[0] or self.perm_n.shape[0] != keep.shape[0]):
            return False
        n = keep.shape[0]
        br = self._bricks
        brick_n = br[0] if br is not None else np.zeros(0, np.int32)
        m, npairs = _compact_rows(keep, self.perm_n, self.row_n, self.first_n, self._pool, self.j_mask,
                                  self.xs_nc, self.offs_nc, self.ref_nc, brick_n, self._keys(n))
        self._sorted_buffers(m)
        self.ref_nc = self._ref_store[:m]
        self.jp_p = self._pool[:npairs]
        self._j_p = self._img_p = None
        self.layer_rows = max(1, self.layer_rows * m // max(n, 1)) if self.layer_rows else 0
        if br is not None:
            self._drop_bricks(m)
        self.version += 1
        self.nremovals += 1
        self.compacted = True
        return True

    def _drop_bricks(self, m):
        """The local test's bricks over the ``m`` particles kept by :meth:`remove`."""
        brick_n, blo, bhi, box, periodic_c, *_, skey, sid, nb_c, csz = self._bricks
        brick_n = self._brick_store[0][:m]
        newb = _renumber_bricks(brick_n, blo.shape[0])
        mb = int(newb.max()) + 1 if newb.size else 0
        if mb < 2:
            self._bricks = None
            return
        nt = _brick_chunks()
        blo, bhi = self._brick_store[1][:mb], self._brick_store[2][:mb]
        _brick_boxes(self.ref_nc, np.where(periodic_c, box, 1.0), periodic_c, brick_n, np.empty((nt, mb, 6)),
                     blo, bhi)
        u = newb[sid] >= 0
        self._bricks = (brick_n, blo, bhi, box, periodic_c, np.empty((nt, mb, 6)), np.empty((mb, 3)),
                        np.empty((mb, 3)), np.empty((nt, mb, 2)), np.empty((mb, 2)), skey[u].copy(),
                        newb[sid[u]].astype(np.int64), nb_c, csz)

    def scratch(self, n):
        """A scratch of ``n`` rows of :data:`~clusterdyn.buffers.PERMUTE_WORDS` float64 words for
        :func:`clusterdyn.buffers.permute` (and :meth:`renumber`) between builds: the builds' key
        scratch, whose contents matter only inside a build, so a caller's sort of its particles
        holds no memory of its own.  Valid until the next build."""
        return self._keys(n * PERMUTE_WORDS).view(np.float64).reshape(n, PERMUTE_WORDS)

    @property
    def npairs(self):
        return int(self.first_n[-1])

    def memory_bytes(self):
        """Bytes of the arrays the list keeps between builds (list, permutation, buffers)."""
        arrs = [self._ref_store, self._pool, self._j_p, self._img_p, self._disp]
        arrs += list(self._store) if self._store is not None else [self.first_n, self.offs_nc]
        arrs.append(self._key_store)
        if self._bricks is not None:          # the brick store's arrays, and those made per build
            arrs += list(self._brick_store)
            arrs += [a for a in self._bricks[3:] if isinstance(a, np.ndarray)]
        return int(sum(a.nbytes for a in arrs if a is not None))

    def sorted_positions(self, positions, out=None):
        """Wrapped positions in the list's row order (sorted lists), Angstrom."""
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        if self.perm_n is None:
            return pos + self.offs_nc
        if out is None:
            out = np.empty_like(pos)
        gather_positions(pos, self.perm_n, self.offs_nc, out)
        return out

    def pairs(self, positions):
        """Python-side view: (i_p, j_p, d_pc, r_p) for the given positions (tests, analysis).

        Indices are the caller's particle rows, also for a sorted list.
        """
        pos = np.asarray(positions, dtype=float)
        i_p = np.repeat(np.arange(len(pos)), np.diff(self.first_n))
        j_p = self.j_p.astype(np.int64)
        w = self.sorted_positions(pos)
        d = w[j_p] - w[i_p] + self.image_sc[self.img_p]
        if self.perm_n is not None:
            i_p = self.perm_n[i_p]
            j_p = self.perm_n[j_p]
        return i_p, j_p, d, np.sqrt((d * d).sum(axis=1))
