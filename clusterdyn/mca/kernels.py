"""numba kernels of the MCA force evaluation (docs/theory.md 2.2-2.5).

Naming (shape suffixes): ``_n`` per automaton, ``_p`` per pair, ``_p2`` per
pair side (0: side of automaton i, 1: side of j), ``_c`` Cartesian.
Pairs are stored once (i < j by id); the separation is
``d = x_j - x_i`` (minimum image across periodic axes), ``n = d / r``.

Per-side values are the specific normal force ``sigma`` (tension positive)
and the specific tangential force ``tau`` (a vector in the contact plane, in
the *pair* convention: the tangential force on automaton i per unit area).
The force on i is ``S (sigma_bar n + tau_bar)`` with the stiffness-weighted
means over the two sides, the force on j its opposite: linear and angular momentum are
conserved pair by pair.

All kernels are module-level ``@njit(cache=True)``; the loops over pairs and automata are
``prange`` loops (``parallel=True``; the thread count is :func:`clusterdyn.parallel.use_threads`'s,
one thread below 8 192 automata) in which every item writes only its own rows: per-automaton sums
go through the incidence lists ``first_n/side_p/side_s`` (CSR: automaton i
owns sides ``k in range(first_n[i], first_n[i+1])`` = pair ``side_p[k]``,
side ``side_s[k]``) in a fixed order, so the results are the same bits on any thread count.
The calculator's evaluation is one call, :func:`trial_forces`, which runs the passes of the
single kernels (:func:`pair_geometry`, :func:`split_strain`, :func:`volume_change`,
:func:`trial_linked`, :func:`trial_contact`, :func:`automaton_sums`) with their operations.
"""

import math

import numpy as np
from numba import njit, prange

from ..neighbors.image import image_component


@njit(cache=True)
def _rot3(vx, vy, vz, px, py, pz):
    """R(phi) v by Rodrigues (phi a rotation vector); returns a tuple."""
    ang = math.sqrt(px * px + py * py + pz * pz)
    if ang < 1e-300:
        return vx, vy, vz
    kx = px / ang
    ky = py / ang
    kz = pz / ang
    c = math.cos(ang)
    s = math.sin(ang)
    kv = (kx * vx + ky * vy + kz * vz) * (1.0 - c)
    return (vx * c + (ky * vz - kz * vy) * s + kx * kv,
            vy * c + (kz * vx - kx * vz) * s + ky * kv,
            vz * c + (kx * vy - ky * vx) * s + kz * kv)


@njit(cache=True, inline="always")
def _rot_prep(px, py, pz):
    """The constants of R(phi) (Rodrigues, as :func:`_rot3`): (kx, ky, kz, cos, sin, identity)."""
    ang = math.sqrt(px * px + py * py + pz * pz)
    if ang < 1e-300:
        return 0.0, 0.0, 0.0, 1.0, 0.0, True
    return px / ang, py / ang, pz / ang, math.cos(ang), math.sin(ang), False


@njit(cache=True, inline="always")
def _rot_apply(vx, vy, vz, kx, ky, kz, c, s, ident):
    """R v from :func:`_rot_prep`'s constants: the same operations as :func:`_rot3`, same bits."""
    if ident:
        return vx, vy, vz
    kv = (kx * vx + ky * vy + kz * vz) * (1.0 - c)
    return (vx * c + (ky * vz - kz * vy) * s + kx * kv,
            vy * c + (kz * vx - kx * vz) * s + ky * kv,
            vz * c + (kx * vy - ky * vx) * s + kz * kv)


@njit(cache=True, inline="always")
def _rot_one(i, theta_nc, thlast_nc, rot_n9):
    """Item i of :func:`rotation_constants`."""
    px = theta_nc[i, 0] - thlast_nc[i, 0]
    py = theta_nc[i, 1] - thlast_nc[i, 1]
    pz = theta_nc[i, 2] - thlast_nc[i, 2]
    kx, ky, kz, c, s, ident = _rot_prep(px, py, pz)
    rot_n9[i, 0] = px
    rot_n9[i, 1] = py
    rot_n9[i, 2] = pz
    rot_n9[i, 3] = kx
    rot_n9[i, 4] = ky
    rot_n9[i, 5] = kz
    rot_n9[i, 6] = c
    rot_n9[i, 7] = s
    rot_n9[i, 8] = 1.0 if ident else 0.0


@njit(cache=True, parallel=True)
def rotation_constants(theta_nc, thlast_nc, rot_n9):
    """Per automaton, its rotation since the last commit ``phi = theta - theta_last`` (0:3) and
    the constants of R(phi) (3:9, :func:`_rot_prep`; the last 1.0 where R is the identity):
    computed once per automaton instead of once per pair side."""
    for i in prange(theta_nc.shape[0]):
        _rot_one(i, theta_nc, thlast_nc, rot_n9)


@njit(cache=True, inline="always")
def _rot_row(vx, vy, vz, rot_n9, i):
    return _rot_apply(vx, vy, vz, rot_n9[i, 3], rot_n9[i, 4], rot_n9[i, 5], rot_n9[i, 6],
                      rot_n9[i, 7], rot_n9[i, 8] != 0.0)


