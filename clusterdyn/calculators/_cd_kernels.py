"""numba kernels of the Cluster Dynamics pair loop.

Every kernel walks a half Verlet list (clusterdyn.neighbors) in fixed chunks
of particles; chunk k accumulates into its own buffer ``f_knc[k]`` and the
buffers are summed in a fixed order, so results are deterministic for a given
thread count (bit-identical restarts) and no two threads write one row.

Variants are separate module-level kernels (cached on disk by numba): the
conservative loop (:func:`cd_forces`), the same loop with per-particle
energies and virials (:func:`cd_forces_per_particle`) and the fused
conservative + pair-damping loop of the dynamics (:func:`cd_forces_damped`).
A run without damping never executes a damping instruction.

Table layout (potentials.build_tables): ``coef[a, b, k, 0:4]`` cubic
coefficients of the shifted pair energy in bin k; ``meta[a, b]`` =
(r_min, 1/h, cutoff^2, r_min^2, 1/r0_ab^2, E(cutoff), r0_ab^2).

``attraction="initial"`` (physics.md 1.5): with ``initial_only`` set, a pair
not listed in ``bonds_nk`` (partner ids bonded at set-up, -1 padded, one row
per particle) only repels: zero force beyond r0_ab and energy
``E(r) - E(r0_ab)`` inside, so it stays conservative.
"""

import numba
import numpy as np
from numba import njit, prange


@njit(inline="always")
def _table(r, coef, meta, a, b):
    """(E, f) of the pair law of types (a, b) at r (f > 0 repulsive)."""
    x = (r - meta[a, b, 0]) * meta[a, b, 1]
    k = int(x)
    nb = coef.shape[2]
    if k >= nb:
        k = nb - 1
    t = x - k
    c0 = coef[a, b, k, 0]
    c1 = coef[a, b, k, 1]
    c2 = coef[a, b, k, 2]
    c3 = coef[a, b, k, 3]
    e = c0 + t * (c1 + t * (c2 + t * c3))
    de = c1 + t * (2.0 * c2 + 3.0 * t * c3)
    return e, -de * meta[a, b, 1]


@njit(inline="always")
def _bonded(bonds_nk, i, jid):
    for k in range(bonds_nk.shape[1]):
        b = bonds_nk[i, k]
        if b == jid:
            return True
        if b < 0:
            return False
    return False


@njit(cache=True)
def chunk_bounds(first_n, nchunks):
    """Split particles into nchunks ranges of about equal pair counts."""
    n = first_n.shape[0] - 1
    b = np.zeros(nchunks + 1, np.int64)
    total = first_n[n]
    i = 0
    for k in range(1, nchunks):
        target = total * k // nchunks
        while i < n and first_n[i] < target:
            i += 1
        b[k] = i
    b[nchunks] = n
    for k in range(1, nchunks + 1):
        if b[k] < b[k - 1]:
            b[k] = b[k - 1]
    return b


@njit(cache=True, parallel=True)
def reduce_chunks(f_knc, out_nc):
    """out = sum over chunks in fixed order (deterministic)."""
    nk = f_knc.shape[0]
    n = f_knc.shape[1]
    for i in prange(n):
        for c in range(3):
            s = f_knc[0, i, c]
            for k in range(1, nk):
                s += f_knc[k, i, c]
            out_nc[i, c] = s


@njit(inline="always")
def _close(stat_k, k, r2n, i, j):
    # track the smallest r^2/r0_ab^2 of the chunk and its pair
    if r2n < stat_k[k, 1]:
        stat_k[k, 1] = r2n
        stat_k[k, 2] = i
        stat_k[k, 3] = j


