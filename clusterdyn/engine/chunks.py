"""The chunks of the Cluster Dynamics pair loop and the sums over them.

A pass walks the rows of the list in fixed chunks (:func:`chunk_count`: set by the particle
count and the list's cell layers, never by the thread count, so the forces are the same bits on
any number of threads).  Chunk k accumulates into its own buffer rows, which cover only the rows
its pairs touch; :func:`reduce_rows` sums the buffers of a row in chunk order and scatters the
sum to the caller's row ``perm_n[i]``; :func:`reduce_shared` does it for the rows two chunks
share, after a step kernel wrote every other row itself.
"""

from collections import namedtuple

import numpy as np
from numba import njit, prange


#: rows per chunk: the unit of work of a thread and of the summation order
CHUNK_ROWS = 16384


#: a chunk spans at least this many layers of the list's cells where there are at least
#: :data:`MIN_CHUNKS` such chunks (a chunk's partners reach about one layer past its end)
CHUNK_LAYERS = 16


#: the fewest chunks that thick layers may bring the count down to
MIN_CHUNKS = 16


#: a list of fewer than ``FEW_CHUNKS * CHUNK_ROWS`` rows still gets up to this many chunks, of at
#: least :data:`MIN_CHUNK_ROWS` rows, so that two to four threads share its pair loop
FEW_CHUNKS = 4


MIN_CHUNK_ROWS = 2048


#: shared rows per block of :func:`reduce_shared`
SHARED_BLOCK = 4096


#: the chunks of a list (:func:`chunk_layout`)
Chunks = namedtuple("Chunks", "bounds span boff cptr clist shared_n shared_r owner_r")


