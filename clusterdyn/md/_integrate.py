"""numba kernels of the velocity-Verlet sub-steps (kick, drift) with a speed monitor.

They stream through memory at about a nanosecond per particle, so on more
than one thread they are a visible share of a step (Amdahl): they run in
parallel over fixed blocks of ``clusterdyn.parallel.STREAM_BLOCK`` particles.  Every result is the
same on any thread count: kicks and drifts are per particle, and the largest
speed is a maximum over blocks taken in block order.  Over fewer particles
than ``clusterdyn.parallel.MIN_PARTICLES_PER_THREAD`` the dynamics runs them
on one thread (no fork and join).
"""

import numpy as np
from numba import njit, prange

from ..parallel import STREAM_BLOCK as BLOCK, blocks_max, max_take


@njit(cache=True, parallel=True)
def kick(p_nc, f_nc, h):
    """p += h * f (h = dt/2)."""
    n = p_nc.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    for b in prange(nb):
        for i in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            p_nc[i, 0] += h * f_nc[i, 0]
            p_nc[i, 1] += h * f_nc[i, 1]
            p_nc[i, 2] += h * f_nc[i, 2]


@njit(cache=True, parallel=True)
def drift(x_nc, p_nc, invm_n, dt):
    """x += dt * p/m; returns (max v^2, its particle). NaN/inf speeds come back as max."""
    n = x_nc.shape[0]
    if n == 0:
        return 0.0, -1
    nb = (n + BLOCK - 1) // BLOCK
    bmax = np.empty(nb)
    barg = np.empty(nb, np.int64)
    for b in prange(nb):
        m = -1.0
        k = b * BLOCK
        for i in range(b * BLOCK, min(n, (b + 1) * BLOCK)):
            vx = p_nc[i, 0] * invm_n[i]
            vy = p_nc[i, 1] * invm_n[i]
            vz = p_nc[i, 2] * invm_n[i]
            x_nc[i, 0] += dt * vx
            x_nc[i, 1] += dt * vy
            x_nc[i, 2] += dt * vz
            m, k = max_take(m, k, vx * vx + vy * vy + vz * vz, i)
        bmax[b] = m
        barg[b] = k
    return blocks_max(bmax, barg)


@njit(cache=True)
def kinetic(p_nc, invm_n):
    e = 0.0
    for i in range(p_nc.shape[0]):
        e += 0.5 * (p_nc[i, 0] ** 2 + p_nc[i, 1] ** 2 + p_nc[i, 2] ** 2) * invm_n[i]
    return e


@njit(cache=True)
def set_momenta(p_nc, m_n, idx, v_c):
    """p[i] = m[i] * v for i in idx (a piston's layer)."""
    for q in range(idx.shape[0]):
        i = idx[q]
        p_nc[i, 0] = m_n[i] * v_c[0]
        p_nc[i, 1] = m_n[i] * v_c[1]
        p_nc[i, 2] = m_n[i] * v_c[2]


@njit(cache=True)
def take_forces(f_nc, idx, out_c):
    """out = sum of f[i] over idx, then f[i] = 0 (a piston's reaction)."""
    out_c[0] = 0.0
    out_c[1] = 0.0
    out_c[2] = 0.0
    for q in range(idx.shape[0]):
        i = idx[q]
        for d in range(3):
            out_c[d] += f_nc[i, d]
            f_nc[i, d] = 0.0


@njit(cache=True)
def set_momenta_along(p_nc, m_n, idx, n_c, u):
    """p[i] = (p[i] - (p[i].n) n) + (m[i] u) n for i in idx: the momentum along the unit
    vector n set to m u, the rest kept (a piston with free lateral motion).  Along a
    Cartesian axis the set component is m u exactly and the others are untouched."""
    for q in range(idx.shape[0]):
        i = idx[q]
        pn = p_nc[i, 0] * n_c[0] + p_nc[i, 1] * n_c[1] + p_nc[i, 2] * n_c[2]
        mu = m_n[i] * u
        for d in range(3):
            p_nc[i, d] = (p_nc[i, d] - pn * n_c[d]) + mu * n_c[d]


@njit(cache=True)
def take_forces_along(f_nc, idx, n_c, out_c):
    """out = sum over idx of (f[i].n) n, then f[i] -= (f[i].n) n (the reaction along n of a
    piston with free lateral motion; the forces across n stay on the particles)."""
    s = 0.0
    for q in range(idx.shape[0]):
        i = idx[q]
        fn = f_nc[i, 0] * n_c[0] + f_nc[i, 1] * n_c[1] + f_nc[i, 2] * n_c[2]
        s += fn
        for d in range(3):
            f_nc[i, d] -= fn * n_c[d]
    out_c[0] = s * n_c[0]
    out_c[1] = s * n_c[1]
    out_c[2] = s * n_c[2]


@njit(cache=True)
def outside_box(x_nc, lo_c, hi_c, out_n):
    """``out_n[i]`` = particle i is outside the box [lo, hi] (or has a non-finite coordinate);
    returns how many are."""
    c = 0
    for i in range(x_nc.shape[0]):
        o = False
        for d in range(3):
            if not (x_nc[i, d] >= lo_c[d] and x_nc[i, d] <= hi_c[d]):
                o = True
        out_n[i] = o
        c += o
    return c
