"""A hand-written single-material CD pair loop with no damping code at all (benchmark reference).

Same list, chunks, buffers and work (forces, the smallest distance, the count of pairs
below the table, no energy; the rows no other chunk touches written out after the chunk's
loop) as ``clusterdyn.calculators._cd_kernels.cd_forces_1``; used by
throughput.py to show that the library's undamped variant costs what a loop
written without the damping term costs.
"""

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def reference_forces(xs_nc, first_n, j_p, img_p, image_sc, coef, meta, bounds_k, span_k2, boff_k, f_mc, stat_k,
                     shared_n, perm_n, out_nc):
    nb = coef.shape[2]
    smin = meta[0, 0, 0]
    invh = meta[0, 0, 1]
    cut2 = meta[0, 0, 2]
    rmin2 = meta[0, 0, 3]
    zero_img = image_sc.shape[0] // 2
    for k in prange(bounds_k.shape[0] - 1):
        off = boff_k[k] - span_k2[k, 0]
        for r in range(boff_k[k], boff_k[k + 1]):
            f_mc[r, 0] = 0.0
            f_mc[r, 1] = 0.0
            f_mc[r, 2] = 0.0
        minr2 = 1e300
        nclose = 0
        for i in range(bounds_k[k], bounds_k[k + 1]):
            xi = xs_nc[i, 0]
            yi = xs_nc[i, 1]
            zi = xs_nc[i, 2]
            fxi = 0.0
            fyi = 0.0
            fzi = 0.0
            for p in range(first_n[i], first_n[i + 1]):
                j = j_p[p]
                ju = np.uint64(j)
                dx = xs_nc[ju, 0] - xi
                dy = xs_nc[ju, 1] - yi
                dz = xs_nc[ju, 2] - zi
                s = img_p[p]
                if s != zero_img:
                    dx += image_sc[s, 0]
                    dy += image_sc[s, 1]
                    dz += image_sc[s, 2]
                r2 = dx * dx + dy * dy + dz * dz
                if not r2 < cut2:
                    continue
                minr2 = min(minr2, r2)
                if r2 < rmin2:
                    nclose += 1
                    continue
                x = (r2 - smin) * invh
                kb = int(x)
                if kb >= nb:
                    kb = nb - 1
                t = x - kb
                c1 = coef[0, 0, kb, 1]
                c2 = coef[0, 0, kb, 2]
                c3 = coef[0, 0, kb, 3]
                s_ = -2.0 * (c1 + t * (2.0 * c2 + 3.0 * t * c3)) * invh
                fx = s_ * dx
                fy = s_ * dy
                fz = s_ * dz
                fxi -= fx
                fyi -= fy
                fzi -= fz
                rj = np.uint64(off + j)
                f_mc[rj, 0] += fx
                f_mc[rj, 1] += fy
                f_mc[rj, 2] += fz
            f_mc[off + i, 0] += fxi
            f_mc[off + i, 1] += fyi
            f_mc[off + i, 2] += fzi
        for i in range(bounds_k[k], bounds_k[k + 1]):
            if shared_n[i] == 0:
                o = np.uint64(perm_n[i])
                out_nc[o, 0] = f_mc[off + i, 0]
                out_nc[o, 1] = f_mc[off + i, 1]
                out_nc[o, 2] = f_mc[off + i, 2]
        stat_k[k, 0] = 0.0
        stat_k[k, 1] = minr2
        stat_k[k, 2] = -1
        stat_k[k, 3] = -1
        stat_k[k, 4] = nclose
