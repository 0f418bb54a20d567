"""When the Verlet list must be rebuilt: the displacement tests.

The global test: the largest displacement since the build (or, centred, the spread of the
displacements) against half the skin, reduced in :data:`DISP_BLOCKS` fixed blocks (the result
does not depend on the thread count).  The local test: the particles are grouped into bricks
(cubes of at least :data:`BRICK_SIDE` cut-offs); only pairs of bricks within reach of each other
are checked, each with its own displacement bound, so a sample whose parts move apart fast (a
debris cloud) is not rebuilt for motions that cannot bring a new pair within the cut-off.
"""

import math

import numba
import numpy as np
from numba import njit, prange

from .fill import _lower
from .grid import _wrap1


#: blocks of the displacement check (fixed: the result does not depend on the thread count)
DISP_BLOCKS = 16


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
