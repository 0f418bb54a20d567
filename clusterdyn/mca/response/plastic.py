"""(c) Elastic-plastic response: radial return on the automaton (Wilkins; docs/theory.md 2.5).

If the von Mises intensity of automaton i exceeds ``sigma_y(eps_p)``, the
deviatoric parts of its pair forces are scaled,
``sigma_ij <- P_i + (sigma_ij - P_i) M``, ``tau_ij <- M tau_ij``,
``M = sigma_y / sigma_int``, and ``d eps_p = (sigma_int - sigma_y)/(3G + H)``
with H the hardening slope.  The hardening curve is a table
``(eps_p_k, sigma_y_k)`` per material (a function is tabulated at set-up),
interpolated linearly and held constant beyond its last point.

Metals (docs/theory.md 2.7): a material with ``extra['johnson_cook']``
(:func:`johnson_cook`) flows by J2 with the Johnson-Cook curve
``sigma_y = (A + B eps_p^n)(1 + C ln(rate/eps0))`` (rate factor 1 below
eps0) and an *implicit* (consistent) radial
return: the plastic strain increment ``x`` of the step solves
``sigma_int - 3G x = sigma_y(eps_p + x, x/dt)`` (bisection to round-off;
the left side falls and the right side rises with x, so the root is unique),
and the deviator is scaled to ``M = (sigma_int - 3G x)/sigma_int``.  The
strain hardening is tabulated on a geometric grid (400 points from 1e-6 to
20, error of the linear interpolation below 1e-4 of sigma_y past eps_p =
1e-4); the rate factor is evaluated exactly.

Johnson-Cook's thermal term (optional: a record with ``m``, :func:`johnson_cook`;
docs/theory.md 2.7): each automaton carries a temperature ``T_n`` (K), the flow
stress is multiplied by ``1 - T*^m``, ``T* = (T - T_room)/(T_melt - T_room)``
(0 at and above T_melt: molten, no strength), and the automaton heats
adiabatically from its plastic work, ``dT = beta sigma_new x / (rho c_p)``
with ``sigma_new`` the flow stress the return lands on and ``x`` the step's
plastic strain (Taylor-Quinney ``beta``, 0.9 by default: our choice).  The
temperature of the step's start sets the factor (the heat of a step softens
the next one: explicit in T, as explicit codes do).  The heat is not extra
energy: it is a share of the plastic work already in the ledger, which books
``x (sigma_int + sigma_new)/2 >= sigma_new x`` per unit volume (the excess
``3G x^2/2`` is the return's O(dt) overshoot of the elastic predictor).
A sample without it passes an empty ``T_n`` and the term costs nothing.

Every return also yields the plastic work of the step, the drop of the
automaton's elastic energy in its pairs (:func:`clusterdyn.mca.kernels.pair_energy`,
with the mean stress ``Pv_n`` of the volume change and ``c_n = lambda/K``;
for a homogeneous field ``Omega (sigma_int^2 - sigma_new^2)/(6G)`` = ``Omega x
(sigma_int + sigma_new)/2``), summed by the dynamics into its energy ledger.
"""

import math

import numpy as np
from numba import njit, prange


@njit(cache=True)
def yield_stress(eps_p, tab_e, tab_s, m):
    """sigma_y and slope H at plastic strain eps_p from table row m (ascending eps_p).

    The segment is found by bisection: the first point at or past eps_p, as a scan from the
    start would find it (a 401-point Johnson-Cook table is searched in 9 steps, not 400)."""
    e = tab_e[m]
    s = tab_s[m]
    k = e.shape[0]
    if eps_p <= e[0]:
        h = (s[1] - s[0]) / (e[1] - e[0]) if k > 1 else 0.0
        return s[0], h
    if not eps_p <= e[k - 1]:          # beyond the table (or NaN): its last value, no slope
        return s[k - 1], 0.0
    lo = 0                             # e[lo] < eps_p <= e[hi]
    hi = k - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if eps_p <= e[mid]:
            hi = mid
        else:
            lo = mid
    h = (s[hi] - s[lo]) / (e[hi] - e[lo])
    return s[lo] + h * (eps_p - e[lo]), h


@njit(cache=True)
def rate_factor(x, dt, C, eps0):
    """Johnson-Cook rate factor ``1 + C ln(x/(dt eps0))`` for a plastic strain increment x (1 below eps0)."""
    if C == 0.0 or x <= eps0 * dt:
        return 1.0
    return 1.0 + C * math.log(x / (dt * eps0))


@njit(cache=True)
def thermal_factor(T, m, T_room, T_melt):
    """Johnson-Cook's thermal factor ``1 - T*^m``, ``T* = (T - T_room)/(T_melt - T_room)``:
    1 at or below T_room, 0 at or above T_melt (molten)."""
    ts = (T - T_room) / (T_melt - T_room)
    if ts <= 0.0:
        return 1.0
    if ts >= 1.0:
        return 0.0
    return 1.0 - ts ** m


