"""Per-particle buffers that grow and never shrink.

A run that removes particles (``DampedVerlet(region=...)``) would otherwise
reallocate every N-sized buffer at each removal; the old and new arrays side by
side, and the freed blocks glibc keeps in its heap, raised the peak memory by
100-170 bytes per particle (docs/performance.md, "Removing particles allocates
nothing of N's size").  A buffer from :func:`grown` keeps its rows; the caller
uses a view of the first n.
"""

import numpy as np


def grown(buf, n, tail=(3,), dtype=np.float64):
    """``buf`` when it has at least ``n`` rows, else a new empty array of ``n`` rows of shape
    ``tail`` and ``dtype``; callers use ``[:n]`` of it."""
    if buf is None or buf.shape[0] < n:
        return np.empty((n, *tail), dtype)
    return buf