def chunk_count(n, layer_rows):
    """Chunks of a list of n rows whose cell layers hold up to ``layer_rows`` rows.

    About n / :data:`CHUNK_ROWS`; but a chunk's partners reach about one layer of cells past
    its last row, into rows that the next chunk owns (summed afterwards, :func:`reduce_shared`,
    and held in the chunk's own buffer rows), so where layers are thick (a compact body of a
    million clusters: up to 22 000 rows a layer, half the rows shared at 16 384 rows a chunk)
    chunks are made :data:`CHUNK_LAYERS` layers long, as long as there are at least
    :data:`MIN_CHUNKS`.  A small list (under ``FEW_CHUNKS * CHUNK_ROWS`` rows) is cut into up to
    :data:`FEW_CHUNKS` chunks of at least :data:`MIN_CHUNK_ROWS` rows (8 192 rows: 4 chunks),
    where a chunk of 16 384 rows would leave a second thread nothing to do in the pair loop.
    A property of the list alone, never of the thread count: the sums' order, and so the
    forces' bits, do not depend on it.
    """
    nk = max(1, n // CHUNK_ROWS, min(FEW_CHUNKS, n // MIN_CHUNK_ROWS))
    if layer_rows > 0:
        nk = min(nk, max(MIN_CHUNKS, n // (CHUNK_LAYERS * layer_rows)))
    return nk


@njit(cache=True)
def chunk_bounds(first_n, nchunks):
    """Split rows into nchunks ranges of about equal pair counts."""
    n = first_n.shape[0] - 1
    b = np.zeros(nchunks + 1, np.int64)
    total = first_n[n]
    i = 0
    for k in range(1, nchunks):
        target = total * k // nchunks
        while i < n and first_n[i] < target:
            i += 1
        b[k] = i
    b[nchunks] = n
    for k in range(1, nchunks + 1):
        if b[k] < b[k - 1]:
            b[k] = b[k - 1]
    return b


def chunk_layout(first_n, jp_p, jmask, nchunks):
    """The :class:`Chunks` of a list (:func:`_chunk_layout`)."""
    return Chunks(*_chunk_layout(first_n, jp_p, jmask, nchunks))


@njit(cache=True, parallel=True)
def _chunk_layout(first_n, jp_p, jmask, nchunks):
    """Chunks of a list: (bounds_k, span_k2, boff_k, cptr_k, clist, shared_n, shared_r, owner_r).

    Chunk k owns rows ``bounds_k[k]:bounds_k[k+1]`` and writes rows
    ``span_k2[k, 0]:span_k2[k, 1]`` into buffer rows starting at ``boff_k[k]``;
    ``clist[cptr_k[k]:cptr_k[k+1]]`` are the chunks (ascending) whose span meets
    the rows chunk k owns: the terms of those rows' sums, in order.
    ``shared_n[i]`` is 1 for a row that a chunk other than its owner writes (a
    partner row across a chunk boundary); ``shared_r`` lists them ascending and
    ``owner_r`` their owner chunks.  Every other row's force is its owner's buffer
    row alone, which the step kernels write out themselves (``FIN``).
    """
    bounds = chunk_bounds(first_n, nchunks)
    nk = nchunks
    n = first_n.shape[0] - 1
    span = np.empty((nk, 2), np.int64)
    shared_n = np.zeros(n, np.uint8)
    for k in prange(nk):        # (chunks mark partner rows as shared: only ever the value 1)
        lo = bounds[k]
        hi = bounds[k + 1]
        b0 = bounds[k]
        b1 = bounds[k + 1]
        for p in range(first_n[b0], first_n[b1]):
            j = np.int64(jp_p[p] & jmask)
            if j < lo:
                lo = j
            if j + 1 > hi:
                hi = j + 1
            if j < b0 or j >= b1:
                shared_n[j] = 1
        span[k, 0] = lo
        span[k, 1] = hi
    nsh = 0
    for i in range(n):
        nsh += shared_n[i]
    shared_r = np.empty(nsh, np.int64)
    owner_r = np.empty(nsh, np.int64)
    q = 0
    k = 0
    for i in range(n):
        if shared_n[i]:
            while i >= bounds[k + 1]:
                k += 1
            shared_r[q] = i
            owner_r[q] = k
            q += 1
    boff = np.zeros(nk + 1, np.int64)
    for k in range(nk):
        boff[k + 1] = boff[k] + span[k, 1] - span[k, 0]
    cnt = 0
    for k in range(nk):
        for kk in range(nk):
            if span[kk, 0] < bounds[k + 1] and span[kk, 1] > bounds[k]:
                cnt += 1
    cptr = np.zeros(nk + 1, np.int64)
    clist = np.empty(cnt, np.int64)
    q = 0
    for k in range(nk):
        for kk in range(nk):
            if span[kk, 0] < bounds[k + 1] and span[kk, 1] > bounds[k]:
                clist[q] = kk
                q += 1
        cptr[k + 1] = q
    return bounds, span, boff, cptr, clist, shared_n, shared_r, owner_r


@njit(inline="always")
def _row_sum3(buf_mc, i, q0, q1, clist, span_k2, boff_k):
    """Sum of row i's three columns over the chunks ``clist[q0:q1]`` whose span holds it, in order."""
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for q in range(q0, q1):
        kk = clist[q]
        if span_k2[kk, 0] <= i and i < span_k2[kk, 1]:
            r = boff_k[kk] + i - span_k2[kk, 0]
            sx += buf_mc[r, 0]
            sy += buf_mc[r, 1]
            sz += buf_mc[r, 2]
    return sx, sy, sz


@njit(cache=True)
def _put3(out_nc, p_nc, o, sx, sy, sz, kick, h):
    """out[o] = s, and the half kick p[o] += h s when ``kick``."""
    out_nc[o, 0] = sx
    out_nc[o, 1] = sy
    out_nc[o, 2] = sz
    if kick:
        p_nc[o, 0] += h * sx
        p_nc[o, 1] += h * sy
        p_nc[o, 2] += h * sz


@njit(cache=True, parallel=True)
def reduce_shared(buf_mc, ch, perm_n, out_nc, p_nc, h):
    """:func:`reduce_rows` (three columns) over the shared rows only: the step kernels (``FIN``)
    have written every other row.  Fixed blocks of rows, so the same on any thread count."""
    _, span_k2, boff_k, cptr_k, clist, _, shared_r, owner_r = ch
    kick = p_nc.shape[0] > 0
    m = shared_r.shape[0]
    for b in prange((m + SHARED_BLOCK - 1) // SHARED_BLOCK):
        for q in range(b * SHARED_BLOCK, min(m, (b + 1) * SHARED_BLOCK)):
            i = shared_r[q]
            k = owner_r[q]
            sx, sy, sz = _row_sum3(buf_mc, i, cptr_k[k], cptr_k[k + 1], clist, span_k2, boff_k)
            _put3(out_nc, p_nc, np.uint64(perm_n[i]), sx, sy, sz, kick, h)


@njit(cache=True)
def chunk_stats(stat_k6, perm_n):
    """After a force pass: the closest pair's rows (columns 2, 3, where the loop tracked them)
    renamed to the caller's rows through ``perm_n``, in place; returns (k, smallest of column
    4, sum of column 4), k the chunk of the smallest r^2 (the first NaN if any, as
    ``np.argmin``).  One call instead of a Python loop over the chunks and three numpy
    reductions (about 10 us a step, a twentieth of a step of 2 048 clusters)."""
    k = 0
    best = stat_k6[0, 1]
    low = stat_k6[0, 4]
    tot = 0.0
    for q in range(stat_k6.shape[0]):
        for c in range(2, 4):
            if stat_k6[q, c] >= 0:
                stat_k6[q, c] = perm_n[np.int64(stat_k6[q, c])]
        v = stat_k6[q, 1]
        if best == best and (v != v or v < best):
            k = q
            best = v
        low = min(low, stat_k6[q, 4])
        tot += stat_k6[q, 4]
    return k, low, tot


@njit(cache=True, parallel=True)
def reduce_rows(buf_mc, ch, perm_n, out_nc, p_nc, h):
    """out[perm[i]] = sum over the chunks whose span holds row i, in chunk order (deterministic).

    With three columns and ``p_nc`` non-empty, also the velocity-Verlet half
    kick ``p[perm[i]] += h * out[perm[i]]`` in the same pass (the dynamics'
    second kick; the constraints' momenta are set after it).
    """
    bounds_k, span_k2, boff_k, cptr_k, clist, _, _, _ = ch
    kick = p_nc.shape[0] > 0
    nk = bounds_k.shape[0] - 1
    nc = buf_mc.shape[1]
    for k in prange(nk):
        q0 = cptr_k[k]
        q1 = cptr_k[k + 1]
        for i in range(bounds_k[k], bounds_k[k + 1]):
            o = np.uint64(perm_n[i])
            if nc == 3:
                sx, sy, sz = _row_sum3(buf_mc, i, q0, q1, clist, span_k2, boff_k)
                _put3(out_nc, p_nc, o, sx, sy, sz, kick, h)
            else:
                for c in range(nc):
                    out_nc[o, c] = 0.0
                for q in range(q0, q1):
                    kk = clist[q]
                    if span_k2[kk, 0] <= i and i < span_k2[kk, 1]:
                        r = boff_k[kk] + i - span_k2[kk, 0]
                        for c in range(nc):
                            out_nc[o, c] += buf_mc[r, c]