@njit(cache=True, inline="always")
def _geometry_one(p, pos_nc, rot_n9, i_p, j_p, dlast_pc, q0_p2, G_n, box_c, periodic_c, tau_p2c,
                  d_pc, r_p, dr_p, arm_p2, dtau_pc, taurot_p2c):
    """Pair p of :func:`pair_geometry`."""
    i = i_p[p]
    j = j_p[p]
    dx = pos_nc[j, 0] - pos_nc[i, 0]
    dy = pos_nc[j, 1] - pos_nc[i, 1]
    dz = pos_nc[j, 2] - pos_nc[i, 2]
    if periodic_c[0]:
        dx = image_component(dx, box_c[0])
    if periodic_c[1]:
        dy = image_component(dy, box_c[1])
    if periodic_c[2]:
        dz = image_component(dz, box_c[2])
    r = math.sqrt(dx * dx + dy * dy + dz * dz)
    lx = dlast_pc[p, 0]
    ly = dlast_pc[p, 1]
    lz = dlast_pc[p, 2]
    rl = math.sqrt(lx * lx + ly * ly + lz * lz)
    nlx = lx / rl
    nly = ly / rl
    nlz = lz / rl
    nx = dx / r
    ny = dy / r
    nz = dz / r
    d_pc[p, 0] = dx
    d_pc[p, 1] = dy
    d_pc[p, 2] = dz
    r_p[p] = r
    dr_p[p] = r - rl
    qs = q0_p2[p, 0] + q0_p2[p, 1]
    ai = rl * q0_p2[p, 0] / qs
    aj = rl * q0_p2[p, 1] / qs
    arm_p2[p, 0] = r * q0_p2[p, 0] / qs
    arm_p2[p, 1] = r * q0_p2[p, 1] / qs
    pix = rot_n9[i, 0]
    piy = rot_n9[i, 1]
    piz = rot_n9[i, 2]
    pjx = rot_n9[j, 0]
    pjy = rot_n9[j, 1]
    pjz = rot_n9[j, 2]
    rix, riy, riz = _rot_row(nlx, nly, nlz, rot_n9, i)
    rjx, rjy, rjz = _rot_row(nlx, nly, nlz, rot_n9, j)
    ux = dx - ai * rix - aj * rjx
    uy = dy - ai * riy - aj * rjy
    uz = dz - ai * riz - aj * rjz
    un = ux * nx + uy * ny + uz * nz
    gi = G_n[i]
    gj = G_n[j]
    coef = 2.0 * gi * gj / (ai * gj + aj * gi)
    dtau_pc[p, 0] = coef * (ux - un * nx)
    dtau_pc[p, 1] = coef * (uy - un * ny)
    dtau_pc[p, 2] = coef * (uz - un * nz)
    # rotate the stored tangential forces: minimal rotation n_last -> n, then twist about n
    ax = nly * nz - nlz * ny
    ay = nlz * nx - nlx * nz
    az = nlx * ny - nly * nx
    sn = math.sqrt(ax * ax + ay * ay + az * az)
    cs = nlx * nx + nly * ny + nlz * nz
    if sn > 0.0:
        f = math.atan2(sn, cs) / sn
        ax *= f
        ay *= f
        az *= f
    tw = 0.5 * ((pix + pjx) * nx + (piy + pjy) * ny + (piz + pjz) * nz)
    # the two rotations' constants once for both sides (the same numbers as per side)
    akx, aky, akz, ac, as_, aid = _rot_prep(ax, ay, az)
    tkx, tky, tkz, tc, ts, tid = _rot_prep(tw * nx, tw * ny, tw * nz)
    for s in range(2):
        tx, ty, tz = _rot_apply(tau_p2c[p, s, 0], tau_p2c[p, s, 1], tau_p2c[p, s, 2],
                                akx, aky, akz, ac, as_, aid)
        tx, ty, tz = _rot_apply(tx, ty, tz, tkx, tky, tkz, tc, ts, tid)
        tn = tx * nx + ty * ny + tz * nz
        taurot_p2c[p, s, 0] = tx - tn * nx
        taurot_p2c[p, s, 1] = ty - tn * ny
        taurot_p2c[p, s, 2] = tz - tn * nz


@njit(cache=True, parallel=True)
def pair_geometry(pos_nc, rot_n9, i_p, j_p, dlast_pc, q0_p2, G_n, box_c, periodic_c,
                  tau_p2c, d_pc, r_p, dr_p, arm_p2, dtau_pc, taurot_p2c):
    """Separation, elongation and tangential increment of every pair since the last commit.

    ``rot_n9``: :func:`rotation_constants` of the automata.
    Outputs: ``d_pc`` separation, ``r_p`` distance, ``dr_p = r - r_last``,
    ``arm_p2`` lever arms (``r`` split as q0: they sum to r, so torques conserve angular momentum),
    ``dtau_pc`` tangential increment ``2 G_i G_j du_t / (a_i G_j + a_j G_i)``
    (docs/theory.md 2.4) from the objective relative displacement of the two
    material points that were at the contact point at the last commit,
    ``du = d - (a_i R_i + a_j R_j) n_last`` (zero for any rigid motion),
    ``taurot_p2c`` the stored tangential forces rotated with the pair (minimal
    rotation n_last -> n, then the mean spin about n).  Pairs in parallel (each writes its rows).
    """
    for p in prange(i_p.shape[0]):
        _geometry_one(p, pos_nc, rot_n9, i_p, j_p, dlast_pc, q0_p2, G_n, box_c, periodic_c, tau_p2c,
                      d_pc, r_p, dr_p, arm_p2, dtau_pc, taurot_p2c)


