"""The grain-boundary pair law (clusterdyn.md.boundary; docs/theory.md 1.11)."""

import numpy as np
import pytest
from ase import Atoms

from clusterdyn import units
from clusterdyn.build import Box, polycrystal
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError
from clusterdyn.io.checkpoint import load_run, save_run
from clusterdyn.md import DampedVerlet
from clusterdyn.md.boundary import FROZEN, J_M2, UPDATE, BoundaryLaw, apply_boundary_law

R0 = 10 * units.um


def _pair(r_over_r0, law, material="Al"):
    """Two clusters in one 'grain' each, at r: one boundary bond."""
    atoms = Atoms("X2", positions=[[0, 0, 0], [1.0 * R0, 0, 0]], cell=[10 * R0] * 3, pbc=False)
    atoms.info["cd_materials"] = [material]
    atoms.info["cd_r0"] = [R0]
    atoms.new_array("grain", np.array([0, 1]))
    from clusterdyn.potentials import ClusterPotential
    atoms.set_masses([ClusterPotential(material, R0).mass] * 2)
    calc, term = apply_boundary_law(atoms, law)
    atoms.positions[1, 0] = r_over_r0 * R0
    return atoms, calc, term


def _cube(law, seed=1):
    L = 9 * R0
    atoms = polycrystal("Al", R0, Box((0, 0, 0), (L, L, L)), grain_size=4.5 * R0, seed=seed, pbc=True)
    calc, term = apply_boundary_law(atoms, law)
    return atoms, calc, term


LAW = BoundaryLaw(sigma_t=1.0 * units.GPa, G_c=2000 * J_M2, tau_c=0.3 * units.GPa, mu=0.3)


def test_bond_curve_peak_softening_and_failure_is_permanent():
    law = BoundaryLaw(sigma_t=1.0 * units.GPa, G_c=2000 * J_M2)
    atoms, calc, term = _pair(1.0, law)
    ft, d0, df = term.ft[0], term.d0[0], term.df[0]
    assert ft == pytest.approx(1.0 * units.GPa * R0 ** 2 / (2 * np.sqrt(2)))
    # area under the envelope = W_b = G_c r0^2 / 4
    assert 0.5 * ft * df == pytest.approx(2000 * J_M2 * R0 ** 2 / 4)
    force = []
    for d in np.linspace(0, 1.2 * df, 601):
        atoms.positions[1, 0] = R0 + d
        f = term.forces(atoms, mode=UPDATE)
        force.append(f[0, 0])
    force = np.array(force)
    assert force.max() == pytest.approx(ft, rel=0.03)          # the peak is the tensile strength
    assert force[-1] == 0.0 and term.failed()[0]
    # back to a small opening: still failed (no cohesion), and the repulsion is the calculator's
    atoms.positions[1, 0] = R0 + 0.5 * d0
    assert term.forces(atoms, mode=UPDATE)[0, 0] == 0.0
    assert term.failed()[0]
    # the work of separation (G_c r0^2/4) dissipated, to the sampling of the path (601 points)
    assert term.dissipated == pytest.approx(0.5 * ft * df, rel=0.01)


def test_damaged_bond_unloads_to_origin():
    law = BoundaryLaw(sigma_t=1.0 * units.GPa, G_c=2000 * J_M2)
    atoms, calc, term = _pair(1.0, law)
    d0, df, ft = term.d0[0], term.df[0], term.ft[0]
    kmax = d0 + 0.5 * (df - d0)
    atoms.positions[1, 0] = R0 + kmax
    f_peak = term.forces(atoms, mode=UPDATE)[0, 0]
    assert f_peak == pytest.approx(0.5 * ft)
    atoms.positions[1, 0] = R0 + 0.5 * kmax
    assert term.forces(atoms, mode=UPDATE)[0, 0] == pytest.approx(0.25 * ft)   # secant unloading


