"""(b) Degrading response (concrete, ceramics; MCA Fig. 3b).

Linear up to ``sigma_d``; beyond it a scalar damage per pair grows with the
pair's Drucker-Prager equivalent stress, linearly from 0 at ``sigma_d`` to
``D_c`` at ``sigma_c``, where the pair unlinks.  Increments (loading,
unloading, reloading) use the damaged modulus ``(1 - D) 2G``; damage never
decreases.  (With ``D -> 1`` at sigma_c an incremental law would approach
sigma_c only asymptotically; ``D_c < 1`` is the material parameter that keeps
the peak finite, default 0.8.)
"""

from numba import njit

from .brittle import drucker_prager, unlink


@njit(cache=True)
def degrade(i_p, j_p, linked_p, s_ncc, sigd_p, sigc_p, beta_p, Dc_p, D_p, sig_p2, tau_p2c, broken_p):
    """Update the damage of linked pairs; unlink at sigma_c.  Returns the number unlinked."""
    n = 0
    for p in range(i_p.shape[0]):
        broken_p[p] = 0
        if linked_p[p] == 0 or sigc_p[p] <= 0.0:
            continue
        seq = drucker_prager(s_ncc, i_p[p], j_p[p], beta_p[p])
        if seq >= sigc_p[p]:
            unlink(p, linked_p, broken_p, sig_p2, tau_p2c)
            n += 1
            continue
        # the Drucker-Prager scale of sigma_d: sigma_d is given in the same measure
        if seq > sigd_p[p]:
            d = Dc_p[p] * (seq - sigd_p[p]) / (sigc_p[p] - sigd_p[p])
            if d > D_p[p]:
                D_p[p] = d
    return n
