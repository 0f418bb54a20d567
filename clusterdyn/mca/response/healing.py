"""Healing / micro-welding: unlinked -> linked under sustained compression (docs/theory.md 2.5).

An unlinked pair relinks when its normal stress has stayed compressive beyond
``sigma_weld`` (a material parameter, > 0 as a magnitude) for ``n_weld``
consecutive steps.  The geometry at that moment becomes its new rest state:
the contact rest distance ``r0`` is reset to the current distance and the
pair continues from its current forces with the linked (incremental) law, so
nothing jumps; pulled apart afterwards it carries tension up to its strength.
"""

from numba import njit


@njit(cache=True)
def weld(linked_p, sig_p2, r_p, r0_p, sigw_p, nweld_p, count_p, welded_p):
    """Count compressed steps of unlinked pairs, relink those that reached n_weld.  Returns the count."""
    n = 0
    for p in range(linked_p.shape[0]):
        welded_p[p] = 0
        if linked_p[p] != 0 or sigw_p[p] <= 0.0:
            continue
        sg = 0.5 * (sig_p2[p, 0] + sig_p2[p, 1])
        if sg <= -sigw_p[p]:
            count_p[p] += 1
            if count_p[p] >= nweld_p[p]:
                linked_p[p] = 1
                count_p[p] = 0
                r0_p[p] = r_p[p]
                welded_p[p] = 1
                n += 1
        else:
            count_p[p] = 0
    return n