@njit(cache=True, inline="always")
def _split_one(p, dr_p, q0_p2, A_n, i_p, j_p, linked_p, dB_n, deps_p2):
    """Pair p of :func:`split_strain`."""
    if linked_p[p] == 0:
        deps_p2[p, 0] = 0.0
        deps_p2[p, 1] = 0.0
        return
    i = i_p[p]
    j = j_p[p]
    qi = q0_p2[p, 0]
    qj = q0_p2[p, 1]
    den = A_n[i] * qj + A_n[j] * qi
    deps_p2[p, 0] = (A_n[j] * dr_p[p] + qj * (dB_n[j] - dB_n[i])) / den
    deps_p2[p, 1] = (A_n[i] * dr_p[p] + qi * (dB_n[i] - dB_n[j])) / den


@njit(cache=True, parallel=True)
def split_strain(dr_p, q0_p2, A_n, i_p, j_p, linked_p, dB_n, deps_p2):
    """Split the elongation between the two automata (docs/theory.md 2.4).

    ``d eps_i = [A_j dr + q0_j (dB_j - dB_i)] / (A_i q0_j + A_j q0_i)`` with
    ``A = 2G`` and ``dB = (1 - 2G/3K) dP``; unlinked pairs get zero.  The
    calculator passes ``dB = 0``: the mean-stress terms are balanced in the pair
    force instead (stiffness-weighted mean of the sides).  The lagged dB
    correction of docs/theory.md 2.4 is a Jacobi iteration on P whose gain on the
    checkerboard mode is about ``z (1 - 2G/3K) K / 4G`` (z neighbours): it
    diverged for nu >= 0.3 in our tests, so it is not used (docs/mca.md).
    """
    for p in prange(i_p.shape[0]):
        _split_one(p, dr_p, q0_p2, A_n, i_p, j_p, linked_p, dB_n, deps_p2)


@njit(cache=True, inline="always")
def _volume_one(i, deps_p2, q0_p2, S_p, first_n, side_p, side_s, K_n, lk_n, omega_n, dP_n, dB_n):
    """Item i of :func:`volume_change`."""
    dv = 0.0
    for k in range(first_n[i], first_n[i + 1]):
        p = side_p[k]
        s = side_s[k]
        dv += q0_p2[p, s] * deps_p2[p, s] * S_p[p]
    dP_n[i] = K_n[i] * dv / omega_n[i]
    dB_n[i] = lk_n[i] * dP_n[i]


@njit(cache=True, parallel=True)
def volume_change(deps_p2, q0_p2, S_p, first_n, side_p, side_s, K_n, lk_n, omega_n, dP_n, dB_n):
    """Mean-stress increment of every automaton: ``dP = K sum_j dq_ij S_ij / Omega`` (MCA 8-9)."""
    for i in prange(first_n.shape[0] - 1):
        _volume_one(i, deps_p2, q0_p2, S_p, first_n, side_p, side_s, K_n, lk_n, omega_n, dP_n, dB_n)


@njit(cache=True, inline="always")
def _trial_linked_one(p, i_p, j_p, linked_p, sig_p2, deps_p2, dB_n, A_n, D_p, taurot_p2c, dtau_pc,
                      sigt_p2, taut_p2c):
    """Pair p of :func:`trial_linked`."""
    if linked_p[p] == 0:
        return
    i = i_p[p]
    j = j_p[p]
    f = 1.0 - D_p[p]
    sigt_p2[p, 0] = sig_p2[p, 0] + f * (A_n[i] * deps_p2[p, 0] + dB_n[i])
    sigt_p2[p, 1] = sig_p2[p, 1] + f * (A_n[j] * deps_p2[p, 1] + dB_n[j])
    for s in range(2):
        for a in range(3):
            taut_p2c[p, s, a] = taurot_p2c[p, s, a] + f * dtau_pc[p, a]


@njit(cache=True, parallel=True)
def trial_linked(i_p, j_p, linked_p, sig_p2, deps_p2, dB_n, A_n, D_p, taurot_p2c, dtau_pc,
                 sigt_p2, taut_p2c):
    """Elastic predictor of linked pairs: ``d sigma = (1-D)(2G d eps + (1-2G/3K) dP)``, ``d tau = (1-D) dtau``."""
    for p in prange(i_p.shape[0]):
        _trial_linked_one(p, i_p, j_p, linked_p, sig_p2, deps_p2, dB_n, A_n, D_p, taurot_p2c,
                          dtau_pc, sigt_p2, taut_p2c)