@pytest.mark.parametrize("stretch", [0.0, 0.02])
def test_forces_are_the_energy_gradient_at_fixed_history(stretch):
    """The normal part is conservative at fixed damage (the tangential spring is incremental:
    path-dependent, not a potential; its forces are checked for momentum and the cap below)."""
    atoms, calc, term = _cube(BoundaryLaw(sigma_t=1.0 * units.GPa, G_c=2000 * J_M2))
    rng = np.random.default_rng(3)
    atoms.set_cell(atoms.cell.array * (1 + stretch), scale_atoms=True)
    atoms.positions += rng.normal(0, 0.01 * R0, atoms.positions.shape)
    atoms.set_momenta(rng.normal(0, 1, atoms.positions.shape) * atoms.get_masses()[:, None] * 50 * units.m_s)
    dyn = DampedVerlet(atoms, timestep=0.05 * R0 / (5 * units.km_s), J=None)
    dyn.attach_piece(term)
    dyn.run(5)       # history: tangential displacements and some damage
    f = term.forces(atoms, mode=FROZEN)
    assert np.abs(f.sum(axis=0)).max() <= 1e-12 * np.abs(f).max()       # momentum
    h = 1e-5 * R0
    sel = np.flatnonzero(np.abs(f).sum(axis=1) > 0)[:12]
    for k in sel:
        for c in range(3):
            atoms.positions[k, c] += h
            ep = term.evaluate(atoms, mode=FROZEN)
            atoms.positions[k, c] -= 2 * h
            em = term.evaluate(atoms, mode=FROZEN)
            atoms.positions[k, c] += h
            assert -(ep - em) / (2 * h) == pytest.approx(f[k, c], rel=1e-5, abs=1e-7 * np.abs(f).max())


def test_shear_cap_is_coulomb_plus_cohesion():
    law = BoundaryLaw(sigma_t=1.0 * units.GPa, G_c=2000 * J_M2, tau_c=0.2 * units.GPa, mu=0.5)
    atoms, calc, term = _pair(0.95, law)
    nc = float(calc.law(0, 0).force(0.95 * R0))
    cap = term.fs[0] + 0.5 * nc
    atoms.set_momenta(np.zeros((2, 3)))
    atoms.arrays["momenta"][1, 1] = atoms.get_masses()[1] * 10 * units.m_s     # slide j along y
    dt = 0.1 * R0 / (10 * units.m_s)          # one step moves it 0.1 r0: far beyond the elastic range
    term.evaluate(atoms, 1.0 / atoms.get_masses(), dt, mode=UPDATE)
    f = np.zeros((2, 3))
    term.scatter(f)
    assert f[0, 1] == pytest.approx(cap, rel=1e-3)       # the spring pulls i along +y at the cap
    assert f[1, 1] == -f[0, 1]
    kt = term.kt[0]
    s_trial = 0.1 * R0
    assert term.lam[0] == pytest.approx(s_trial - cap / kt)
    assert term.dissipated == pytest.approx(0.5 * kt * s_trial ** 2 - 0.5 * cap ** 2 / kt)


def test_off_by_default_and_same_bits_without_a_term():
    """Without a term the dynamics runs as before (the hook loops over an empty list)."""
    def run(attach):
        L = 9 * R0
        atoms = polycrystal("Al", R0, Box((0, 0, 0), (L, L, L)), grain_size=4.5 * R0, seed=2, pbc=True)
        atoms.calc = ClusterDynamics()
        rng = np.random.default_rng(1)
        atoms.set_momenta(rng.normal(0, 1, atoms.positions.shape) * atoms.get_masses()[:, None] * 20 * units.m_s)
        dyn = DampedVerlet(atoms, J=50)
        assert not any(q.adds_forces for q in dyn.pieces)
        dyn.run(20)
        return atoms.positions.copy()
    a = run(False)
    b = run(False)
    assert np.array_equal(a, b)


def test_restart_bit_for_bit_with_history(tmp_path):
    def start():
        atoms, calc, term = _cube(LAW, seed=4)
        atoms.set_cell(atoms.cell.array * 1.01, scale_atoms=True)   # pull: bonds damage
        rng = np.random.default_rng(5)
        atoms.set_momenta(rng.normal(0, 1, atoms.positions.shape) * atoms.get_masses()[:, None] * 30 * units.m_s)
        dyn = DampedVerlet(atoms, J=50)
        dyn.attach_piece(term)
        return atoms, dyn, term
    atoms, dyn, term = start()
    dyn.run(30)
    save_run(tmp_path / "half.h5", dyn)
    dyn.run(30)
    atoms2, dyn2, _ = load_run(tmp_path / "half.h5")
    assert [q.name for q in dyn2.pieces if q.adds_forces] == ["boundary"]
    dyn2.run(30)
    assert np.array_equal(atoms.positions, atoms2.positions)
    assert np.array_equal(atoms.get_momenta(), atoms2.get_momenta())
    t2 = next(q for q in dyn2.pieces if q.adds_forces)
    assert np.array_equal(term.kappa, t2.kappa) and np.array_equal(term.s, t2.s)
    assert (term.kappa > term.d0).any()         # the history was exercised


