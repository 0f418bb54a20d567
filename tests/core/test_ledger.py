"""The energy ledger of DampedVerlet: kinetic + potential against drive work and damping loss."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.md import DampedVerlet, Piston, Table
from clusterdyn.scenes.common import thermal_noise

R0 = 5 * units.um


def _ramp_shock(J):
    a = fcc_packing("Al", R0, size=(12, 3, 3), pbc=(False, True, True))
    a.calc = ClusterDynamics()
    mask = a.positions[:, 0] < 1.5 * R0 - 1e-3
    u = 2 * units.km_s
    thermal_noise(a, 10 * units.m_s, 1, exclude=mask)
    a.set_constraint(Piston(mask, Table([0, 10 * units.ns], [0.5 * u, u])))
    a.set_momenta(a.get_momenta())
    return a, DampedVerlet(a, J=J, timestep=0.01 * R0 / (5.3 * units.km_s))


@pytest.mark.parametrize("J", [None, 50.0])
def test_ledger_closes_under_a_ramped_piston(J):
    a, dyn = _ramp_shock(J)
    dyn.start_ledger()
    dyn.run(600)
    L = dyn.energy_ledger()
    assert abs(L["residual"]) < 1e-4 * L["energy_in"]
    if J is None:
        assert L["damping_loss"] == 0.0
    else:
        # the loss is real: without it the ledger would miss by far more than the bound
        assert L["damping_loss"] > 100 * abs(L["residual"])


def test_damping_loss_of_a_damped_pair_converges_at_first_order():
    """A damped pair oscillating inside the cutoff: the ledger's loss (dt times the power at the
    half-step velocities the force used) misses the kinetic + potential energy lost by an error of
    first order in dt: halving dt halves it."""
    from clusterdyn.build import make_cluster_atoms
    res = []
    for f in (0.004, 0.002):
        a = make_cluster_atoms(np.array([[0.0, 0.0, 0.0], [R0, 0.0, 0.0]]), ["Al"], [R0])
        a.calc = ClusterDynamics()
        v = 1.0 * units.m_s
        a.set_velocities([[-v, 0, 0], [v, 0, 0]])
        dyn = DampedVerlet(a, J=10.0, timestep=f * R0 / (5.3 * units.km_s))
        dyn.start_ledger()
        dyn.run(int(0.8 / f))
        L = dyn.energy_ledger()
        assert L["damping_loss"] > 0.1 * L["kinetic0"]            # the pair lost a sixth of its energy
        res.append(L["residual"] / L["damping_loss"])
    assert abs(res[0]) < 3e-3
    assert res[0] / res[1] == pytest.approx(2.0, rel=0.05)