@njit(cache=True, inline="always")
def _trial_contact_one(p, i_p, j_p, linked_p, d_pc, r_p, r0_p, q0_p2, M_n, mu_p, taurot_p2c,
                       dtau_pc, sigt_p2, taut_p2c):
    """Pair p of :func:`trial_contact`."""
    if linked_p[p] != 0:
        return
    i = i_p[p]
    j = j_p[p]
    h = r_p[p] - r0_p[p]
    if h >= 0.0:
        sigt_p2[p, 0] = 0.0
        sigt_p2[p, 1] = 0.0
        for s in range(2):
            for a in range(3):
                taut_p2c[p, s, a] = 0.0
        return
    Mp = r0_p[p] / (q0_p2[p, 0] / M_n[i] + q0_p2[p, 1] / M_n[j])
    sg = Mp * h / r0_p[p]
    sigt_p2[p, 0] = sg
    sigt_p2[p, 1] = sg
    lim = mu_p[p] * abs(sg)
    for s in range(2):
        t2 = 0.0
        for a in range(3):
            v = taurot_p2c[p, s, a] + dtau_pc[p, a]
            taut_p2c[p, s, a] = v
            t2 += v * v
        t = math.sqrt(t2)
        if t > lim:
            sc = lim / t
            for a in range(3):
                taut_p2c[p, s, a] *= sc


@njit(cache=True, parallel=True)
def trial_contact(i_p, j_p, linked_p, d_pc, r_p, r0_p, q0_p2, M_n, mu_p, taurot_p2c, dtau_pc,
                  sigt_p2, taut_p2c):
    """Unlinked pairs: repulsion only in contact (``h = r - r0 < 0``) and Coulomb friction.

    ``sigma = M_p h / r0`` with ``M_p = r0 / (q0_i/M_i + q0_j/M_j)``,
    ``M = K + 4G/3`` (the two half-automata in series, uniaxial strain);
    tangential force incremental, capped at ``mu |sigma|``; zero when apart.
    """
    for p in prange(i_p.shape[0]):
        _trial_contact_one(p, i_p, j_p, linked_p, d_pc, r_p, r0_p, q0_p2, M_n, mu_p, taurot_p2c,
                           dtau_pc, sigt_p2, taut_p2c)


@njit(cache=True, parallel=True)
def automaton_sums(i_p, j_p, d_pc, r_p, S_p, q0_p2, arm_p2, sig_p2, tau_p2c, first_n, side_p, side_s,
                   omega_n, G_n, K_n, n_pc, g_pc, c_pc, f_nc, t_nc, s_ncc, e_n):
    """Forces, torques, Love-Weber stress and elastic energy of every automaton.

    ``F_i = sum_j S (sigma_bar n_ij + tau_bar)`` with the stiffness-weighted mean over the two
    sides, ``x_bar = w_i x_ij + w_j x_ji``, ``w_i = q_i G_j / (q_i G_j + q_j G_i)`` (1/2 for equal
    automata): with it the normal force is the derivative of the elastic energy
    ``sum_i [sum_j G_i q_ij S_ij eps_ij^2 + lambda_i dOmega_i^2 / (2 Omega_i)]``,
    ``T_i = sum_j q_ij S n_ij x tau_bar`` (MCA 6);
    ``sigma^i = (1/Omega_i) sum_j q_ij S (sigma_ij n + tau_ij) (x) n`` (symmetrised);
    ``e_i = Omega_i (s:s / 4G + P^2 / 2K)`` from that tensor (linear elasticity).

    The per-pair parts once per pair (:func:`_pair_force_one`, buffers ``n_pc``, ``g_pc``, ``c_pc``),
    then gathered per automaton in its side order (:func:`_gather_one`), as :func:`trial_forces` does.
    """
    for p in prange(i_p.shape[0]):
        _pair_force_one(p, i_p, j_p, d_pc, r_p, S_p, q0_p2, sig_p2, tau_p2c, G_n, n_pc, g_pc, c_pc)
    for i in prange(first_n.shape[0] - 1):
        _gather_one(i, S_p, q0_p2, arm_p2, sig_p2, tau_p2c, first_n, side_p, side_s, omega_n, G_n, K_n,
                    n_pc, g_pc, c_pc, f_nc, t_nc, s_ncc, e_n)


