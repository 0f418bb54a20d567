"""The step kernels against the previous kernel's arithmetic, pair by pair, on a shocked state.

The previous kernel evaluated ``-2 (c1 + t (2 c2 + 3 t c3)) / h_s`` from the energy cubic and
skipped pairs beyond the cut-off with a branch; the present one reads the force table with the
constants folded in and sends pairs beyond the cut-off to a zero bin.  The two must agree to
1e-12 of the largest force (measured: 4e-16), damped and undamped.
"""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.scenes.shock import build_shock


def previous_forces(atoms, calc, eta=None):
    """Forces with the previous kernel's arithmetic over the calculator's own list (NumPy)."""
    nl = calc.nl
    i, j, d, r = nl.pairs(atoms.positions)
    coef = calc.coef[0, 0]
    smin, invh, cut2 = calc.meta[0, 0, 0], calc.meta[0, 0, 1], calc.meta[0, 0, 2]
    nb = coef.shape[0] - 1                   # the table's bins (the last row is the zero bin)
    r2 = (d * d).sum(axis=1)
    k = r2 < cut2
    i, j, d, r2 = i[k], j[k], d[k], r2[k]
    x = (r2 - smin) * invh
    kb = np.minimum(x.astype(np.int64), nb - 1)
    t = x - kb
    c1, c2, c3 = coef[kb, 1], coef[kb, 2], coef[kb, 3]
    s = -2.0 * (c1 + t * (2.0 * c2 + 3.0 * t * c3)) * invh
    fp = s[:, None] * d
    if eta is not None:
        v = atoms.get_velocities()
        fp = fp + eta * (v[i] - v[j])
    F = np.zeros((len(atoms), 3))
    np.add.at(F, i, -fp)
    np.add.at(F, j, fp)
    return F


@pytest.mark.parametrize("J", [None, 50.0])
def test_step_forces_match_the_previous_kernel(J):
    s = build_shock(size=(24, 4, 4), u=3 * units.km_s, J=J, seed=2)
    s.dyn.run(150)                             # the front has formed: compressed and tensile pairs
    a, c = s.atoms, s.calc
    damping = None if J is None else (a.arrays["momenta"], 1.0 / a.get_masses(), c.damping_matrix(J))
    f = c.compute(a, damping=damping, virial=False, energy=False)["forces"]
    ref = previous_forces(a, c, None if J is None else c.damping_matrix(J)[0, 0])
    scale = np.abs(ref).max()
    assert np.abs(f - ref).max() < 1e-12 * scale
    norm = np.linalg.norm(ref, axis=1)
    big = norm > 1e-3 * norm.max()
    assert (np.linalg.norm(f - ref, axis=1)[big] / norm[big]).max() < 1e-12
    assert c.last_stats["min_r_over_r0"] < 0.95       # compressed pairs are in the comparison
