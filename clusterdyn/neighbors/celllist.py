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
the last build, or when the cell or pbc changed.
"""

import math

import numba
import numpy as np
from numba import njit, prange

from ..errors import InputError
from ..parallel import use_threads

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


class NeighborList:
    """Verlet list with skin, built on a cell list (numba).

    Parameters
    ----------
    cutoff : float
        Interaction cutoff, Angstrom (largest over pair types).
    skin : float, default 0
        Extra radius; the list stays valid until a particle moved skin/2.
    half : bool, default True
        Store each unordered pair once (``True``) or both directions.

    Attributes
    ----------
    first_n : (N+1,) int64, j_p : (P,) int32, img_p : (P,) int16
        CSR pair list (see module docstring).
    offset_nc : (N, 3) float64
        Wrap of each particle into the box at the last build.
    image_sc : (S, 3) float64
        Cartesian lattice translations indexed by ``img_p``.
    nbuilds : int
        Number of builds so far.
    """

    def __init__(self, cutoff, skin=0.0, half=True):
        if not (float(cutoff) > 0):
            raise InputError("cutoff", cutoff, "a positive distance")
        if not (float(skin) >= 0):
            raise InputError("skin", skin, "a distance >= 0")
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.half = bool(half)
        self.nbuilds = 0
        self.ref_nc = None
        self._cell = None
        self._pbc = None

    def update(self, positions, cell, pbc):
        """Rebuild if needed; return True when rebuilt."""
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        cell = np.asarray(cell, dtype=float).reshape(3, 3)
        pbc = np.broadcast_to(np.asarray(pbc, dtype=bool), (3,)).copy()
        use_threads(pos.shape[0])
        if (self.ref_nc is None or self.ref_nc.shape != pos.shape
                or not np.array_equal(cell, self._cell) or not np.array_equal(pbc, self._pbc)
                or (pos.shape[0] and _max_disp2(pos, self.ref_nc) > (0.5 * self.skin) ** 2)):
            self.build(pos, cell, pbc)
            return True
        return False

    def build(self, positions, cell, pbc):
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        box_c, periodic_c = check_cell(cell, pbc)
        n = pos.shape[0]
        if not np.all(np.isfinite(pos)):
            bad = np.nonzero(~np.isfinite(pos).all(axis=1))[0]
            raise InputError("positions", f"non-finite at particles {bad[:5].tolist()}", "finite values")
        rcut = self.cutoff + self.skin
        wpos = pos.copy()
        lo = np.zeros(3)
        ext = np.zeros(3)
        for d in range(3):
            if periodic_c[d]:
                wpos[:, d] -= np.floor(pos[:, d] / box_c[d]) * box_c[d]
                # guard the rare x == L after rounding
                wpos[wpos[:, d] >= box_c[d], d] -= box_c[d]
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
        inv_cs = 1.0 / cs
        cell_n, start, order = _bin_particles(wpos, lo, inv_cs, ncell)
        first_n = np.zeros(n + 1, np.int64)
        dummy_j = np.empty(0, np.int32)
        dummy_i = np.empty(0, np.int16)
        box = np.where(periodic_c, box_c, 0.0)
        _search(wpos, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, True, first_n, dummy_j, dummy_i)
        np.cumsum(first_n, out=first_n)
        npairs = int(first_n[-1])
        j_p = np.empty(npairs, np.int32)
        img_p = np.empty(npairs, np.int16)
        _search(wpos, cell_n, start, order, ncell, krange, periodic_c, box, rcut * rcut,
                self.half, False, first_n, j_p, img_p)
        kx, ky, kz = krange
        ii = np.arange(-kx, kx + 1)
        jj = np.arange(-ky, ky + 1)
        ll = np.arange(-kz, kz + 1)
        img = np.array(np.meshgrid(ii, jj, ll, indexing="ij")).reshape(3, -1).T
        self.image_sc = np.ascontiguousarray(img * box[None, :])
        self.first_n, self.j_p, self.img_p = first_n, j_p, img_p
        self.offset_nc = wpos - pos
        self.ref_nc = pos.copy()
        self._cell = np.array(cell, dtype=float).reshape(3, 3)
        self._pbc = periodic_c.copy()
        self.nbuilds += 1

    @property
    def npairs(self):
        return int(self.first_n[-1])

    def pairs(self, positions):
        """Python-side view: (i_p, j_p, d_pc, r_p) for the given positions (tests, analysis)."""
        pos = np.asarray(positions, dtype=float)
        i_p = np.repeat(np.arange(len(pos)), np.diff(self.first_n))
        j_p = self.j_p.astype(np.int64)
        w = pos + self.offset_nc
        d = w[j_p] - w[i_p] + self.image_sc[self.img_p]
        return i_p, j_p, d, np.sqrt((d * d).sum(axis=1))
