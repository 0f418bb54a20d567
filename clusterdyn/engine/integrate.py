"""The Cluster Dynamics integrator's kernels: velocity Verlet's first half (kick and drift)
fused with the gathers of the next pair loop.

A CD step (:meth:`clusterdyn.engine.CDEngine.step`) is: kick and drift every particle, taking
in the same pass the sorted row of its position (and velocity, for the pair damping) and the
bounds of its displacement since the list's build (the rebuild test); then the pair loop, which
ends with the second half kick (:mod:`clusterdyn.engine.pair`).  The arithmetic per particle is
that of separate kick, drift and gather passes, so the fused step is the same bit for bit.
"""

import numpy as np
from numba import njit, prange

from ..parallel import STREAM_BLOCK as BLOCK, blocks_max, max_take
from ..neighbors.rebuild import _disp_add, _disp_result, _disp_start


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


@njit(cache=True, parallel=True)
def kick_drift_gather(p_nc, f_nc, x_nc, invm_n, h, dt, row_n, offs_nc, ref_nc, xs_nc, vs_nc, bstat_b9):
    """The first half of a velocity-Verlet step fused with the pair loop's gathers.

    For particle i, of sorted row k = row_n[i]: ``p[i] += h f[i]``, ``x[i] += dt p[i]/m[i]``,
    then ``xs[k] = x[i] + offs[i]`` (as :func:`clusterdyn.neighbors.sort.gather_positions`) and, when
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
    order (CHANGELOG.md, stop 25).
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
