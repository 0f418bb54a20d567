"""(c) Elastic-plastic response: radial return on the automaton (Wilkins; docs/theory.md 2.5).

If the von Mises intensity of automaton i exceeds ``sigma_y(eps_p)``, the
deviatoric parts of its pair forces are scaled,
``sigma_ij <- P_i + (sigma_ij - P_i) M``, ``tau_ij <- M tau_ij``,
``M = sigma_y / sigma_int``, and ``d eps_p = (sigma_int - sigma_y)/(3G + H)``
with H the hardening slope.  The hardening curve is a table
``(eps_p_k, sigma_y_k)`` per material (a function is tabulated at set-up),
interpolated linearly and held constant beyond its last point.
"""

import math

import numpy as np
from numba import njit


@njit(cache=True)
def yield_stress(eps_p, tab_e, tab_s, m):
    """sigma_y and slope H at plastic strain eps_p from table row m."""
    e = tab_e[m]
    s = tab_s[m]
    k = e.shape[0]
    if eps_p <= e[0]:
        h = (s[1] - s[0]) / (e[1] - e[0]) if k > 1 else 0.0
        return s[0], h
    for q in range(k - 1):
        if eps_p <= e[q + 1]:
            h = (s[q + 1] - s[q]) / (e[q + 1] - e[q])
            return s[q] + h * (eps_p - e[q]), h
    return s[k - 1], 0.0


@njit(cache=True)
def radial_return(s_ncc, first_n, side_p, side_s, mat_n, plastic_m, G_n, tab_e, tab_s, soft_n,
                  epsp_n, sig_p2, tau_p2c, M_n):
    """Return every yielding automaton to its yield surface; returns the number that yielded.

    ``soft_n`` scales the yield stress (1 - D for plastic-degrading, else 1).
    ``M_n`` receives the scale factor (1 where elastic).
    """
    n = 0
    for i in range(first_n.shape[0] - 1):
        M_n[i] = 1.0
        m = mat_n[i]
        if plastic_m[m] == 0:
            continue
        P = (s_ncc[i, 0, 0] + s_ncc[i, 1, 1] + s_ncc[i, 2, 2]) / 3.0
        ss = 0.0
        for a in range(3):
            for b in range(3):
                v = s_ncc[i, a, b] - (P if a == b else 0.0)
                ss += v * v
        sint = math.sqrt(1.5 * ss)
        sy, H = yield_stress(epsp_n[i], tab_e, tab_s, m)
        sy *= soft_n[i]
        if sint <= sy or sint == 0.0:
            continue
        M = sy / sint
        M_n[i] = M
        epsp_n[i] += (sint - sy) / (3.0 * G_n[i] + H)
        for k in range(first_n[i], first_n[i + 1]):
            p = side_p[k]
            s = side_s[k]
            sig_p2[p, s] = P + (sig_p2[p, s] - P) * M
            for a in range(3):
                tau_p2c[p, s, a] *= M
        n += 1
    return n


def hardening_table(material, n=201, eps_max=1.0):
    """(eps_p, sigma_y) table of a material: from ``hardening`` (callable or (2, K) table) or flat."""
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
    return tab[0].copy(), tab[1].copy()