@njit(cache=True, parallel=True)
def radial_return(s_ncc, first_n, side_p, side_s, mat_n, plastic_m, G_n, tab_e, tab_s, soft_n,
                  epsp_n, sig_p2, tau_p2c, M_n, implicit_m, rateC_m, rate0_m, dt, omega_n, wp_n,
                  q0_p2, S_p, Pv_n, c_n, T_n, therm_m4):
    """Return every yielding automaton to its yield surface; returns the number that yielded.

    ``soft_n`` scales the yield stress (1 - D for plastic-degrading, else 1).
    ``M_n`` receives the scale factor (1 where elastic), ``wp_n`` the plastic work of the
    step (0 where elastic).  Materials with ``implicit_m`` set use the consistent return
    with the rate factor (``rateC_m``, ``rate0_m`` in 1/ASE time; module docstring).
    ``T_n`` the automata's temperatures (K; empty: no thermal term anywhere), updated in
    place; ``therm_m4`` per material ``(m, T_room, T_melt, beta/(rho c_p))``, the last 0
    for a material without the thermal term (:func:`thermal_constants`).
    """
    n = 0
    thermal = T_n.shape[0] > 0
    for i in prange(first_n.shape[0] - 1):      # each automaton writes its own pair sides
        M_n[i] = 1.0
        wp_n[i] = 0.0
        m = mat_n[i]
        if plastic_m[m] == 0:
            continue
        th = thermal and therm_m4[m, 3] > 0.0
        tf = 1.0
        if th:
            tf = thermal_factor(T_n[i], therm_m4[m, 0], therm_m4[m, 1], therm_m4[m, 2])
        P = (s_ncc[i, 0, 0] + s_ncc[i, 1, 1] + s_ncc[i, 2, 2]) / 3.0
        ss = 0.0
        for a in range(3):
            for b in range(3):
                v = s_ncc[i, a, b] - (P if a == b else 0.0)
                ss += v * v
        sint = math.sqrt(1.5 * ss)
        sy, H = yield_stress(epsp_n[i], tab_e, tab_s, m)
        sy *= soft_n[i]
        if th:
            sy *= tf
        if sint <= sy or sint == 0.0:
            continue
        G3 = 3.0 * G_n[i]
        if implicit_m[m]:
            lo = 0.0
            hi = sint / G3
            e0 = epsp_n[i]
            for _ in range(200):
                x = 0.5 * (lo + hi)
                if x == lo or x == hi:
                    break
                syx, _h = yield_stress(e0 + x, tab_e, tab_s, m)
                if th:
                    g = sint - G3 * x - soft_n[i] * syx * rate_factor(x, dt, rateC_m[m], rate0_m[m]) * tf
                else:
                    g = sint - G3 * x - soft_n[i] * syx * rate_factor(x, dt, rateC_m[m], rate0_m[m])
                if g > 0.0:
                    lo = x
                else:
                    hi = x
            x = 0.5 * (lo + hi)
            snew = sint - G3 * x
            epsp_n[i] = e0 + x
        else:
            snew = sy
            x = (sint - sy) / (G3 + H)
            epsp_n[i] += x
        if th:      # adiabatic heating: beta sigma_y d eps_p, the flow stress at the end of the return
            T_n[i] += therm_m4[m, 3] * snew * x
        M = snew / sint
        M_n[i] = M
        de = 0.0
        cP = c_n[i] * Pv_n[i]
        for k in range(first_n[i], first_n[i + 1]):
            p = side_p[k]
            s = side_s[k]
            v0 = sig_p2[p, s] - cP
            t0 = tau_p2c[p, s, 0] ** 2 + tau_p2c[p, s, 1] ** 2 + tau_p2c[p, s, 2] ** 2
            sig_p2[p, s] = P + (sig_p2[p, s] - P) * M
            v1 = sig_p2[p, s] - cP
            de += q0_p2[p, s] * S_p[p] * (v0 * v0 - v1 * v1 + t0 * (1.0 - M * M))
            for a in range(3):
                tau_p2c[p, s, a] *= M
        # the drop of the pairs' elastic energy (kernels.pair_energy, mean stress Pv_n from the
        # volume): for a homogeneous field Omega (sint^2 - snew^2)/(6G)
        wp_n[i] = de / (4.0 * G_n[i])
        n += 1
    return n


#: Taylor-Quinney coefficient, the share of plastic work that heats (our choice; common value)
TAYLOR_QUINNEY = 0.9


