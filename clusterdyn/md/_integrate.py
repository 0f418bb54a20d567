"""numba kernels of the velocity-Verlet sub-steps (kick, drift) with a speed monitor.

They stream through memory at a few ns per particle and run on one thread:
every parallel region is a fork and a join of all threads, and on a loaded
machine a join that waits for a descheduled thread costs milliseconds.  The
dynamics keeps its parallel regions to the force loop and its reduction.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def kick(p_nc, f_nc, h):
    """p += h * f (h = dt/2)."""
    n = p_nc.shape[0]
    for i in range(n):
        p_nc[i, 0] += h * f_nc[i, 0]
        p_nc[i, 1] += h * f_nc[i, 1]
        p_nc[i, 2] += h * f_nc[i, 2]


@njit(cache=True)
def drift(x_nc, p_nc, invm_n, dt, v2_n):
    """x += dt * p/m; returns (max v^2, its particle). NaN/inf speeds come back as max."""
    n = x_nc.shape[0]
    for i in range(n):
        vx = p_nc[i, 0] * invm_n[i]
        vy = p_nc[i, 1] * invm_n[i]
        vz = p_nc[i, 2] * invm_n[i]
        x_nc[i, 0] += dt * vx
        x_nc[i, 1] += dt * vy
        x_nc[i, 2] += dt * vz
        v2_n[i] = vx * vx + vy * vy + vz * vz
    if n == 0:
        return 0.0, -1
    k = np.argmax(v2_n)
    return v2_n[k], k


@njit(cache=True)
def kinetic(p_nc, invm_n):
    e = 0.0
    for i in range(p_nc.shape[0]):
        e += 0.5 * (p_nc[i, 0] ** 2 + p_nc[i, 1] ** 2 + p_nc[i, 2] ** 2) * invm_n[i]
    return e
