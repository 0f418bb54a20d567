"""(d) Plastic with degradation (MCA Fig. 3d).

Elastic-plastic as (c); in addition each linked pair carries a damage that
grows linearly with the mean plastic strain of its two automata, from 0 at
``eps_d`` to 1 at ``eps_f``, where the pair unlinks.  The damage scales the
pair's modulus and the yield stress of its automata (mean over their pairs),
so the stress-strain curve softens after the plateau.
"""

from numba import njit

from .brittle import unlink


@njit(cache=True)
def degrade_plastic(i_p, j_p, linked_p, epsp_n, epsd_p, epsf_p, D_p, sig_p2, tau_p2c, broken_p):
    n = 0
    for p in range(i_p.shape[0]):
        broken_p[p] = 0
        if linked_p[p] == 0 or epsf_p[p] <= 0.0:
            continue
        e = 0.5 * (epsp_n[i_p[p]] + epsp_n[j_p[p]])
        if e <= epsd_p[p]:
            continue
        d = (e - epsd_p[p]) / (epsf_p[p] - epsd_p[p])
        if d >= 1.0:
            unlink(p, linked_p, broken_p, sig_p2, tau_p2c)
            n += 1
        elif d > D_p[p]:
            D_p[p] = d
    return n


@njit(cache=True)
def softening(first_n, side_p, D_p, soft_n):
    """Yield-stress factor of each automaton: 1 - mean damage of its pairs."""
    for i in range(first_n.shape[0] - 1):
        k0 = first_n[i]
        k1 = first_n[i + 1]
        if k1 == k0:
            soft_n[i] = 1.0
            continue
        s = 0.0
        for k in range(k0, k1):
            s += D_p[side_p[k]]
        soft_n[i] = 1.0 - s / (k1 - k0)
