"""(a) Linear elastic-brittle: Drucker-Prager fracture of a linked pair (docs/theory.md 2.5).

``sigma_eq = 0.5 (beta+1) sigma_int + 1.5 (beta-1) sigma_mean >= sigma_c`` on the
pair's stress state, the mean of the two automata's tensors, with
``beta = sigma_c / sigma_t`` (beta = 1: von Mises).  Gives exactly sigma_t in
uniaxial tension and sigma_c in uniaxial compression.
"""

import math

from numba import njit


@njit(cache=True)
def unlink(p, linked_p, broken_p, sig_p2, tau_p2c):
    """Switch pair p from linked to unlinked: mark it broken and drop its pair forces."""
    linked_p[p] = 0
    broken_p[p] = 1
    sig_p2[p, 0] = 0.0
    sig_p2[p, 1] = 0.0
    for s in range(2):
        for a in range(3):
            tau_p2c[p, s, a] = 0.0


@njit(cache=True)
def drucker_prager(s_ncc, i, j, beta):
    """Equivalent stress of the mean tensor of automata i and j."""
    m = 0.0
    for a in range(3):
        m += 0.5 * (s_ncc[i, a, a] + s_ncc[j, a, a])
    m /= 3.0
    ss = 0.0
    for a in range(3):
        for b in range(3):
            v = 0.5 * (s_ncc[i, a, b] + s_ncc[j, a, b]) - (m if a == b else 0.0)
            ss += v * v
    sint = math.sqrt(1.5 * ss)
    return 0.5 * (beta + 1.0) * sint + 1.5 * (beta - 1.0) * m


@njit(cache=True)
def fracture(i_p, j_p, linked_p, s_ncc, sigc_p, beta_p, sig_p2, tau_p2c, broken_p):
    """Unlink every linked pair at or above the criterion; its forces drop to the contact law.

    ``broken_p`` (int8) is set to 1 for the pairs unlinked now.  Returns the count.
    """
    n = 0
    for p in range(i_p.shape[0]):
        broken_p[p] = 0
        if linked_p[p] == 0 or sigc_p[p] <= 0.0:
            continue
        if drucker_prager(s_ncc, i_p[p], j_p[p], beta_p[p]) >= sigc_p[p]:
            unlink(p, linked_p, broken_p, sig_p2, tau_p2c)
            n += 1
    return n
