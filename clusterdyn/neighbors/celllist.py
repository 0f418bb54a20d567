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

from ..errors import InputError
from ..parallel import STREAM_BLOCK as BLOCK, blocks_max, max_take, use_threads

#: blocks of the displacement check (fixed: the result does not depend on the thread count)
DISP_BLOCKS = 16
#: most cells per particle before the grid is coarsened (dilute, exploding samples)
MAX_CELLS_PER_PARTICLE = 4


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


@njit(cache=True)
def _sort_by_cell(wpos_nc, pos_nc, lo_c, inv_cs_c, ncell_c, axes, xs_nc, offs_nc, cell_s):
    """Counting sort of the particles by cell (axes[0] slowest); stable in the original order.

    Returns (perm, start): sorted row k holds particle perm[k]; cell c holds rows start[c]..start[c+1].
    Fills the sorted wrapped positions ``xs_nc``, wrap offsets ``offs_nc`` and cells ``cell_s``.
    """
    n = wpos_nc.shape[0]
    a0, a1, a2 = axes[0], axes[1], axes[2]
    n0, n1, n2 = ncell_c[a0], ncell_c[a1], ncell_c[a2]
    ncell = n0 * n1 * n2
    cell_n = np.empty(n, np.int64)
    count = np.zeros(ncell + 1, np.int64)
    for i in range(n):
        k0 = int(math.floor((wpos_nc[i, a0] - lo_c[a0]) * inv_cs_c[a0]))
        k1 = int(math.floor((wpos_nc[i, a1] - lo_c[a1]) * inv_cs_c[a1]))
        k2 = int(math.floor((wpos_nc[i, a2] - lo_c[a2]) * inv_cs_c[a2]))
        k0 = min(max(k0, 0), n0 - 1)
        k1 = min(max(k1, 0), n1 - 1)
        k2 = min(max(k2, 0), n2 - 1)
        c = (k0 * n1 + k1) * n2 + k2
        cell_n[i] = c
        count[c + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    start = count.copy()
    fill = count[:-1].copy()
    perm = np.empty(n, np.int64)
    for i in range(n):
        c = cell_n[i]
        k = fill[c]
        fill[c] += 1
        perm[k] = i
        cell_s[k] = c
        for d in range(3):
            xs_nc[k, d] = wpos_nc[i, d]
            offs_nc[k, d] = wpos_nc[i, d] - pos_nc[i, d]
    return perm, start


@njit(inline="always")
def _scan(xs_nc, a0, a1, b0, b1, own, sx, sy, sz, code, rcut2, cap, nbr_nk, img_nk, cnt_n):
    """Partners of rows a0..a1 among rows b0..b1 (shifted by -s); ``own``: only j > i."""
    for i in range(a0, a1):
        xi = xs_nc[i, 0] - sx
        yi = xs_nc[i, 1] - sy
        zi = xs_nc[i, 2] - sz
        cnt = cnt_n[i]
        q0 = b0
        if own:
            q0 = i + 1
        for j in range(q0, b1):
            ju = np.uint64(j)
            dx = xs_nc[ju, 0] - xi
            dy = xs_nc[ju, 1] - yi
            dz = xs_nc[ju, 2] - zi
            # branch-free: every candidate is written at the next free slot,
            # which only a hit keeps (a hit or miss is a coin toss here)
            if cnt < cap:
                nbr_nk[i, cnt] = j
                img_nk[i, cnt] = code
            cnt += 1 if dx * dx + dy * dy + dz * dz < rcut2 else 0
        cnt_n[i] = cnt


@njit(cache=True, parallel=True)
def _fill_half_stencil(xs_nc, start, nslot, periodic_s, runs_r4, slotbox_s3, slotmult_s,
                       rcut2, cap, nbr_nk, img_nk, cnt_n):
    """Half list over sorted particles in one pass: own cell (j > i) + 13 forward cells.

    Cells are indexed in "slot" order (slot 0 slowest); ``nslot``/``periodic_s`` are
    the cell counts and periodicity per slot, ``slotbox_s3`` the Cartesian box
    vector of each slot's axis and ``slotmult_s`` its weight in the 3x3x3 image
    code.  Valid when every periodic slot has >= 3 cells of size >= the cut-off.
    The forward stencil is walked as runs of cells along the fastest slot
    (``runs_r4`` = d0, d1, first and last d2; :data:`HALF_RUNS`): cells of a
    run are consecutive rows, so a run is one scan unless it wraps a periodic
    face.  Row i gets its partners in stencil order in ``nbr_nk[i, :cnt_n[i]]``.
    cnt_n may exceed cap (the maximum is returned), then the caller retries
    with a larger cap.
    """
    m0 = nslot[0]
    m1 = nslot[1]
    m2 = nslot[2]
    nr = runs_r4.shape[0]
    for c in prange(m0 * m1 * m2):
        a0 = start[c]
        a1 = start[c + 1]
        if a1 == a0:
            continue
        for i in range(a0, a1):
            cnt_n[i] = 0
        g2 = c % m2
        g1 = (c // m2) % m1
        g0 = c // (m2 * m1)
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
                    b0 = start[base + seg_lo]
                    b1 = start[base + seg_hi + 1]
                    if b1 > b0:
                        own = r == 0 and base + seg_lo == c
                        sx = i0 * slotbox_s3[0, 0] + i1 * slotbox_s3[1, 0] + seg_i2 * slotbox_s3[2, 0]
                        sy = i0 * slotbox_s3[0, 1] + i1 * slotbox_s3[1, 1] + seg_i2 * slotbox_s3[2, 1]
                        sz = i0 * slotbox_s3[0, 2] + i1 * slotbox_s3[1, 2] + seg_i2 * slotbox_s3[2, 2]
                        code = 13 + i0 * slotmult_s[0] + i1 * slotmult_s[1] + seg_i2 * slotmult_s[2]
                        _scan(xs_nc, a0, a1, b0, b1, own, sx, sy, sz, code, rcut2, cap, nbr_nk, img_nk,
                              cnt_n)
                seg_lo = -1
                if ok:
                    seg_lo = h2
                    seg_hi = h2
                    seg_i2 = i2
    m = 0
    for i in range(cnt_n.shape[0]):
        m = max(m, cnt_n[i])
    return m


@njit(cache=True, parallel=True)
def _compact(nbr_nk, img_nk, cnt_n, first_n, j_p, img_p):
    n = cnt_n.shape[0]
    for i in prange(n):
        p = first_n[i]
        for q in range(cnt_n[i]):
            j_p[p + q] = nbr_nk[i, q]
            img_p[p + q] = img_nk[i, q]


@njit(cache=True, parallel=True)
def gather_positions(pos_nc, perm, offs_nc, xs_nc):
    """xs[k] = pos[perm[k]] + offset[k]: sorted wrapped positions for the kernels."""
    n = perm.shape[0]
    for b in prange((n + BLOCK - 1) // BLOCK):
        for k in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            i = np.uint64(perm[k])
            xs_nc[k, 0] = pos_nc[i, 0] + offs_nc[k, 0]
            xs_nc[k, 1] = pos_nc[i, 1] + offs_nc[k, 1]
            xs_nc[k, 2] = pos_nc[i, 2] + offs_nc[k, 2]


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
def kick_drift_gather(p_nc, f_nc, x_nc, invm_n, h, dt, perm, offs_nc, ref_nc, xs_nc, vs_nc, bstat_b9):
    """The first half of a velocity-Verlet step fused with the pair loop's gathers, in row order.

    For sorted row k, particle i = perm[k]: ``p[i] += h f[i]``, ``x[i] += dt p[i]/m[i]``,
    then ``xs[k] = x[i] + offs[k]`` (as :func:`gather_positions`) and, when
    ``vs_nc`` has rows, ``vs[k] = p[i]/m[i]`` (as :func:`gather_velocities`).  The
    arithmetic per particle is that of the separate kick, drift and gathers, so
    the results are the same bit for bit.  Returns (max v^2, its particle,
    ``max |x - ref|^2``, squared half-diagonal of the displacements' bounding box):
    the speed check and the list's rebuild test (:meth:`NeighborList.update`
    with ``displacement=``) without another pass.  Maxima are over fixed blocks
    in block order (independent of the thread count); a NaN speed or
    displacement comes back as the maximum (inf for the displacement).
    """
    n = perm.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    damp = vs_nc.shape[0] > 0
    for b in prange(nb):
        m = -1.0
        kk = -1
        acc = _disp_start()
        for k in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            i = np.uint64(perm[k])
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
            xs_nc[k, 0] = x + offs_nc[k, 0]
            xs_nc[k, 1] = y + offs_nc[k, 1]
            xs_nc[k, 2] = z + offs_nc[k, 2]
            if damp:
                vs_nc[k, 0] = vx
                vs_nc[k, 1] = vy
                vs_nc[k, 2] = vz
            m, kk = max_take(m, kk, vx * vx + vy * vy + vz * vz, perm[k])
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


def _box_key(cell, pbc):
    """What :meth:`NeighborList.update` compares to tell whether the box changed since the build."""
    return (tuple(np.asarray(cell, dtype=float).ravel().tolist()),
            tuple(np.broadcast_to(np.asarray(pbc, dtype=bool), (3,)).tolist()))


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
        built in one pass over the own cell and 13 forward cells.
    centered : bool, default False
        Rebuild test.  False: when a particle moved more than ``skin/2`` since
        the last build.  True: when both that and the half-diagonal of the
        bounding box of all displacements exceed ``skin/2`` (any common
        translation is subtracted, so a block moving as a whole, e.g. the
        material behind a shock front, triggers no rebuild of its own).  Both
        are rigorous: no pair closer than the cutoff is ever missing.

    Attributes
    ----------
    first_n : (N+1,) int64, j_p : (P,) int32, img_p : (P,) int16
        CSR pair list (see module docstring); over sorted rows when ``sort``.
    perm_n : (N,) int64 or None
        With ``sort``: sorted row k is particle ``perm_n[k]``.
    offs_nc : (N, 3) float64
        With ``sort``: wrap offsets of the sorted rows.
    offset_nc : (N, 3) float64
        Wrap of each particle into the box at the last build (caller's order).
    image_sc : (S, 3) float64
        Cartesian lattice translations indexed by ``img_p``.
    nbuilds : int
        Number of builds so far.
    """

    def __init__(self, cutoff, skin=0.0, half=True, sort=False, centered=False):
        if not (float(cutoff) > 0):
            raise InputError("cutoff", cutoff, "a positive distance")
        if not (float(skin) >= 0):
            raise InputError("skin", skin, "a distance >= 0")
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.half = bool(half)
        self.sort = bool(sort)
        self.centered = bool(centered)
        self.nbuilds = 0
        self.ref_nc = None
        self.perm_n = None
        self._key = None
        self._cap = 0
        self._work = {}
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
        return not (m <= lim or h2 <= lim)

    def _grid(self, pos, cell, pbc):
        box_c, periodic_c = check_cell(cell, pbc)
        n = pos.shape[0]
        if not np.all(np.isfinite(pos)):
            bad = np.nonzero(~np.isfinite(pos).all(axis=1))[0]
            raise InputError("positions", f"non-finite at particles {bad[:5].tolist()}", "finite values")
        rcut = self.cutoff + self.skin
        wpos = np.empty_like(pos)
        _wrap(pos, box_c, periodic_c, wpos)
        lo = np.zeros(3)
        ext = np.zeros(3)
        for d in range(3):
            if periodic_c[d]:
                ext[d] = box_c[d]
            elif n:
                lo[d] = pos[:, d].min()
                ext[d] = pos[:, d].max() - lo[d]
        ncell = np.ones(3, np.int64)
        cs = np.ones(3)
        for d in range(3):
            ncell[d] = max(1, int(math.floor(ext[d] / rcut))) if ext[d] > 0 else 1
        # coarsen a dilute grid (fragments flying apart) so cells stay O(N)
        while ncell.prod() > MAX_CELLS_PER_PARTICLE * max(n, 1) + 27:
            big = np.argmax(ncell)
            ncell[big] = max(1, ncell[big] // 2)
        krange = np.ones(3, np.int64)
        for d in range(3):
            cs[d] = ext[d] / ncell[d] if ext[d] > 0 else rcut
            if not periodic_c[d]:
                cs[d] = max(cs[d], rcut)
            krange[d] = max(1, int(math.ceil(rcut / cs[d] - 1e-12)))
            if not periodic_c[d]:
                krange[d] = 1
        box = np.where(periodic_c, box_c, 0.0)
        return wpos, lo, cs, ncell, krange, periodic_c, box, rcut

    def build(self, positions, cell, pbc):
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        wpos, lo, cs, ncell, krange, periodic_c, box, rcut = self._grid(pos, cell, pbc)
        if self.sort:
            self._build_sorted(pos, wpos, lo, cs, ncell, krange, periodic_c, box, rcut)
        else:
            self._build_unsorted(pos, wpos, lo, cs, ncell, krange, periodic_c, box, rcut)
        if self.ref_nc is not None and self.ref_nc.shape == pos.shape:
            np.copyto(self.ref_nc, pos)
        else:
            self.ref_nc = pos.copy()
        self._key = _box_key(cell, pbc)
        self.nbuilds += 1

    def _scratch(self, name, shape, dtype):
        """A build's work array, kept between builds (fresh pages cost a page fault each)."""
        a = self._work.get(name)
        if a is None or a.shape != shape or a.dtype != dtype:
            a = np.empty(shape, dtype)
            self._work[name] = a
        return a

    def _image_table(self, krange, box):
        kx, ky, kz = krange
        ii = np.arange(-kx, kx + 1)
        jj = np.arange(-ky, ky + 1)
        ll = np.arange(-kz, kz + 1)
        img = np.array(np.meshgrid(ii, jj, ll, indexing="ij")).reshape(3, -1).T
        return np.ascontiguousarray(img * box[None, :])

    def _build_unsorted(self, pos, wpos, lo, cs, ncell, krange, periodic_c, box, rcut):
        n = pos.shape[0]
        cell_n, start, order = _bin_particles(wpos, lo, 1.0 / cs, ncell)
        first_n = np.zeros(n + 1, np.int64)
        dummy_j = np.empty(0, np.int32)
        dummy_i = np.empty(0, np.int16)
        _search(wpos, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, True, first_n, dummy_j, dummy_i)
        np.cumsum(first_n, out=first_n)
        npairs = int(first_n[-1])
        j_p = np.empty(npairs, np.int32)
        img_p = np.empty(npairs, np.int16)
        _search(wpos, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, False, first_n, j_p, img_p)
        self.image_sc = self._image_table(krange, box)
        self.first_n, self.j_p, self.img_p = first_n, j_p, img_p
        self.perm_n = None
        self._offset_nc = wpos - pos

    def _build_sorted(self, pos, wpos, lo, cs, ncell, krange, periodic_c, box, rcut):
        n = pos.shape[0]
        # slowest-varying cell axis: the one with most cells (thinnest layers, so a
        # contiguous block of rows touches few rows outside itself)
        axes = np.array(sorted(range(3), key=lambda d: (-ncell[d], d)), np.int64)
        xs = np.empty((n, 3))
        offs = self._scratch("offs", (n, 3), np.float64)
        cell_s = self._scratch("cell", (n,), np.int64)
        perm, start = _sort_by_cell(wpos, pos, lo, 1.0 / cs, ncell, axes, xs, offs, cell_s)
        fast = self.half and np.all(krange == 1) and all(ncell[d] >= 3 for d in range(3) if periodic_c[d])
        if fast:
            nslot = ncell[axes]
            periodic_s = periodic_c[axes].copy()
            slotbox = np.zeros((3, 3))
            for q, d in enumerate(axes):
                slotbox[q, d] = box[d]
            slotmult = np.array([9, 3, 1], np.int64)[axes]
            cap = self._cap or 16
            while True:
                nbr = self._scratch("nbr", (n, cap), np.int32)
                img = self._scratch("img", (n, cap), np.int16)
                cnt = self._scratch("cnt", (n,), np.int64)
                m = _fill_half_stencil(xs, start, nslot, periodic_s, HALF_RUNS, slotbox,
                                       slotmult, rcut * rcut, cap, nbr, img, cnt)
                if m <= cap:
                    break
                cap = int(m * 1.25) + 4
            self._cap = cap
            first_n = np.zeros(n + 1, np.int64)
            np.cumsum(cnt, out=first_n[1:])
            npairs = int(first_n[-1])
            j_p = np.empty(npairs, np.int32)
            img_p = np.empty(npairs, np.int16)
            _compact(nbr, img, cnt, first_n, j_p, img_p)
            self.image_sc = self._image_table(np.ones(3, np.int64), box)
        else:
            first_n = np.zeros(n + 1, np.int64)
            dummy_j = np.empty(0, np.int32)
            dummy_i = np.empty(0, np.int16)
            # _search decodes cells with x slowest: re-bin the sorted rows that way
            cell_x, start_x, order_x = _bin_particles(xs, lo, 1.0 / cs, ncell)
            _search(xs, cell_x, start_x, order_x, ncell, krange, periodic_c, box, rcut * rcut,
                    self.half, True, first_n, dummy_j, dummy_i)
            np.cumsum(first_n, out=first_n)
            npairs = int(first_n[-1])
            j_p = np.empty(npairs, np.int32)
            img_p = np.empty(npairs, np.int16)
            _search(xs, cell_x, start_x, order_x, ncell, krange, periodic_c, box, rcut * rcut,
                    self.half, False, first_n, j_p, img_p)
            self.image_sc = self._image_table(krange, box)
        self.first_n, self.j_p, self.img_p = first_n, j_p, img_p
        self.perm_n = perm
        self.offs_nc = offs
        self._offset_nc = None

    @property
    def offset_nc(self):
        """Wrap offsets at the last build, in the caller's particle order."""
        if self.perm_n is None:
            return self._offset_nc
        off = np.empty_like(self.offs_nc)
        off[self.perm_n] = self.offs_nc
        return off

    @property
    def npairs(self):
        return int(self.first_n[-1])

    def sorted_positions(self, positions, out=None):
        """Wrapped positions in the list's row order (sorted lists), Angstrom."""
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        if self.perm_n is None:
            return pos + self._offset_nc
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