@njit(cache=True, parallel=True)
def pair_damping(vel_nc, om_nc, i_p, j_p, d_pc, r_p, arm_p2, c_p, f_nc_out, t_nc_out,
                 first_n, side_p, side_s):
    """Viscous damping of the relative velocity at the contact point of every pair.

    ``f = c_p v_rel`` on i (``-f`` on j), ``v_rel = (V_j - a_j omega_j x n) - (V_i + a_i omega_i x n)``;
    torques ``a n x f`` on both: momentum and angular momentum conserved.
    Writes per automaton (``f_nc_out``, ``t_nc_out`` overwritten).
    """
    for i in prange(first_n.shape[0] - 1):
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for k in range(first_n[i], first_n[i + 1]):
            p = side_p[k]
            s = side_s[k]
            a_ = i_p[p]
            b_ = j_p[p]
            r = r_p[p]
            n0 = d_pc[p, 0] / r
            n1 = d_pc[p, 1] / r
            n2 = d_pc[p, 2] / r
            ai = arm_p2[p, 0]
            aj = arm_p2[p, 1]
            # omega x n
            wi0 = om_nc[a_, 1] * n2 - om_nc[a_, 2] * n1
            wi1 = om_nc[a_, 2] * n0 - om_nc[a_, 0] * n2
            wi2 = om_nc[a_, 0] * n1 - om_nc[a_, 1] * n0
            wj0 = om_nc[b_, 1] * n2 - om_nc[b_, 2] * n1
            wj1 = om_nc[b_, 2] * n0 - om_nc[b_, 0] * n2
            wj2 = om_nc[b_, 0] * n1 - om_nc[b_, 1] * n0
            v0 = (vel_nc[b_, 0] - aj * wj0) - (vel_nc[a_, 0] + ai * wi0)
            v1 = (vel_nc[b_, 1] - aj * wj1) - (vel_nc[a_, 1] + ai * wi1)
            v2 = (vel_nc[b_, 2] - aj * wj2) - (vel_nc[a_, 2] + ai * wi2)
            c = c_p[p]
            f0 = c * v0
            f1 = c * v1
            f2 = c * v2
            sgn = 1.0 if s == 0 else -1.0
            fx += sgn * f0
            fy += sgn * f1
            fz += sgn * f2
            arm = arm_p2[p, s]
            tx += arm * (n1 * f2 - n2 * f1)
            ty += arm * (n2 * f0 - n0 * f2)
            tz += arm * (n0 * f1 - n1 * f0)
        f_nc_out[i, 0] = fx
        f_nc_out[i, 1] = fy
        f_nc_out[i, 2] = fz
        t_nc_out[i, 0] = tx
        t_nc_out[i, 1] = ty
        t_nc_out[i, 2] = tz


@njit(cache=True)
def incidence(n, i_p, j_p):
    """CSR of pair sides per automaton: (first_n, side_p, side_s)."""
    cnt = np.zeros(n + 1, np.int64)
    for p in range(i_p.shape[0]):
        cnt[i_p[p] + 1] += 1
        cnt[j_p[p] + 1] += 1
    for i in range(n):
        cnt[i + 1] += cnt[i]
    fill = cnt[:-1].copy()
    side_p = np.empty(cnt[n], np.int64)
    side_s = np.empty(cnt[n], np.int8)
    for p in range(i_p.shape[0]):
        a = i_p[p]
        side_p[fill[a]] = p
        side_s[fill[a]] = 0
        fill[a] += 1
        b = j_p[p]
        side_p[fill[b]] = p
        side_s[fill[b]] = 1
        fill[b] += 1
    return cnt, side_p, side_s


@njit(cache=True, parallel=True)
def pair_energy(sig_p2, tau_p2c, q0_p2, S_p, linked_p, P_n, first_n, side_p, side_s, omega_n,
                G_n, K_n, e_n):
    """Elastic energy of every automaton from its pair state (eV), the energy whose
    derivative the pair forces are (docs/mca.md, "Energy ledger"):

    ``e_i = sum_j q_ij S_ij [(sigma_ij - (lambda/K) P_i)^2 + |tau_ij|^2] / (4 G_i)
    + lambda P_i^2 Omega_i / (2 K_i^2)``, ``P_i`` the automaton's mean stress
    (from its volume change, accumulated by the dynamics), lambda = K - 2G/3: with ``sigma_ij = 2G eps_ij + (lambda/K) P_i``
    this is ``sum_j G q S eps^2 + lambda dOmega^2/(2 Omega)`` plus the tangential
    springs.  Linked pairs only (contacts carry no stored energy here).
    """
    for i in prange(first_n.shape[0] - 1):
        P = P_n[i]
        G = G_n[i]
        K = K_n[i]
        lam = K - 2.0 * G / 3.0
        c = lam / K
        e = 0.0
        for k in range(first_n[i], first_n[i + 1]):
            p = side_p[k]
            if linked_p[p] == 0:
                continue
            s = side_s[k]
            v = sig_p2[p, s] - c * P
            t2 = tau_p2c[p, s, 0] ** 2 + tau_p2c[p, s, 1] ** 2 + tau_p2c[p, s, 2] ** 2
            e += q0_p2[p, s] * S_p[p] * (v * v + t2)
        e_n[i] = e / (4.0 * G) + lam * P * P * omega_n[i] / (2.0 * K * K)


@njit(cache=True, parallel=True)
def log_volume(d_pc, q0_p2, S_p, linked_p, first_n, side_p, side_s, lnJ_n):
    """``ln sqrt(det B_i)``, ``B_i = sum_j q_ij S_ij d_ij (x) d_ij`` over the linked pairs of every
    automaton (large strain, docs/mca.md): under any affine motion of the neighbourhood,
    ``B -> F B F^T``, so the change of this number is exactly ``ln det F`` (an isochoric flow
    changes it by nothing at any strain, where the summed pair elongations change by O(strain^2)).
    NaN where the neighbourhood is flat (det B below 1e-9 of (tr B / 3)^3)."""
    for i in prange(first_n.shape[0] - 1):
        b00 = 0.0
        b01 = 0.0
        b02 = 0.0
        b11 = 0.0
        b12 = 0.0
        b22 = 0.0
        for k in range(first_n[i], first_n[i + 1]):
            p = side_p[k]
            if linked_p[p] == 0:
                continue
            w = q0_p2[p, side_s[k]] * S_p[p]
            x = d_pc[p, 0]
            y = d_pc[p, 1]
            z = d_pc[p, 2]
            b00 += w * x * x
            b01 += w * x * y
            b02 += w * x * z
            b11 += w * y * y
            b12 += w * y * z
            b22 += w * z * z
        det = (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
               + b02 * (b01 * b12 - b11 * b02))
        tr = (b00 + b11 + b22) / 3.0
        # a flat neighbourhood (all pairs in a plane, or none) has no volume: NaN (no sync)
        lnJ_n[i] = 0.5 * math.log(det) if det > 1e-9 * tr * tr * tr and tr > 0.0 else math.nan



