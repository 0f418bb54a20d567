"""Stiff and extreme cases: what runs, what stops, and that a stop names step, particles and quantity.

docs/theory.md 3: the stable step scales as r0/c_max; a run past the limit, or
pushed to compressions beyond the potential's tabulated range, stops with
InstabilityError.  The measured limits are in ``clusterdyn study stability``.
"""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing, make_cluster_atoms
from clusterdyn.calculators import ClusterDynamics, mark_initial_bonds
from clusterdyn.errors import InputError, InstabilityError
from clusterdyn.md import DampedVerlet, default_timestep, stability_limit
from clusterdyn.potentials import R_MIN_FACTOR
from clusterdyn.scenes.common import thermal_noise
from clusterdyn.scenes.shock import build_shock, run_shock
from clusterdyn.analysis.energy_balance import EnergyBalance

R0 = 5 * units.um


def r0_c0(calc):
    p = calc.potentials[0]
    return p.r0 / p.c0


def noisy_lattice(material="Al", size=(3, 3, 3), compression=1.0, rms=100 * units.m_s, attraction="all"):
    a = fcc_packing(material, R0, size=size, pbc=True)
    if attraction == "initial":
        mark_initial_bonds(a)
    a.set_cell(a.cell.array * compression ** (-1 / 3), scale_atoms=True)
    a.calc = ClusterDynamics(attraction=attraction)
    a.calc.setup(a)
    thermal_noise(a, rms, 1)
    return a


def energy_trace(dyn, blocks=40, every=10):
    E0 = dyn.get_total_energy()
    out = []
    for _ in range(blocks):
        dyn.run(every)
        out.append(dyn.get_total_energy() - E0)
    return np.abs(out)


# ---------------------------------------------------------------- 8 km/s pistons
def test_8kms_piston_in_b4c_runs_with_energy_balance():
    s = build_shock("B4C", 8 * units.km_s, size=(16, 3, 3))
    bal = EnergyBalance(s.dyn, s.atoms, [s.piston])
    s.dyn.attach(bal, interval=1)
    _, st, _ = run_shock(s, frames=20, progress=False)
    assert math.isfinite(st.D_fit) and st.D_fit > 8 * units.km_s
    assert np.max(np.abs(bal.errors)) < 2e-3 * bal.W       # E - E0 = piston work
    assert bal.min_r < 0.7                                  # deep in the compressed branch


def test_8kms_piston_in_aluminium():
    # the piston's first impact pushes pairs deep into the cold table's tail (beyond 0.75 r0)
    s = build_shock("Al", 8 * units.km_s, size=(16, 3, 3))
    bal = EnergyBalance(s.dyn, s.atoms, [s.piston])
    s.dyn.attach(bal, interval=1)
    _, st, _ = run_shock(s, frames=20, progress=False)
    assert math.isfinite(st.D_fit) and np.max(np.abs(bal.errors)) < 1e-3 * bal.W
    assert R_MIN_FACTOR < bal.min_r < 0.6


def test_piston_past_the_former_table_end_keeps_its_energy_balance():
    # at 25 km/s pairs reach 0.29 r0, below the 0.3 r0 where the pair table used to end
    s = build_shock("Al", 25 * units.km_s, size=(16, 3, 3))
    bal = EnergyBalance(s.dyn, s.atoms, [s.piston])
    s.dyn.attach(bal, interval=1)
    _, st, _ = run_shock(s, frames=20, progress=False)
    assert math.isfinite(st.D_fit) and np.max(np.abs(bal.errors)) < 2e-3 * bal.W
    assert R_MIN_FACTOR < bal.min_r < 0.3


def test_piston_far_beyond_the_table_stops_naming_step_particles_quantity():
    s = build_shock("Al", 100 * units.km_s, size=(16, 3, 3))
    with pytest.raises(InstabilityError) as e:
        run_shock(s, frames=10, progress=False)
    err = e.value
    assert err.quantity in ("distance r/r0", "timestep", "displacement per step / r0")
    assert err.step is not None and len(err.particles) >= 1
    assert "step" in str(err) and "particle" in str(err)


# ---------------------------------------------------------------- compression beyond delta = 2.5
def test_compression_beyond_2p5():
    delta = 2.6                                 # beyond the densest table row (2.37): the tail
    a = noisy_lattice(compression=delta, rms=0.0, attraction="initial")
    P_x = a.calc.potentials[0].curve.pressure(delta)
    assert -a.get_stress()[:3].mean() == pytest.approx(P_x, rel=1e-3)
    # with every pair attracting, second neighbours (at 1.03 r0 now, inside rc) pull back
    b = noisy_lattice(compression=delta, rms=0.0)
    assert -b.get_stress()[:3].mean() < 0.99 * P_x
    # the stable step shrinks with compression; 0.9 of it stays bounded
    lim = stability_limit(a.calc, delta ** (-1 / 3))
    assert lim < 0.5 * stability_limit(a.calc)
    c = noisy_lattice(compression=delta)
    dyn = DampedVerlet(c, timestep=0.9 * lim, J=None)
    tr = energy_trace(dyn, 20)
    assert np.all(np.isfinite(tr)) and tr[10:].max() < 2 * tr[:10].max() + 1e-12


