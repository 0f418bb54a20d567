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


def test_8kms_piston_keeps_its_ledger_in_the_table_tail():
    """Aluminium's default tail (the table's own Murnaghan form beyond the densest row): an 8 km/s
    piston drives pairs deep into it, and E - E0 - W stays within 1e-3 of the piston's work W
    (at every step, against W at the end)."""
    import math
    from clusterdyn.scenes.shock import build_shock
    s = build_shock("Al", 8 * units.km_s, size=(20, 3, 3))
    curve = s.calc.potentials[0].material.curve
    assert curve.tail == "murnaghan"
    r_tail = curve.delta_rows[-1] ** (-1.0 / 3.0)            # r/r0 of the densest table row (0.75)
    seen = {"min_r": math.inf, "worst": 0.0}

    def watch():
        seen["min_r"] = min(seen["min_r"], s.calc.last_stats["min_r_over_r0"])
        seen["worst"] = max(seen["worst"], abs(s.dyn.energy_ledger()["residual"]))

    s.dyn.start_ledger()
    s.dyn.attach(watch, interval=1)
    s.dyn.run(s.nsteps)
    L = s.dyn.energy_ledger()
    assert L["drive_work"] > 10 * L["kinetic0"]               # the piston's work is most of the energy in
    assert seen["worst"] < 1e-3 * L["drive_work"]             # at every step, against the work done by the end
    assert seen["min_r"] < 0.7 * r_tail                       # deep in the tail (0.47 r0), not just past its start