@njit(cache=True, inline="always")
def _pair_force_one(p, i_p, j_p, d_pc, r_p, S_p, q0_p2, sig_p2, tau_p2c, G_n, n_pc, g_pc, c_pc):
    """The per-pair parts of :func:`automaton_sums`, computed once per pair (not once per side):
    ``n``, ``g = S (sigma_bar n + tau_bar)`` (the force on i; j gets ``-g``) and ``c = n x tau_bar``
    (the torque per lever arm and area), with its operations (the same bits)."""
    r = r_p[p]
    nx = d_pc[p, 0] / r
    ny = d_pc[p, 1] / r
    nz = d_pc[p, 2] / r
    S = S_p[p]
    gi = G_n[i_p[p]]
    gj = G_n[j_p[p]]
    wden = q0_p2[p, 0] * gj + q0_p2[p, 1] * gi
    w0 = q0_p2[p, 0] * gj / wden
    w1 = 1.0 - w0
    sb = w0 * sig_p2[p, 0] + w1 * sig_p2[p, 1]
    tbx = w0 * tau_p2c[p, 0, 0] + w1 * tau_p2c[p, 1, 0]
    tby = w0 * tau_p2c[p, 0, 1] + w1 * tau_p2c[p, 1, 1]
    tbz = w0 * tau_p2c[p, 0, 2] + w1 * tau_p2c[p, 1, 2]
    n_pc[p, 0] = nx
    n_pc[p, 1] = ny
    n_pc[p, 2] = nz
    g_pc[p, 0] = S * (sb * nx + tbx)
    g_pc[p, 1] = S * (sb * ny + tby)
    g_pc[p, 2] = S * (sb * nz + tbz)
    c_pc[p, 0] = ny * tbz - nz * tby
    c_pc[p, 1] = nz * tbx - nx * tbz
    c_pc[p, 2] = nx * tby - ny * tbx


@njit(cache=True, inline="always")
def _gather_one(i, S_p, q0_p2, arm_p2, sig_p2, tau_p2c, first_n, side_p, side_s, omega_n, G_n, K_n,
                n_pc, g_pc, c_pc, f_nc, t_nc, s_ncc, e_n):
    """Automaton i of :func:`automaton_sums` from the per-pair parts of :func:`_pair_force_one`, gathered in the
    automaton's side order (``(-1) (S X)`` is ``(-S) X`` exactly: the same bits)."""
    fx = 0.0
    fy = 0.0
    fz = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    s00 = 0.0
    s01 = 0.0
    s02 = 0.0
    s10 = 0.0
    s11 = 0.0
    s12 = 0.0
    s20 = 0.0
    s21 = 0.0
    s22 = 0.0
    for k in range(first_n[i], first_n[i + 1]):
        p = side_p[k]
        s = side_s[k]
        nx = n_pc[p, 0]
        ny = n_pc[p, 1]
        nz = n_pc[p, 2]
        S = S_p[p]
        if s == 0:
            fx += g_pc[p, 0]
            fy += g_pc[p, 1]
            fz += g_pc[p, 2]
        else:
            fx += -g_pc[p, 0]
            fy += -g_pc[p, 1]
            fz += -g_pc[p, 2]
        a = arm_p2[p, s] * S
        tx += a * c_pc[p, 0]
        ty += a * c_pc[p, 1]
        tz += a * c_pc[p, 2]
        w = q0_p2[p, s] * S
        sg = sig_p2[p, s]
        tv0 = sg * nx + tau_p2c[p, s, 0]
        tv1 = sg * ny + tau_p2c[p, s, 1]
        tv2 = sg * nz + tau_p2c[p, s, 2]
        s00 += w * tv0 * nx
        s01 += w * tv0 * ny
        s02 += w * tv0 * nz
        s10 += w * tv1 * nx
        s11 += w * tv1 * ny
        s12 += w * tv1 * nz
        s20 += w * tv2 * nx
        s21 += w * tv2 * ny
        s22 += w * tv2 * nz
    f_nc[i, 0] = fx
    f_nc[i, 1] = fy
    f_nc[i, 2] = fz
    t_nc[i, 0] = tx
    t_nc[i, 1] = ty
    t_nc[i, 2] = tz
    inv = 1.0 / omega_n[i]
    s_ncc[i, 0, 0] = 0.5 * (s00 + s00) * inv
    v = 0.5 * (s01 + s10) * inv
    s_ncc[i, 0, 1] = v
    s_ncc[i, 1, 0] = v
    v = 0.5 * (s02 + s20) * inv
    s_ncc[i, 0, 2] = v
    s_ncc[i, 2, 0] = v
    s_ncc[i, 1, 1] = 0.5 * (s11 + s11) * inv
    v = 0.5 * (s12 + s21) * inv
    s_ncc[i, 1, 2] = v
    s_ncc[i, 2, 1] = v
    s_ncc[i, 2, 2] = 0.5 * (s22 + s22) * inv
    P = (s_ncc[i, 0, 0] + s_ncc[i, 1, 1] + s_ncc[i, 2, 2]) / 3.0
    ss = 0.0
    for a in range(3):
        for b in range(3):
            dv = s_ncc[i, a, b] - (P if a == b else 0.0)
            ss += dv * dv
    e_n[i] = omega_n[i] * (ss / (4.0 * G_n[i]) + P * P / (2.0 * K_n[i]))


