"""DampedVerlet: energy conservation, damping, momentum, ASE compatibility, stability guards."""

import numpy as np
import pytest
from ase.md.verlet import VelocityVerlet

from clusterdyn import units
from clusterdyn.build import fcc_packing, make_cluster_atoms
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError, InstabilityError
from clusterdyn.md import DampedVerlet, Piston, default_timestep, stability_limit

R0 = 5 * units.um


def thermal(atoms, frac=0.01, seed=0):
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    c0 = atoms.calc.potentials[0].c0
    v = np.random.default_rng(seed).normal(0, frac * c0 / np.sqrt(3), (len(atoms), 3))
    v -= v.mean(axis=0)
    atoms.set_velocities(v)
    return c0


def test_energy_conserved_undamped_4000():
    atoms = fcc_packing("Al", R0, size=(10, 10, 10), pbc=True)
    assert len(atoms) == 4000
    thermal(atoms)
    dyn = DampedVerlet(atoms, J=None)
    E0 = dyn.get_total_energy()
    K0 = dyn.get_kinetic_energy()
    worst = 0.0
    for _ in range(50):
        dyn.run(200)
        worst = max(worst, abs(dyn.get_total_energy() - E0))
    assert dyn.nsteps == 10_000
    assert worst < 1e-3 * K0


def test_same_trajectory_as_ase_velocity_verlet():
    a = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    thermal(a, 0.02, seed=4)
    b = a.copy()
    b.calc = ClusterDynamics()
    d1 = DampedVerlet(a, J=None)
    d2 = VelocityVerlet(b, timestep=d1.dt)
    d1.run(300)
    d2.run(300)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-9 * R0)
    np.testing.assert_allclose(a.get_velocities(), b.get_velocities(), rtol=1e-8, atol=1e-12)


def test_damping_conserves_momentum_and_dissipates_two_materials():
    base = fcc_packing("Al", R0, size=(4, 4, 4), pbc=True)
    rng = np.random.default_rng(2)
    mid = (rng.random(len(base)) < 0.5).astype(int)
    atoms = make_cluster_atoms(base.positions, ["Al", "Pb"], [R0, R0], material_id=mid,
                               cell=base.cell, pbc=True)
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    v = rng.normal(0, 50 * units.m_s, (len(atoms), 3))
    atoms.set_velocities(v + np.array([100.0, 200.0, -100.0]) * units.m_s)     # and a net drift
    p0 = atoms.get_momenta().sum(axis=0)
    dyn = DampedVerlet(atoms, J=50)
    windows = []
    for _ in range(10):
        es = []
        for _ in range(10):
            dyn.run(10)
            es.append(dyn.get_total_energy())
        windows.append(np.mean(es))
    p1 = atoms.get_momenta().sum(axis=0)
    scale = np.abs(atoms.get_momenta()).sum()
    assert np.abs(p1 - p0).max() < 1e-12 * scale
    assert np.all(np.diff(windows) < 0)


def test_run_twice_adds_steps_and_observers():
    atoms = fcc_packing("Al", R0, size=(2, 2, 2), pbc=True)
    thermal(atoms)
    dyn = DampedVerlet(atoms, J=None)
    seen = []
    dyn.attach(lambda: seen.append(dyn.nsteps), interval=5)
    dyn.run(10)
    dyn.run(10)
    assert dyn.nsteps == 20 and seen == [0, 5, 10, 15, 20]


def test_piston_moves_at_its_speed():
    atoms = fcc_packing("Al", R0, size=(6, 2, 2), pbc=(False, True, True))
    mask = atoms.positions[:, 0] < 0.5 * R0
    u = 1 * units.km_s
    atoms.set_constraint(Piston(mask, u))
    atoms.calc = ClusterDynamics()
    atoms.set_momenta(atoms.get_momenta())
    x0 = atoms.positions[mask, 0].copy()
    dyn = DampedVerlet(atoms, J=None)
    dyn.run(100)
    np.testing.assert_allclose(atoms.positions[mask, 0] - x0, u * dyn.get_time(), rtol=1e-12)
    assert atoms.constraints[0].force[0] < 0          # the compressed sample pushes back


def test_bad_input():
    atoms = fcc_packing("Al", R0, size=(2, 2, 2), pbc=True)
    atoms.calc = ClusterDynamics()
    for J in (0, -5, "x"):
        with pytest.raises(InputError, match="J="):
            DampedVerlet(atoms, J=J)
    atoms.calc.setup(atoms)
    lim = stability_limit(atoms.calc)
    assert lim == pytest.approx(0.58 * R0 / atoms.calc.potentials[0].c0, rel=0.05)
    with pytest.raises(InputError, match="timestep=.*stability"):
        DampedVerlet(atoms, timestep=1.01 * lim, J=None)
    with pytest.raises(InputError, match="timestep="):
        DampedVerlet(atoms, timestep=-1.0, J=None)
    assert default_timestep(atoms.calc) < 0.06 * lim


