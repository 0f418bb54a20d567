"""The Cluster Dynamics engine: what a run costs in pair passes, and the calculator's results
after a dynamics step (clusterdyn.engine.CDEngine, ClusterDynamics.publish)."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.io import H5MDWriter
from clusterdyn.md import DampedVerlet
from clusterdyn.md.pieces import Piece

R0 = 5 * units.um


def _box(seed=1):
    a = fcc_packing("Al", R0, size=(5, 5, 5), pbc=True)
    a.calc = ClusterDynamics()
    rng = np.random.default_rng(seed)
    a.set_momenta(a.get_masses()[:, None] * rng.normal(0.0, 30 * units.m_s, (len(a), 3)))
    return a


@pytest.mark.parametrize("J", [None, 50.0])
def test_an_h5md_frame_costs_no_force_pass(tmp_path, J):
    """A writer attached every 5 steps: the steps' own passes give every frame's forces and energy
    (one pass a step, nothing else), with damping too (the observed steps' pass keeps the
    conservative forces apart from the damped ones).  The forces and energy the calculator then
    reports are those of its own full pass (forces, energy, virial) bit for bit, and a fresh
    calculator's (another list: another order of the sums) to rounding."""
    a = _box()
    dyn = DampedVerlet(a, J=J)
    writer = H5MDWriter(tmp_path / "run.h5md", a, dyn=dyn)
    dyn.attach(writer, interval=5)
    dyn.run(20)
    writer.close()
    # 5 frames (steps 0, 5, 10, 15, 20); before, with damping: {"forces": 6, "step": 20}
    assert dict(a.calc.engine.passes) == {"forces": 1, "step": 20}   # the start's forces, then the steps
    f = a.calc.get_property("forces", a, allow_calculation=False)
    e = a.calc.get_property("energy", a, allow_calculation=False)
    assert e + dyn._constraint_energy() == dyn.potential_energy
    full = a.calc.compute(a)
    assert np.array_equal(f, full["forces"]) and e == full["energy"]
    fresh = a.copy()
    fresh.calc = ClusterDynamics()
    np.testing.assert_allclose(f, fresh.get_forces(), rtol=0, atol=1e-12 * np.abs(f).max())
    assert e == pytest.approx(fresh.get_potential_energy(), rel=1e-13)


@pytest.mark.parametrize("materials", [1, 2])
def test_a_damped_step_publishes_the_conservative_forces_of_every_frame(materials):
    """On every observed step of a damped run (one material, and two: the multi-material kernels)
    the calculator holds, from the step's own pass, the forces and energy its own conservative
    pass gives, bit for bit, while the dynamics' forces hold the damping; the damped steps
    themselves are the same bits with and without observers."""
    def box():
        a = _box()
        if materials == 2:
            a.info["cd_materials"] = ["Al", "Al"]
            a.info["cd_r0"] = [R0, R0]
            a.arrays["material"] = np.arange(len(a)) % 2
        return a

    a = box()
    dyn = DampedVerlet(a, J=20.0)
    seen = []

    def check():
        f = a.calc.get_property("forces", a, allow_calculation=False)
        e = a.calc.get_property("energy", a, allow_calculation=False)
        full = a.calc.compute(a)                 # a conservative pass of its own, for the check
        assert np.array_equal(f, full["forces"]) and e == full["energy"]
        assert not np.array_equal(f, dyn.forces)   # the step's forces hold the damping
        seen.append(dyn.nsteps)

    dyn.attach(check, interval=3)
    dyn.run(9)
    assert seen == [0, 3, 6, 9]
    quiet = box()
    DampedVerlet(quiet, J=20.0).run(9)
    assert np.array_equal(a.positions, quiet.positions) and np.array_equal(a.get_momenta(), quiet.get_momenta())


def test_published_results_are_dropped_when_the_atoms_change():
    """The results a step leaves follow ASE's cache rule: moved positions (or a removal) drop them."""
    a = _box()
    dyn = DampedVerlet(a, J=None)
    dyn.attach(lambda: None, interval=1)
    dyn.run(3)
    assert a.calc.get_property("forces", a, allow_calculation=False) is not None
    a.positions[0, 0] += 0.01 * R0
    assert a.calc.get_property("forces", a, allow_calculation=False) is None
    before = a.calc.engine.passes["forces"]
    a.get_forces()
    assert a.calc.engine.passes["forces"] == before + 1


def test_a_run_without_observers_publishes_nothing():
    """No observer: the steps take no energy and the calculator keeps no results (no copies)."""
    a = _box()
    dyn = DampedVerlet(a, J=None)
    dyn.run(5)
    assert a.calc.results == {} and dict(a.calc.engine.passes) == {"forces": 1, "step": 5}


class _Gravity(Piece):
    """A uniform force g on every particle (energy -g.x): an attached force term."""

    name = "gravity"
    adds_forces = True

    def __init__(self, g):
        self.g = np.asarray(g, float)
        self.orders = []

    def add_forces(self, atoms, forces, kick):
        forces += self.g
        if kick is not None:
            atoms.arrays["momenta"] += kick * self.g

    def energy(self, atoms):
        return -float((atoms.positions @ self.g).sum())

    def reindexed(self, order):
        self.orders.append(order.copy())


def test_an_attached_force_term_is_integrated_with_the_pairs():
    """A piece's forces join the step (its half kicks included): under a uniform force the total
    momentum grows by N g t (the pair forces sum to zero), its energy is part of the potential
    energy, and it is told of the sorts that renumber the particles."""
    a = _box()
    dyn = DampedVerlet(a, J=None, sort_interval=10)
    g = np.array([0.0, 0.0, -1e-4 * R0 / dyn.dt ** 2]) * a.get_masses()[0]      # 1e-4 r0 / dt^2
    term = dyn.attach_piece(_Gravity(g))
    p0 = a.get_momenta().sum(axis=0)
    dyn.run(30)
    dp = a.get_momenta().sum(axis=0) - p0
    np.testing.assert_allclose(dp, len(a) * g * 30 * dyn.dt, rtol=1e-9, atol=1e-9 * np.abs(g).max() * dyn.dt)
    pair = a.calc.compute(a, virial=False)["energy"]
    assert dyn.potential_energy == pytest.approx(pair + term.energy(a), rel=1e-12)
    assert dyn.nsorts == len(term.orders) >= 1