def _trial_forces(pos_nc, theta_nc, thlast_nc, i_p, j_p, first_n, side_p, side_s, dlast_pc, q0_p2,
                  S_p, linked_p, sig_p2, tau_p2c, D_p, r0_p, mu_p, G_n, K_n, A_n, lk_n, M_n, omega_n,
                  box_c, periodic_c, contacts, rot_n9, d_pc, r_p, dr_p, arm_p2, dtau_pc, taurot_p2c,
                  deps_p2, dB_n, dP_n, sigt_p2, taut_p2c, n_pc, g_pc, c_pc, f_nc, t_nc, s_ncc, e_n):
    """The whole trial evaluation (docs/theory.md 2.2-2.5) in one call, five passes: rotations
    (automata), geometry and strain split (pairs), volume change (automata), trial pair forces
    (pairs, with each pair's force and torque parts, ``n_pc, g_pc, c_pc``), sums gathered per
    automaton in its side order (automata).  Every item writes only its own rows, with the
    operations of the single kernels above (the same bits, on any thread count); ``dB_n`` is zero
    during the split (the calculator's choice, see :func:`split_strain`) and then the automata's
    increments."""
    n = theta_nc.shape[0]
    for i in prange(n):
        _rot_one(i, theta_nc, thlast_nc, rot_n9)
        dB_n[i] = 0.0
    for p in prange(i_p.shape[0]):
        _geometry_one(p, pos_nc, rot_n9, i_p, j_p, dlast_pc, q0_p2, G_n, box_c, periodic_c, tau_p2c,
                      d_pc, r_p, dr_p, arm_p2, dtau_pc, taurot_p2c)
        _split_one(p, dr_p, q0_p2, A_n, i_p, j_p, linked_p, dB_n, deps_p2)
    for i in prange(n):
        _volume_one(i, deps_p2, q0_p2, S_p, first_n, side_p, side_s, K_n, lk_n, omega_n, dP_n, dB_n)
    for p in prange(i_p.shape[0]):
        if linked_p[p] != 0:
            _trial_linked_one(p, i_p, j_p, linked_p, sig_p2, deps_p2, dB_n, A_n, D_p, taurot_p2c,
                              dtau_pc, sigt_p2, taut_p2c)
        elif contacts:
            _trial_contact_one(p, i_p, j_p, linked_p, d_pc, r_p, r0_p, q0_p2, M_n, mu_p, taurot_p2c,
                               dtau_pc, sigt_p2, taut_p2c)
        else:                              # without contacts an unlinked pair carries nothing
            sigt_p2[p, 0] = 0.0
            sigt_p2[p, 1] = 0.0
            for s in range(2):
                for a in range(3):
                    taut_p2c[p, s, a] = 0.0
        _pair_force_one(p, i_p, j_p, d_pc, r_p, S_p, q0_p2, sigt_p2, taut_p2c, G_n, n_pc, g_pc, c_pc)
    for i in prange(n):
        _gather_one(i, S_p, q0_p2, arm_p2, sigt_p2, taut_p2c, first_n, side_p, side_s, omega_n, G_n, K_n,
                    n_pc, g_pc, c_pc, f_nc, t_nc, s_ncc, e_n)


#: numba's parfor lowering of the loops ran faster on one thread than a plain serial jit of the
#: same source (measured 3.0 against 4.9 ms, 2 048 automata): one variant serves every count
trial_forces = njit(cache=True, parallel=True)(_trial_forces)


@njit(cache=True)
def max_linked_strain(r_p, r0_p, linked_p):
    """(largest ``|r - r0|/r0`` over the linked pairs, its pair), the first pair on ties; (NaN, -1)
    if any is NaN, (-1, -1) without linked pairs (as numpy's max/argmax over the linked pairs)."""
    m = -1.0
    k = -1
    for p in range(r_p.shape[0]):
        if linked_p[p] != 1:
            continue
        s = abs(r_p[p] - r0_p[p]) / r0_p[p]
        if s != s:
            return math.nan, -1
        if s > m:
            m = s
            k = p
    return m, k


