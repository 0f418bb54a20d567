"""Unlike-pair mixing, cutoff rules and the kernel tables (docs/theory.md 1.2)."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.potentials import ClusterPotential, MixedPairPotential, PairTable


def test_rc_and_r0_validation():
    for bad in (1.0, 0.9, 1.5, np.sqrt(2), "x"):
        with pytest.raises(InputError, match="rc="):
            ClusterPotential("Al", 5 * units.um, rc=bad)
    for bad in (0.0, -1.0):
        with pytest.raises(InputError, match="r0="):
            ClusterPotential("Al", bad)


def test_force_at_cutoff_matches_reference():
    p = ClusterPotential("Al", 5 * units.um, rc=1.15)
    assert p.force(p.cutoff) / units.N == pytest.approx(-0.153, abs=1e-3)


def test_mixed_pair_series_rule():
    a = ClusterPotential("Al", 5 * units.um)
    b = ClusterPotential("Pb", 4 * units.um)
    m = MixedPairPotential(a, b)
    assert m.r0 == pytest.approx(4.5 * units.um)
    r = np.linspace(0.6, 1.14, 40) * m.r0
    xa, xb = m.split(r)
    scale = np.abs(a.force(2 * xa)).max()
    assert np.abs(a.force(2 * xa) - b.force(2 * xb)).max() < 1e-9 * scale
    h = 1e-6 * m.r0
    fd = -(m.energy(r + h) - m.energy(r - h)) / (2 * h)
    assert np.abs(fd - m.force(r)).max() < 1e-6 * scale
    assert abs(m.force(m.r0)) < 1e-9 * scale           # both halves at rest


def test_chain_AABB_carries_one_force():
    """A static chain A-A-B-B under an end load: every bond carries the same force."""
    a = ClusterPotential("Al", 5 * units.um)
    b = ClusterPotential("Pb", 4 * units.um)
    ab = MixedPairPotential(a, b)
    load = 0.05 * units.N           # tension, below the weakest bond's strength
    # each bond length solves f(r) = -load (bonds in series); find them independently
    from scipy.optimize import brentq
    lens = []
    for law in (a, ab, b):
        lens.append(brentq(lambda r: law.force(r) + load, 0.9 * law.r0, 1.4 * law.r0, xtol=1e-12))
    x = np.concatenate([[0], np.cumsum(lens)])
    forces = [a.force(x[1] - x[0]), ab.force(x[2] - x[1]), b.force(x[3] - x[2])]
    np.testing.assert_allclose(forces, -load, rtol=1e-9)
    # and the AB bond's two halves each carry that force
    xa, xb = ab.split(x[2] - x[1])
    np.testing.assert_allclose([a.force(2 * xa[0]), b.force(2 * xb[0])], -load, rtol=1e-8)


def test_table_matches_raw_law_and_is_conservative():
    p = ClusterPotential("Al", 5 * units.um)
    t = PairTable(p, 2000)
    r = np.linspace(0.5, 1.149, 997) * p.r0
    e, f = t.evaluate(r)
    np.testing.assert_allclose(f, p.force(r), atol=1e-7 * abs(p.force(0.5 * p.r0)))
    np.testing.assert_allclose(e, p.energy(r) - p.energy(p.cutoff), atol=1e-8 * p.energy(0.5 * p.r0))
    # r0 is a node: zero force at rest (to round-off in locating the node)
    assert abs(t.evaluate(np.array([p.r0]))[1][0]) < 1e-12 * abs(p.force(0.5 * p.r0))