@njit(cache=True, parallel=True)
def cd_forces(wpos_nc, type_n, first_n, j_p, img_p, image_sc, coef, meta, bounds_k,
              f_knc, stat_k, initial_only, bonds_nk, id_n, virial_k6):
    """Conservative pair forces, total energy and virial.

    Parameters
    ----------
    wpos_nc : (N, 3) float64     positions + wrap offsets, Angstrom
    type_n : (N,) int64          material id
    first_n, j_p, img_p, image_sc: half Verlet list (CSR)
    coef, meta : pair tables
    bounds_k : (K+1,) int64      chunk boundaries over particles
    f_knc : (K, N, 3) float64    out: per-chunk forces, eV/Angstrom
    stat_k : (K, 5) float64      out: [energy, min r^2/r0^2, i, j, n_close]
    initial_only : bool          attraction only between pairs bonded at set-up
    bonds_nk, id_n : int64       set-up partner ids per particle, particle ids (empty if unused)
    virial_k6 : (K, 6) float64   out: pair virial sum (xx yy zz yz xz xy), eV
    """
    nk = bounds_k.shape[0] - 1
    for k in prange(nk):
        f = f_knc[k]
        f[:, :] = 0.0
        energy = 0.0
        vxx = 0.0
        vyy = 0.0
        vzz = 0.0
        vyz = 0.0
        vxz = 0.0
        vxy = 0.0
        stat_k[k, 1] = 1e300
        stat_k[k, 2] = -1.0
        stat_k[k, 3] = -1.0
        nclose = 0
        for i in range(bounds_k[k], bounds_k[k + 1]):
            a = type_n[i]
            xi = wpos_nc[i, 0]
            yi = wpos_nc[i, 1]
            zi = wpos_nc[i, 2]
            fxi = 0.0
            fyi = 0.0
            fzi = 0.0
            for p in range(first_n[i], first_n[i + 1]):
                j = j_p[p]
                s = img_p[p]
                dx = wpos_nc[j, 0] + image_sc[s, 0] - xi
                dy = wpos_nc[j, 1] + image_sc[s, 1] - yi
                dz = wpos_nc[j, 2] + image_sc[s, 2] - zi
                r2 = dx * dx + dy * dy + dz * dz
                b = type_n[j]
                if not r2 < meta[a, b, 2]:
                    continue
                _close(stat_k, k, r2 * meta[a, b, 4], i, j)
                if r2 < meta[a, b, 3]:
                    nclose += 1
                    continue
                free = False
                if initial_only:
                    free = not _bonded(bonds_nk, i, id_n[j])
                    if free and r2 >= meta[a, b, 6]:
                        continue
                r = np.sqrt(r2)
                e, fr = _table(r, coef, meta, a, b)
                if free:
                    e += meta[a, b, 5]
                energy += e
                s_ = fr / r
                fx = s_ * dx
                fy = s_ * dy
                fz = s_ * dz
                fxi -= fx
                fyi -= fy
                fzi -= fz
                f[j, 0] += fx
                f[j, 1] += fy
                f[j, 2] += fz
                vxx -= fx * dx
                vyy -= fy * dy
                vzz -= fz * dz
                vyz -= fy * dz
                vxz -= fx * dz
                vxy -= fx * dy
            f[i, 0] += fxi
            f[i, 1] += fyi
            f[i, 2] += fzi
        stat_k[k, 0] = energy
        stat_k[k, 4] = nclose
        virial_k6[k, 0] = vxx
        virial_k6[k, 1] = vyy
        virial_k6[k, 2] = vzz
        virial_k6[k, 3] = vyz
        virial_k6[k, 4] = vxz
        virial_k6[k, 5] = vxy


@njit(cache=True, parallel=True)
def cd_forces_per_particle(wpos_nc, type_n, first_n, j_p, img_p, image_sc, coef, meta, bounds_k,
                           f_knc, stat_k, initial_only, bonds_nk, id_n, virial_k6, e_kn, w_kn6):
    """:func:`cd_forces` plus per-particle energies ``e_kn`` (eV) and virials ``w_kn6`` (eV).

    Each pair gives half its energy and half its virial to each partner.
    """
    nk = bounds_k.shape[0] - 1
    for k in prange(nk):
        f = f_knc[k]
        f[:, :] = 0.0
        e_n = e_kn[k]
        e_n[:] = 0.0
        w = w_kn6[k]
        w[:, :] = 0.0
        energy = 0.0
        stat_k[k, 1] = 1e300
        stat_k[k, 2] = -1.0
        stat_k[k, 3] = -1.0
        nclose = 0
        for i in range(bounds_k[k], bounds_k[k + 1]):
            a = type_n[i]
            for p in range(first_n[i], first_n[i + 1]):
                j = j_p[p]
                s = img_p[p]
                dx = wpos_nc[j, 0] + image_sc[s, 0] - wpos_nc[i, 0]
                dy = wpos_nc[j, 1] + image_sc[s, 1] - wpos_nc[i, 1]
                dz = wpos_nc[j, 2] + image_sc[s, 2] - wpos_nc[i, 2]
                r2 = dx * dx + dy * dy + dz * dz
                b = type_n[j]
                if not r2 < meta[a, b, 2]:
                    continue
                _close(stat_k, k, r2 * meta[a, b, 4], i, j)
                if r2 < meta[a, b, 3]:
                    nclose += 1
                    continue
                free = False
                if initial_only:
                    free = not _bonded(bonds_nk, i, id_n[j])
                    if free and r2 >= meta[a, b, 6]:
                        continue
                r = np.sqrt(r2)
                e, fr = _table(r, coef, meta, a, b)
                if free:
                    e += meta[a, b, 5]
                energy += e
                e_n[i] += 0.5 * e
                e_n[j] += 0.5 * e
                s_ = fr / r
                fx = s_ * dx
                fy = s_ * dy
                fz = s_ * dz
                f[i, 0] -= fx
                f[i, 1] -= fy
                f[i, 2] -= fz
                f[j, 0] += fx
                f[j, 1] += fy
                f[j, 2] += fz
                hxx = -0.5 * fx * dx
                hyy = -0.5 * fy * dy
                hzz = -0.5 * fz * dz
                hyz = -0.5 * fy * dz
                hxz = -0.5 * fx * dz
                hxy = -0.5 * fx * dy
                w[i, 0] += hxx
                w[i, 1] += hyy
                w[i, 2] += hzz
                w[i, 3] += hyz
                w[i, 4] += hxz
                w[i, 5] += hxy
                w[j, 0] += hxx
                w[j, 1] += hyy
                w[j, 2] += hzz
                w[j, 3] += hyz
                w[j, 4] += hxz
                w[j, 5] += hxy
        stat_k[k, 0] = energy
        stat_k[k, 4] = nclose
        for c in range(6):
            virial_k6[k, c] = 0.0
        for i in range(w.shape[0]):
            for c in range(6):
                virial_k6[k, c] += w[i, c]


