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


def test_fma_rounds_once_compiled_and_as_python():
    """x y + z with x y = 1 - 2**-60 exactly: rounded once it is -2**-60; a multiplication
    rounded before the addition gives 0.  Both the compiled fma and its Python fallback
    (NUMBA_DISABLE_JIT) must round once."""
    from numba import njit
    from clusterdyn.fma import _fma, _fma_python

    @njit
    def compiled(x, y, z):
        return _fma(x, y, z)
    x, y, z = 1.0 + 2.0 ** -30, 1.0 - 2.0 ** -30, -1.0
    assert x * y + z == 0.0
    assert compiled(x, y, z) == -2.0 ** -60 and _fma_python(x, y, z) == -2.0 ** -60


_RUN = """
import numpy as np
from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.md import DampedVerlet
atoms = fcc_packing("Al", r0=5 * units.um, size=(3, 3, 3), pbc=True)
atoms.positions += np.random.default_rng(1).normal(0, 0.1 * units.um, atoms.positions.shape)
atoms.calc = ClusterDynamics(rc=1.15)
dyn = DampedVerlet(atoms, J=50)
dyn.run(2)
np.save(path, np.concatenate([atoms.positions, dyn.forces]))
"""


def test_the_kernels_run_as_python_with_the_same_bits(tmp_path):
    """Under NUMBA_DISABLE_JIT=1 (the kernels run as Python, for debugging) a damped run gives
    the compiled run's positions and forces bit for bit (the intrinsic fma alone would raise
    there: its fallback is exact rational arithmetic rounded once)."""
    import os
    import subprocess
    import sys
    exec(_RUN, {"path": str(tmp_path / "jit.npy")})
    code = f"path = {str(tmp_path / 'python.npy')!r}\n" + _RUN
    subprocess.run([sys.executable, "-c", code], env=dict(os.environ, NUMBA_DISABLE_JIT="1"), check=True,
                   timeout=300)
    jit, py = np.load(tmp_path / "jit.npy"), np.load(tmp_path / "python.npy")
    assert np.abs(jit).max() > 0 and np.array_equal(jit, py)
