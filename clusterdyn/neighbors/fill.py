"""Filling the Verlet list and its memory pool: the unsorted search (full stencil), the sorted
half-list fill in slabs of a shared pool, the slab sizing, packing of partner and image code
into one word, and the compaction of the rows when particles are removed.

A sorted half list packs each pair as ``j | image_code << HALF_SHIFT`` (uint32).  Rows are
filled a block of :data:`FILL_BLOCK_ROWS` at a time, each block into its own slab of the pool
(sized from its previous need times :data:`SLAB_MARGIN`); a block that needs more is retried
with a larger slab, so the pool is reallocated only when the whole list outgrows it.
"""

import numpy as np
from numba import njit, prange


#: rows per block of the half-list build (the unit of work of a thread and of a slab)
FILL_BLOCK_ROWS = 4096


#: a block's slab of the pair pool: its previous need times this (plus 64)
SLAB_MARGIN = 1.2


#: bit of the image code in a packed half-list pair ``j | code << HALF_SHIFT`` (27 codes; N < 2**27)
HALF_SHIFT = 27


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


@njit(cache=True, parallel=True)
def _pack(j_p, img_p, shift, out_p):
    for p in prange(j_p.shape[0]):
        out_p[p] = np.uint32(j_p[p]) | (np.uint32(img_p[p]) << np.uint32(shift))


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


#: the forward half of the 3x3x3 cell stencil (own cell and the 13 cells after it in slot
#: order) as runs along the fastest slot: (d0, d1, first d2, last d2); the first run starts
#: at the own cell (partners j > i there)
HALF_RUNS = np.array([[0, 0, 0, 1], [0, 1, -1, 1], [1, -1, -1, 1], [1, 0, -1, 1], [1, 1, -1, 1]],
                     dtype=np.int64)
