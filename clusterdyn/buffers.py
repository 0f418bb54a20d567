"""Per-particle buffers that grow and never shrink, and moving rows in place.

A run that removes particles (``DampedVerlet(region=...)``) would otherwise
reallocate every N-sized buffer at each removal; the old and new arrays side by
side, and the freed blocks glibc keeps in its heap, raised the peak memory by
100-170 bytes per particle (CHANGELOG.md, "Removing particles allocates
nothing of N's size").  A buffer from :func:`grown` keeps its rows; the caller
uses a view of the first n.  :func:`permute` reorders an array's rows in place
(sorting the Atoms into the neighbour list's cell order, ``DampedVerlet(sort_interval=...)``)
through one such buffer.
"""

import numpy as np
from numba import njit, prange

#: words per row of the scratch :func:`permute` goes through (wider rows go a group at a time)
PERMUTE_WORDS = 1


def grown(buf, n, tail=(3,), dtype=np.float64):
    """``buf`` when it has at least ``n`` rows, else a new empty array of ``n`` rows of shape
    ``tail`` and ``dtype``; callers use ``[:n]`` of it."""
    if buf is None or buf.shape[0] < n:
        return np.empty((n, *tail), dtype)
    return buf


@njit(cache=True, parallel=True)
def _permute_words(a_nw, order_n, tmp_nw):
    """``a[k] = a[order[k]]`` for every row k, through ``tmp_nw`` (the same rows, at most as many
    words per row: wider rows go a group of ``tmp_nw.shape[1]`` words at a time)."""
    n, b = a_nw.shape
    w = tmp_nw.shape[1]
    for s in range(0, b, w):
        e = min(b, s + w)
        for k in prange(n):
            i = order_n[k]
            for c in range(s, e):
                tmp_nw[k, c - s] = a_nw[i, c]
        for k in prange(n):
            for c in range(s, e):
                a_nw[k, c] = tmp_nw[k, c - s]


def permute(a, order, scratch):
    """Reorder the rows of ``a`` in place: row k becomes old row ``order[k]`` (``order`` a
    permutation of ``range(len(a))``).  ``scratch``: a :func:`grown` float64 buffer of at least
    ``len(a)`` rows of :data:`PERMUTE_WORDS` words (8 bytes a particle: wider rows go a word
    at a time); the array keeps its identity (views of it
    stay valid) and nothing of its size is allocated.  Returns ``a``."""
    n = a.shape[0]
    if n == 0 or a.size == 0:
        return a
    if not a.flags.c_contiguous:
        a[...] = a[order]
        return a
    row = a.nbytes // n
    wt = np.uint64 if row % 8 == 0 else np.uint8
    words = a.reshape(n, -1).view(wt)
    tmp = scratch[:n].view(wt)
    _permute_words(words, order, tmp)
    return a