def test_pair_closer_than_the_table_names_step_particles_quantity():
    r = 0.95 * R_MIN_FACTOR
    a = make_cluster_atoms(np.array([[0, 0, 0], [r * R0, 0, 0]]), ["Al"], [R0])
    a.calc = ClusterDynamics()
    with pytest.raises(InstabilityError) as e:
        a.get_forces()
    assert set(e.value.particles) == {0, 1} and e.value.quantity == "distance r/r0"
    assert e.value.value == pytest.approx(r)


@pytest.mark.parametrize("J", [None, 50])
def test_pair_driven_deep_below_the_table_in_a_step_stops_naming_it(J):
    # the step kernels (undamped and damped) clamp the bin of a pair below the table to the zero
    # bin; the pair must still stop the run, at the step that brought it there
    a = make_cluster_atoms(np.array([[0, 0, 0], [0.5 * R0, 0, 0], [5 * R0, 5 * R0, 5 * R0]]), ["Al"], [R0],
                           cell=[10 * R0] * 3)
    a.calc = ClusterDynamics()
    dyn = DampedVerlet(a, J=J)
    v = 0.5 * (0.5 - 0.06) * R0 / dyn.dt          # each moves 0.22 r0: under the 0.25 r0 step limit
    a.set_velocities([[v, 0, 0], [-v, 0, 0], [0, 0, 0]])
    with pytest.raises(InstabilityError) as e:
        dyn.run(3)
    err = e.value
    assert err.step == 1 and set(err.particles) == {0, 1} and err.quantity == "distance r/r0"
    assert err.value < 0.5 * R_MIN_FACTOR        # far below the table: bins below the first


# ---------------------------------------------------------------- time step at 0.9x and 1.5x the limit
def test_time_step_at_0p9_of_the_limit_is_bounded():
    a = noisy_lattice(rms=10 * units.m_s)
    lim = stability_limit(a.calc)
    dyn = DampedVerlet(a, timestep=0.9 * lim, J=None)
    tr = energy_trace(dyn, 40)
    ke = 0.5 * a.get_masses().sum() * (10 * units.m_s) ** 2
    assert np.all(np.isfinite(tr))
    assert tr[20:].max() < 2 * tr[:20].max()               # oscillates, does not grow
    assert tr.max() < ke                                   # shadow-energy offset, no blow-up


def test_time_step_at_1p5_of_the_limit():
    a = noisy_lattice()
    lim = stability_limit(a.calc)
    with pytest.raises(InputError, match="stability"):
        DampedVerlet(a, timestep=1.5 * lim, J=None)
    # forced past the check: the run stops, naming step, particle and quantity
    dyn = DampedVerlet(a, timestep=0.5 * lim, J=None)
    dyn.dt = 1.5 * lim
    with pytest.raises(InstabilityError) as e:
        dyn.run(500)
    assert e.value.step is not None and e.value.step < 500
    assert e.value.particles and e.value.quantity


def test_time_step_above_the_limit_at_the_current_compression():
    delta = 2.6
    a = noisy_lattice(compression=delta)
    lim = stability_limit(a.calc, delta ** (-1 / 3))
    dyn = DampedVerlet(a, timestep=1.5 * lim, J=None)    # allowed at rest, too large here
    with pytest.raises(InstabilityError) as e:
        dyn.run(5)
    assert e.value.quantity == "timestep" and e.value.limit < e.value.value
    assert e.value.step == 0 and len(e.value.particles) == 2


# ---------------------------------------------------------------- single particles
def test_particle_with_a_huge_velocity():
    a = noisy_lattice(rms=10 * units.m_s)
    v = a.get_velocities()
    v[7] = [3000 * units.km_s, 0, 0]
    a.set_velocities(v)
    dyn = DampedVerlet(a, J=None)
    with pytest.raises(InstabilityError) as e:
        dyn.run(3)
    assert e.value.particles == (7,) and e.value.quantity == "displacement per step / r0"
    assert e.value.step == 1


@pytest.mark.parametrize("J", [None, 50])
def test_single_isolated_particle(J):
    a = make_cluster_atoms(np.array([[1.0, 2.0, 3.0]]) * R0, ["Al"], [R0], cell=[10 * R0] * 3, pbc=True)
    a.calc = ClusterDynamics()
    v = np.array([[1.0, -2.0, 0.5]]) * units.km_s
    a.set_velocities(v)
    dyn = DampedVerlet(a, J=J)
    assert dyn.dt == pytest.approx(default_timestep(a.calc))
    E0 = dyn.get_total_energy()
    x0 = a.positions.copy()
    dyn.run(100)
    assert np.allclose(a.positions, x0 + v * 100 * dyn.dt, rtol=0, atol=1e-9 * R0)
    assert dyn.get_total_energy() == pytest.approx(E0, rel=1e-14)
    assert a.get_potential_energy() == 0.0 and np.all(a.get_forces() == 0.0)