def test_close_approach_during_run_is_an_instability():
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    atoms.calc = ClusterDynamics()
    v = np.zeros((len(atoms), 3))
    # two neighbours driven head-on, far faster than the lattice can hold them apart
    i = 0
    j = int(np.argmin(np.linalg.norm(atoms.positions - atoms.positions[0] - [0, R0 / 2 ** 0.5, R0 / 2 ** 0.5], axis=1)))
    d = atoms.positions[j] - atoms.positions[i]
    d /= np.linalg.norm(d)
    v[i] = 60 * units.km_s * d
    v[j] = -60 * units.km_s * d
    atoms.set_velocities(v)
    dyn = DampedVerlet(atoms, timestep=0.02 * R0 / (5.3 * units.km_s), J=None)
    with pytest.raises(InstabilityError) as exc:
        dyn.run(2000)
    msg = str(exc.value)
    assert "step" in msg and (f"particles {min(i, j)}, {max(i, j)}" in msg or "particle" in msg)
    assert exc.value.step is not None and exc.value.step > 0


def test_stiffness_check_uses_the_closest_pairs_own_law():
    """A compressed soft pair is judged by its own stiffness, not the stiffest material's."""
    from clusterdyn.md import pair_stability_limit
    base = fcc_packing("Al", R0, size=(2, 2, 2), pbc=True)
    atoms = make_cluster_atoms(base.positions, ["Pb", "h-BN"], [R0, R0],
                               material_id=np.arange(len(base)) % 2, cell=base.cell, pbc=True)
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    c = atoms.calc
    r = 0.7 * R0
    lim_pb, lim_bn = pair_stability_limit(c, 0, 0, r), pair_stability_limit(c, 1, 1, r)
    lim_mix = pair_stability_limit(c, 0, 1, r)
    assert lim_bn < lim_pb                       # h-BN (n = 10.4) stiffens far more than Pb (n = 3)
    assert lim_bn < lim_mix < lim_pb             # two halves in series: in between
    assert pair_stability_limit(c, 0, 0, R0) == pytest.approx(
        2 / np.sqrt(8 * c.potentials[0].stiffness() / c.potentials[0].mass))


@pytest.mark.parametrize("J", [None, 50.0])
def test_fused_passes_give_the_separate_passes_trajectory(J):
    """The kicks and drift fused into the calculator's streaming passes change nothing, bit for bit,
    through list rebuilds, and the potential energy computed when read is the step's own."""
    from clusterdyn.scenes.shock import build_shock
    runs = []
    for fused in (True, False):
        s = build_shock(size=(30, 3, 3), u=3 * units.km_s, J=J)
        calls = []
        adv = s.calc.engine.advance
        s.calc.engine.advance = (lambda *a, _adv=adv, _c=calls: _c.append(1) or _adv(*a)) if fused \
            else (lambda *a: None)
        s.dyn.run(80)
        assert s.calc.nl.nbuilds > 2
        assert (len(calls) == 80) == fused
        runs.append((s.atoms.positions.copy(), s.atoms.get_momenta(), s.dyn.forces.copy(),
                     s.dyn.potential_energy, s.calc.compute(s.atoms, virial=False)["energy"]))
    (x1, p1, f1, e1, c1), (x2, p2, f2, e2, c2) = runs
    assert np.array_equal(x1, x2) and np.array_equal(p1, p2) and np.array_equal(f1, f2)
    assert e1 == e2 == c1 == c2


def test_a_calculator_put_on_the_atoms_later_is_used():
    """As ASE's dynamics do, the step uses whatever atoms.calc is now (checked as at construction)."""
    from ase.calculators.lj import LennardJones
    a = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    thermal(a, 0.02, seed=5)
    b = a.copy()
    d1 = DampedVerlet(a, J=50)
    d1.run(5)
    b.positions[:] = a.positions
    b.set_momenta(a.get_momenta())
    new = ClusterDynamics(skin=0.1, n_table=4000)
    a.calc = new
    b.calc = ClusterDynamics(skin=0.1, n_table=4000)
    d2 = DampedVerlet(b, timestep=d1.dt, J=50)
    d1.run(20)
    d2.run(20)
    assert d1.calc is new and new.nl is not None
    np.testing.assert_array_equal(a.positions, b.positions)
    # damping needs ClusterDynamics: refused at the next step, naming the argument
    a.calc = LennardJones()
    with pytest.raises(InputError, match="atoms.calc=.*ClusterDynamics"):
        d1.run(1)


def test_ase_users_pitfalls_are_refused_or_warned():
    """Negative step counts are refused; atomic masses on a cluster packing are refused with the fix;
    an atom-scale time step (1 fs against a stable step of tens of ps) is warned about."""
    import warnings
    from ase import units as U
    from clusterdyn.build import fcc_packing
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.errors import InputError
    from clusterdyn.md import DampedVerlet
    a = fcc_packing("Al", r0=5e4, size=(3, 3, 3), pbc=True)
    a.calc = ClusterDynamics()
    dyn = DampedVerlet(a, J=None)
    with pytest.raises(InputError, match="steps"):
        dyn.run(-5)
    with pytest.raises(InputError, match="steps"):
        dyn.run(2.5)
    b = a.copy()
    b.calc = ClusterDynamics()
    b.set_masses(np.full(len(b), 26.98))
    with pytest.raises(InputError, match="set_masses"):
        DampedVerlet(b, J=None)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        DampedVerlet(a, timestep=1 * U.fs, J=None)
    assert any("timestep" in str(x.message) and "default" in str(x.message) for x in w)