def test_ledger_closes_with_damage():
    """The damage's dissipation is booked (``term_dissipated``) so the ledger closes to the
    integrator's error (first order in dt here: the damage front is a kink of the force; 3e-3 at
    the default step, 1.5e-3 at half of it).  The incremental tangential spring closes it less
    well (docs/theory.md 1.11: 5% over 200 steps in this pull)."""
    atoms, calc, term = _cube(BoundaryLaw(sigma_t=1.0 * units.GPa, G_c=2000 * J_M2), seed=6)
    atoms.set_cell(atoms.cell.array * 1.005, scale_atoms=True)
    dyn = DampedVerlet(atoms, J=50)
    dyn.attach_piece(term)
    dyn.start_ledger()
    dyn.run(200)
    led = dyn.energy_ledger()
    assert led["term_dissipated"] > 0
    assert abs(led["residual"]) < 5e-3 * (abs(led["potential0"] - led["potential"]) + led["kinetic"])


def test_bad_input_is_refused():
    with pytest.raises(InputError, match="sigma_t"):
        BoundaryLaw(sigma_t=-1, G_c=1)
    with pytest.raises(InputError, match="select"):
        BoundaryLaw(sigma_t=1, G_c=1, select="grain")
    with pytest.raises(InputError, match="G_c"):
        _pair(1.0, BoundaryLaw(sigma_t=5 * units.GPa, G_c=1e-3 * J_M2))


def test_stress_map_with_the_law_matches_the_global_virial():
    """The law's pair stresses are in the stress maps: the per-particle virials with the bonds' share
    (analysis.stress.add_piece_virials) sum to the calculator's virial plus the term's, and a slab
    map over the whole cell integrates to the cell stress from the global virial.  The bonds carry
    a large share of the stress here, so a map without them would miss it."""
    from clusterdyn.analysis.slabs import stress_profile
    from clusterdyn.analysis.stress import add_piece_virials, cell_stress, particle_virials
    atoms, calc, term = _cube(BoundaryLaw(sigma_t=5.0 * units.GPa, G_c=2000 * J_M2), seed=2)
    atoms.set_cell(atoms.cell.array * 1.01, scale_atoms=True)
    dyn = DampedVerlet(atoms, J=50)
    dyn.attach_piece(term)
    dyn.run(5)
    W0 = calc.compute(atoms, per_particle=True, forces=False)["virials"]
    W = add_piece_virials(W0, dyn)
    assert W is not W0 and np.array_equal(W0, particle_virials(atoms))     # the calculator's result untouched
    total = particle_virials(atoms).sum(axis=0) + term.virial
    assert np.allclose(W.sum(axis=0), total, rtol=1e-12, atol=1e-12 * np.abs(total).max())
    assert abs(term.virial[0]) > 0.2 * abs(total[0])                      # the bonds' share matters
    s_global = cell_stress(atoms, np.vstack([particle_virials(atoms), term.virial[None, :]]))
    L = atoms.cell[0, 0]
    prof = stress_profile(atoms, L / 4, virials=W, axis=0, lo=0.0, hi=L)
    vol = atoms.get_volume() / 4
    s_map = (prof["stress"] * vol).sum(axis=0) / atoms.get_volume()
    kin_free = cell_stress(atoms, W)
    assert np.allclose(kin_free, s_global, rtol=1e-12, atol=1e-15)
    # the map's slabs carry the kinetic part about their own mean velocity: equal to the cell's to
    # the velocity noise (5 steps from rest), far below the bonds' share
    assert np.allclose(s_map, s_global, rtol=1e-3, atol=1e-3 * np.abs(s_global).max())
    plain = stress_profile(atoms, L / 4, virials=W0, axis=0, lo=0.0, hi=L)
    assert not np.allclose((plain["stress"] * vol).sum(axis=0) / atoms.get_volume(), s_global, rtol=0.1)
    # no piece: the same array back (the default scenes keep their bits)
    a2 = atoms.copy()
    a2.calc = ClusterDynamics()
    assert add_piece_virials(W0, DampedVerlet(a2, J=50)) is W0