# --------------------------------------------------------------------------------- the step's arithmetic
# MCADynamics.step's element-wise updates and energy sums in one pass each, with numpy's operations in
# numpy's order (the same bits as the array expressions they replace: tests/mca/test_step_kernels.py)

@njit(cache=True)
def half_kick(p_nc, w_nc, F_nc, T_nc, J_n, h):
    """``p += h F`` and ``w += h T / J`` (numpy's ``(h T) / J``), in place."""
    for i in range(p_nc.shape[0]):
        for a in range(3):
            p_nc[i, a] = p_nc[i, a] + h * F_nc[i, a]
            w_nc[i, a] = w_nc[i, a] + h * T_nc[i, a] / J_n[i]


@njit(cache=True)
def drift(p_nc, m_n, w_nc, dt, pos_nc, theta_nc, dx_nc, dth_nc):
    """``dx = dt (p / m)``, ``dth = dt w``; ``pos += dx``, ``theta += dth`` in place."""
    for i in range(p_nc.shape[0]):
        for a in range(3):
            dx = dt * (p_nc[i, a] / m_n[i])
            dx_nc[i, a] = dx
            pos_nc[i, a] = pos_nc[i, a] + dx
            dth = dt * w_nc[i, a]
            dth_nc[i, a] = dth
            theta_nc[i, a] = theta_nc[i, a] + dth


@njit(cache=True)
def _pairwise_block(a, b, c, s, n):
    """numpy's pairwise sum of a block of ``n <= 128`` elements ``(a + b) * c`` from flat index ``s``:
    in order below 8, else 8 partial sums combined as a tree, then the remainder in order."""
    if n < 8:
        r = -0.0
        for k in range(s, s + n):
            r += (a[k] + b[k]) * c[k]
        return r
    r0 = (a[s] + b[s]) * c[s]
    r1 = (a[s + 1] + b[s + 1]) * c[s + 1]
    r2 = (a[s + 2] + b[s + 2]) * c[s + 2]
    r3 = (a[s + 3] + b[s + 3]) * c[s + 3]
    r4 = (a[s + 4] + b[s + 4]) * c[s + 4]
    r5 = (a[s + 5] + b[s + 5]) * c[s + 5]
    r6 = (a[s + 6] + b[s + 6]) * c[s + 6]
    r7 = (a[s + 7] + b[s + 7]) * c[s + 7]
    m = n - n % 8
    k = s + 8
    while k < s + m:
        r0 += (a[k] + b[k]) * c[k]
        r1 += (a[k + 1] + b[k + 1]) * c[k + 1]
        r2 += (a[k + 2] + b[k + 2]) * c[k + 2]
        r3 += (a[k + 3] + b[k + 3]) * c[k + 3]
        r4 += (a[k + 4] + b[k + 4]) * c[k + 4]
        r5 += (a[k + 5] + b[k + 5]) * c[k + 5]
        r6 += (a[k + 6] + b[k + 6]) * c[k + 6]
        r7 += (a[k + 7] + b[k + 7]) * c[k + 7]
        k += 8
    r = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while k < s + n:
        r += (a[k] + b[k]) * c[k]
        k += 1
    return r


@njit(cache=True)
def sum_of_products(a_nc, b_nc, c_nc):
    """``np.sum((a + b) * c)`` of C-contiguous arrays of one shape, without the temporaries, in
    numpy's summation order (``np.add.reduce`` of a contiguous array: blocks of at most 128 by
    :func:`_pairwise_block`, larger ranges split in halves rounded to 8 and added left + right), so
    the same bits.  The halving runs on an explicit stack (numba's disk cache does not keep
    recursive functions)."""
    a = a_nc.reshape(-1)
    b = b_nc.reshape(-1)
    c = c_nc.reshape(-1)
    n = a.size
    if n <= 128:
        return _pairwise_block(a, b, c, 0, n)
    f_s = np.empty(64, np.int64)        # frames: start, length, phase (0 new, 1 left pending,
    f_n = np.empty(64, np.int64)        # 2 right pending), the left half's sum
    f_h = np.empty(64, np.int64)
    f_l = np.empty(64)
    f_s[0] = 0
    f_n[0] = n
    f_h[0] = 0
    sp = 1
    val = 0.0
    have = False                        # ``val`` is a finished half for the top frame
    while True:
        t = sp - 1
        if have:
            if f_h[t] == 1:
                f_l[t] = val
                f_h[t] = 2
                n2 = f_n[t] // 2
                n2 -= n2 % 8
                s2 = f_s[t] + n2
                m2 = f_n[t] - n2
                if m2 <= 128:
                    val = _pairwise_block(a, b, c, s2, m2)
                else:
                    have = False
                    f_s[sp] = s2
                    f_n[sp] = m2
                    f_h[sp] = 0
                    sp += 1
            else:
                val = f_l[t] + val
                sp -= 1
                if sp == 0:
                    return val
            continue
        n2 = f_n[t] // 2
        n2 -= n2 % 8
        f_h[t] = 1
        if n2 <= 128:
            val = _pairwise_block(a, b, c, f_s[t], n2)
            have = True
        else:
            f_s[sp] = f_s[t]
            f_n[sp] = n2
            f_h[sp] = 0
            sp += 1