# ---------------------------------------------------------------- head-on collision
def collide(dt_factor, r_start=1.1, v_rel=10 * units.km_s):
    a = make_cluster_atoms(np.array([[0, 0, 0], [r_start * R0, 0, 0]]), ["Al"], [R0], cell=[10 * R0] * 3)
    a.calc = ClusterDynamics()
    a.set_velocities([[0.5 * v_rel, 0, 0], [-0.5 * v_rel, 0, 0]])
    dyn = DampedVerlet(a, timestep=dt_factor * r0_c0(a.calc) if a.calc.potentials else None, J=None)
    dyn.dt = dt_factor * r0_c0(a.calc)
    return a, dyn


def test_head_on_collision_at_10kms_conserves_energy():
    # inside the cutoff all the way (start and end at 1.1 r0 < rc): energy to 1e-6 at 3e-4 r0/c0
    a, dyn = collide(3e-4)
    E0 = dyn.get_total_energy()
    rmin, errs = math.inf, []
    while True:
        dyn.run(10)
        r = np.linalg.norm(a.positions[1] - a.positions[0]) / R0
        rmin = min(rmin, r)
        errs.append(abs(dyn.get_total_energy() - E0) / E0)
        if r > 1.1 and rmin < 1.0:
            break
    assert 0.45 < rmin < 0.6                               # a deep collision, inside the table
    assert max(errs) < 1e-6
    v = a.get_velocities()[:, 0]
    assert v[1] - v[0] > 9.9 * units.km_s                            # rebound
    assert abs(a.get_momenta().sum(axis=0)).max() < 1e-12 * a.get_masses()[0] * units.km_s


def test_cutoff_crossing_costs_at_most_f_rc_v_dt():
    # crossing rc the force jumps by f(rc) (no taper, docs/theory.md 1.2): velocity Verlet then errs by
    # at most |f(rc)| v dt / 2 per crossing, so the error falls with the step
    for dt_factor in (1e-3, 3e-4):
        a, dyn = collide(dt_factor, r_start=1.3)
        E0 = dyn.get_total_energy()
        n = int(2 * 1.3 * R0 / (10 * units.km_s) / dyn.dt) + 1
        dyn.run(n)
        fc = abs(a.calc.potentials[0].force(1.15 * R0))
        bound = 2 * 0.5 * fc * 10 * units.km_s * dyn.dt         # two crossings
        assert abs(dyn.get_total_energy() - E0) <= bound


# ---------------------------------------------------------------- head-on pair collisions deep in the table
def _head_on(v, factor=None):
    """Two aluminium clusters meeting head-on at relative speed v (damping off, the default time
    step rule 0.03 r0/(c0 + v) unless ``factor``); returns (closest r/r0, analytic turning r/r0,
    largest |E - E0|/KE0 during the collision, |E_after - E0|/KE0)."""
    from scipy.optimize import brentq
    a = make_cluster_atoms(np.array([[0, 0, 0], [1.2 * R0, 0, 0]]), ["Al"], [R0])
    a.calc = ClusterDynamics()
    a.calc.setup(a)
    a.set_velocities(np.array([[v / 2, 0, 0], [-v / 2, 0, 0]]))
    dt = default_timestep(a.calc, v) if factor is None else default_timestep(a.calc, v, factor)
    dyn = DampedVerlet(a, timestep=dt, J=None)
    p = a.calc.potentials[0]
    ke0 = a.get_kinetic_energy()
    e0 = a.get_potential_energy() + ke0
    rmin, err = np.inf, 0.0
    for _ in range(int(2.6 * R0 / v / dt)):
        dyn.run(1)
        rmin = min(rmin, a.get_distance(0, 1) / R0)
        err = max(err, abs(a.get_potential_energy() + a.get_kinetic_energy() - e0) / ke0)
    assert a.get_distance(0, 1) > 1.2 * R0                      # apart again
    after = abs(a.get_kinetic_energy() - ke0) / ke0             # no pair energy left
    turn = brentq(lambda r: p.energy(r) - p.energy(p.cutoff) - ke0, 0.05 * R0, R0) / R0
    return rmin, turn, err, after


def test_head_on_collision_12kms_conserves_energy():
    rmin, turn, err, after = _head_on(12 * units.km_s)
    assert rmin == pytest.approx(turn, abs=2e-3) and 0.5 < rmin < 0.6     # 0.536 r0: in the tail
    assert after < 1e-3 and err < 2e-3      # 6e-4 after: the force's step at the cutoff, crossed twice


def test_head_on_collision_reaching_0p21_r0_conserves_energy():
    # 170 km/s relative brings the pair to 0.214 r0, near the table's end (0.2 r0)
    rmin, turn, err, after = _head_on(170 * units.km_s)
    assert rmin == pytest.approx(turn, abs=2e-3) and R_MIN_FACTOR < rmin < 0.22
    assert after < 2e-5 and err < 0.02
    # the error during the collision is velocity Verlet's O(dt^2) offset, not the table's
    _, _, err_half, after_half = _head_on(170 * units.km_s, factor=0.015)
    assert 3.5 < err / err_half < 4.5 and after_half < 2e-5