def johnson_cook(A, B, n, C=0.0, eps0=1.0, m=None, T_melt=None, T_room=294.0, c_p=None,
                 beta=TAYLOR_QUINNEY):
    """The Johnson-Cook record of ``Material.extra['johnson_cook']``.

    A, B : eV/Angstrom^3; n, C dimensionless; eps0 reference strain rate in 1/s.
    ``sigma_y = (A + B eps_p^n)(1 + C ln(rate/eps0))(1 - T*^m)``; the thermal term only when
    ``m`` is given, with T_melt and T_room in K, c_p the specific heat in eV/(amu K)
    (``896 * units.J / units.kg``) and beta the Taylor-Quinney share of the plastic work
    that heats (module docstring).  Without ``m`` the record is the isothermal one.
    """
    from ...errors import InputError
    checks = [("A", A, A > 0, "a positive yield stress"), ("B", B, B >= 0, "B >= 0"),
              ("n", n, 0 < n <= 1, "0 < n <= 1"), ("C", C, C >= 0, "C >= 0"),
              ("eps0", eps0, eps0 > 0, "a positive rate (1/s)")]
    if m is not None:
        checks += [("m", m, m > 0, "a positive thermal exponent"),
                   ("T_room", T_room, T_room is not None and T_room > 0, "a positive temperature (K)"),
                   ("T_melt", T_melt, T_melt is not None and T_room is not None and T_melt > T_room,
                    f"a melting temperature above T_room = {T_room} K"),
                   ("c_p", c_p, c_p is not None and c_p > 0, "a positive specific heat (eV/(amu K))"),
                   ("beta", beta, 0 < beta <= 1, "a Taylor-Quinney share in (0, 1]")]
    for name, v, ok, allowed in checks:
        if not ok:
            raise InputError(f"johnson_cook.{name}", v, allowed)
    rec = {"A": float(A), "B": float(B), "n": float(n), "C": float(C), "eps0": float(eps0)}
    if m is not None:
        rec.update({"m": float(m), "T_melt": float(T_melt), "T_room": float(T_room), "c_p": float(c_p),
                    "beta": float(beta)})
    return rec


def jc_static(jc, eps_p):
    """Johnson-Cook strain hardening ``A + B eps_p^n`` (eV/Angstrom^3)."""
    return jc["A"] + jc["B"] * np.power(np.maximum(eps_p, 0.0), jc["n"])


def jc_flow_stress(jc, eps_p, rate_per_s, T=None):
    """Johnson-Cook flow stress at plastic strain eps_p, plastic strain rate (1/s) and, for a
    record with the thermal term, temperature T (K; None: room temperature)."""
    r = np.maximum(np.asarray(rate_per_s, float), jc["eps0"])
    s = jc_static(jc, eps_p) * (1.0 + jc["C"] * np.log(r / jc["eps0"]))
    if T is None or "m" not in jc:
        return s
    ts = (np.asarray(T, float) - jc["T_room"]) / (jc["T_melt"] - jc["T_room"])
    return s * np.where(ts <= 0.0, 1.0, 1.0 - np.minimum(np.maximum(ts, 0.0), 1.0) ** jc["m"])


def thermal_constants(material):
    """``(m, T_room, T_melt, beta/(rho0 c_p))`` of a material with Johnson-Cook's thermal term,
    else None (``beta/(rho0 c_p)`` in K Angstrom^3/eV: the temperature rise per plastic work
    per unit volume)."""
    jc = material.extra.get("johnson_cook")
    if jc is None or "m" not in jc:
        return None
    return (jc["m"], jc["T_room"], jc["T_melt"], jc["beta"] / (float(material.rho0) * jc["c_p"]))


def heat_energy(state, atoms):
    """Heat held by the thermal automata, ``sum m_i c_p (T_i - T_room)`` (eV; 0 without the term).

    It is part of the plastic work the ledger books (the share beta), not extra energy."""
    if state.T_n.size == 0:
        return 0.0
    cp = np.array([m.extra["johnson_cook"]["c_p"] if thermal_constants(m) is not None else 0.0
                   for m in state.materials])
    mid = state.per_atom("mat_id_n", atoms)
    T = state.per_atom("T_n", atoms)
    return float(np.sum(atoms.get_masses() * cp[mid] * (T - state.therm_m4[mid, 1])))


def rate_constants(material):
    """(implicit, C, eps0 in 1/ASE time) of a plastic material."""
    jc = material.extra.get("johnson_cook")
    if jc is None:
        return 0, 0.0, 1.0
    from ... import units
    return 1, float(jc["C"]), float(jc["eps0"]) / units.s


def hardening_table(material, n=201, eps_max=1.0):
    """(eps_p, sigma_y) table of a material: from ``hardening`` (callable or (2, K) table) or flat.

    A Johnson-Cook material (``extra['johnson_cook']``) is tabulated on a geometric grid
    (0, then 400 points from 1e-6 to 20).
    """
    jc = material.extra.get("johnson_cook")
    if jc is not None:
        e = np.concatenate([[0.0], np.geomspace(1e-6, 20.0, 400)])
        return e, jc_static(jc, e)
    sy = float(material.sigma_y)
    h = material.hardening
    if h is None:
        return np.array([0.0, 1.0]), np.array([sy, sy])
    if callable(h):
        e = np.linspace(0.0, eps_max, n)
        return e, np.array([float(h(x)) for x in e])
    tab = np.asarray(h, dtype=float)
    if tab.ndim != 2 or 2 not in tab.shape:
        from ...errors import InputError
        raise InputError("hardening", h, "a function sigma_y(eps_p) or a table [[eps_p...], [sigma_y...]]")
    if tab.shape[0] != 2:
        tab = tab.T
    if np.any(np.diff(tab[0]) < 0):
        from ...errors import InputError
        raise InputError("hardening", tab[0].tolist(), "a table with ascending plastic strains")
    return tab[0].copy(), tab[1].copy()