@njit(cache=True, parallel=True)
def cd_forces_damped(wpos_nc, type_n, first_n, j_p, img_p, image_sc, coef, meta, bounds_k,
                     f_knc, stat_k, initial_only, bonds_nk, id_n, p_nc, invm_n, eta_tt):
    """Conservative forces plus the pair damping of CD eq. (6).

    Damping on i from j: ``-eta_ab (v_i - v_j)`` with ``v = p/m`` and the
    opposite on j, for pairs within the cutoff (momentum conserved exactly).
    ``eta_tt[a, b] = 2 m_a m_b/(m_a + m_b) (Gamma_a + Gamma_b)/2`` (amu/time).
    """
    nk = bounds_k.shape[0] - 1
    for k in prange(nk):
        f = f_knc[k]
        f[:, :] = 0.0
        energy = 0.0
        stat_k[k, 1] = 1e300
        stat_k[k, 2] = -1.0
        stat_k[k, 3] = -1.0
        nclose = 0
        for i in range(bounds_k[k], bounds_k[k + 1]):
            a = type_n[i]
            xi = wpos_nc[i, 0]
            yi = wpos_nc[i, 1]
            zi = wpos_nc[i, 2]
            vxi = p_nc[i, 0] * invm_n[i]
            vyi = p_nc[i, 1] * invm_n[i]
            vzi = p_nc[i, 2] * invm_n[i]
            fxi = 0.0
            fyi = 0.0
            fzi = 0.0
            for p in range(first_n[i], first_n[i + 1]):
                j = j_p[p]
                s = img_p[p]
                dx = wpos_nc[j, 0] + image_sc[s, 0] - xi
                dy = wpos_nc[j, 1] + image_sc[s, 1] - yi
                dz = wpos_nc[j, 2] + image_sc[s, 2] - zi
                r2 = dx * dx + dy * dy + dz * dz
                b = type_n[j]
                if not r2 < meta[a, b, 2]:
                    continue
                _close(stat_k, k, r2 * meta[a, b, 4], i, j)
                if r2 < meta[a, b, 3]:
                    nclose += 1
                    continue
                free = False
                if initial_only:
                    free = not _bonded(bonds_nk, i, id_n[j])
                    if free and r2 >= meta[a, b, 6]:
                        continue
                r = np.sqrt(r2)
                e, fr = _table(r, coef, meta, a, b)
                if free:
                    e += meta[a, b, 5]
                energy += e
                s_ = fr / r
                eta = eta_tt[a, b]
                fx = s_ * dx + eta * (vxi - p_nc[j, 0] * invm_n[j])
                fy = s_ * dy + eta * (vyi - p_nc[j, 1] * invm_n[j])
                fz = s_ * dz + eta * (vzi - p_nc[j, 2] * invm_n[j])
                fxi -= fx
                fyi -= fy
                fzi -= fz
                f[j, 0] += fx
                f[j, 1] += fy
                f[j, 2] += fz
            f[i, 0] += fxi
            f[i, 1] += fyi
            f[i, 2] += fzi
        stat_k[k, 0] = energy
        stat_k[k, 4] = nclose
