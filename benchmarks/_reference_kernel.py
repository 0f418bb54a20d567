"""A hand-written single-material CD pair loop with no damping code at all (benchmark reference).

Same list, chunks, buffers and work (forces, the smallest distance over the listed pairs,
no energy; pairs beyond the cut-off in the zero bin of the force table; the rows no other
chunk touches written out after the chunk's loop) as
``clusterdyn.calculators._cd_kernels.cd_forces_1``; used by throughput.py to show that
the library's undamped variant costs what a loop written without the damping term costs.
"""

import numpy as np
from numba import njit, prange

from clusterdyn.calculators._cd_kernels import table_force


@njit(cache=True, parallel=True)
def reference_forces(xs_nc, first_n, jp_p, shift, image_sc, gtab, meta, bounds_k, span_k2, boff_k, f_mc,
                     stat_k, shared_n, perm_n, out_nc):
    nbu = np.uint64(gtab.shape[2] - 1)
    smin = meta[0, 0, 0]
    invh = meta[0, 0, 1]
    zero_img = np.uint32(image_sc.shape[0] // 2)
    sh = np.uint32(shift)
    jmask = np.uint32((1 << shift) - 1)
    for k in prange(bounds_k.shape[0] - 1):
        off = boff_k[k] - span_k2[k, 0]
        offu = np.uint64(off)
        for r in range(boff_k[k], boff_k[k + 1]):
            f_mc[r, 0] = 0.0
            f_mc[r, 1] = 0.0
            f_mc[r, 2] = 0.0
        minr2 = 1e300
        for i in range(bounds_k[k], bounds_k[k + 1]):
            xi = xs_nc[i, 0]
            yi = xs_nc[i, 1]
            zi = xs_nc[i, 2]
            fxi = 0.0
            fyi = 0.0
            fzi = 0.0
            for p in range(np.uint64(first_n[i]), np.uint64(first_n[i + 1])):
                v = jp_p[p]
                ju = np.uint64(v & jmask)
                dx = xs_nc[ju, 0] - xi
                dy = xs_nc[ju, 1] - yi
                dz = xs_nc[ju, 2] - zi
                s = v >> sh
                if s != zero_img:
                    su = np.uint64(s)
                    dx += image_sc[su, 0]
                    dy += image_sc[su, 1]
                    dz += image_sc[su, 2]
                r2 = dx * dx + dy * dy + dz * dz
                minr2 = min(minr2, r2)
                x = (r2 - smin) * invh
                kb = int(x)
                t = x - kb
                kbu = min(np.uint64(kb), nbu)     # the library's one unsigned clamp (zero bin beyond)
                s_ = table_force(gtab, 0, 0, kbu, t)
                fx = s_ * dx
                fy = s_ * dy
                fz = s_ * dz
                fxi -= fx
                fyi -= fy
                fzi -= fz
                rj = offu + ju
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
        stat_k[k, 1] = minr2 * meta[0, 0, 4]
        stat_k[k, 2] = -1
        stat_k[k, 3] = -1
        stat_k[k, 4] = -1
