"""ClusterDynamics as an ASE calculator: finite differences, the cold curve, ASE contracts."""

import numpy as np
import pytest
from ase.calculators.fd import calculate_numerical_forces
from ase.optimize import FIRE

from clusterdyn import units
from clusterdyn.build import fcc_packing, make_cluster_atoms
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError, InstabilityError
from clusterdyn.materials import get_material

R0 = 5 * units.um


def two_material_sample(n_target=500, seed=0):
    rng = np.random.default_rng(seed)
    base = fcc_packing("Al", R0, size=(5, 5, 5))
    pos = base.positions[:n_target] + rng.normal(0, 0.04 * R0, (n_target, 3))
    mid = (rng.random(n_target) < 0.4).astype(int)
    return make_cluster_atoms(pos, ["Al", "Pb"], [R0, 0.9 * R0], material_id=mid,
                              cell=base.cell, pbc=False)


def test_forces_are_minus_energy_gradient_two_materials():
    atoms = two_material_sample()
    assert len(atoms) == 500 and set(atoms.arrays["material"]) == {0, 1}
    atoms.calc = ClusterDynamics()
    F = atoms.get_forces()
    Fn = calculate_numerical_forces(atoms, eps=1e-6 * R0)
    assert np.abs(F - Fn).max() < 1e-6 * np.abs(F).max()
    assert np.abs(F.sum(axis=0)).max() < 1e-9 * np.abs(F).max()         # Newton's third law


def test_stress_matches_numerical_and_per_particle_sums():
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    atoms.positions += np.random.default_rng(1).normal(0, 0.03 * R0, atoms.positions.shape)
    atoms.calc = ClusterDynamics()
    s = atoms.get_stress()
    # normal components by finite differences of the energy under normal strain
    # (shear strains would make the cell triclinic, which periodic boxes refuse)
    V = atoms.get_volume()
    eps = 1e-7
    for d in range(3):
        e = []
        for sign in (1, -1):
            a = atoms.copy()
            a.calc = ClusterDynamics()
            strain = np.eye(3)
            strain[d, d] += sign * eps
            a.set_cell(atoms.cell @ strain, scale_atoms=True)
            e.append(a.get_potential_energy())
        assert (e[0] - e[1]) / (2 * eps * V) == pytest.approx(s[d], rel=1e-5)
    np.testing.assert_allclose(atoms.get_stresses().sum(axis=0), s, rtol=1e-10, atol=1e-20)
    assert atoms.get_potential_energies().sum() == pytest.approx(atoms.get_potential_energy(), rel=1e-12)


@pytest.mark.parametrize("direction", ["100", "110", "111"])
def test_lattice_at_rest_has_zero_force_and_stress(direction):
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), direction=direction, pbc=True)
    atoms.calc = ClusterDynamics()
    f = atoms.get_forces()
    scale = ClusterDynamics().__class__ and get_material("Al").curve.K0
    assert np.abs(f).max() < 1e-8 * units.N
    assert np.abs(atoms.get_stress()).max() < 1e-12 * scale


@pytest.mark.parametrize("delta", [0.7, 0.8, 0.9, 1.1, 1.3, 1.5, 1.7, 1.8])
def test_virial_pressure_equals_cold_curve(delta):
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    atoms.set_cell(atoms.cell * delta ** (-1.0 / 3.0), scale_atoms=True)
    atoms.calc = ClusterDynamics()
    P = -atoms.get_stress()[:3].mean()
    Px = get_material("Al").curve.pressure(delta)
    assert P == pytest.approx(Px, rel=5e-3)
    assert np.abs(atoms.get_stress()[3:]).max() < 1e-9 * abs(Px)


def test_cache_sees_material_changes_and_computes_only_what_is_asked():
    atoms = two_material_sample(200)
    calc = ClusterDynamics()
    atoms.calc = calc
    e1 = atoms.get_potential_energy()
    assert "energies" not in calc.results
    mid = atoms.arrays["material"].copy()
    mid[:50] = 1 - mid[:50]
    atoms.arrays["material"] = mid
    e2 = atoms.get_potential_energy()
    assert e1 != e2
    atoms.get_potential_energies()
    assert "energies" in calc.results


def test_energy_without_forces_is_the_same_pass():
    """``compute(forces=False)``: the same energy and per-particle virials as with forces, no
    forces made; refused with damping, a kick or an output array."""
    atoms = two_material_sample(300)
    calc = ClusterDynamics()
    atoms.calc = calc
    for pp in (False, True):
        full = calc.compute(atoms, per_particle=pp)
        lean = calc.compute(atoms, per_particle=pp, forces=False)
        assert lean["forces"] is None and full["forces"].shape == (300, 3)
        assert lean["energy"] == full["energy"] and np.array_equal(lean["virial"], full["virial"])
        if pp:
            assert np.array_equal(lean["virials"], full["virials"])
            assert np.array_equal(lean["energies"], full["energies"])
    p = atoms.get_momenta()
    for kw in ({"out": np.empty((300, 3))}, {"kick": (p, 1.0)},
               {"damping": (p, 1 / atoms.get_masses(), calc.damping_matrix(50))}):
        with pytest.raises(InputError, match="forces"):
            calc.compute(atoms, forces=False, **kw)


def test_works_in_ase_fire():
    atoms = fcc_packing("Al", R0, size=(2, 2, 2), pbc=True)
    atoms.positions += np.random.default_rng(3).normal(0, 0.05 * R0, atoms.positions.shape)
    atoms.calc = ClusterDynamics()
    c0 = get_material("Al").c0
    # FIRE's defaults are atomic-scale (maxstep 0.2 A); give it mesoscale ones
    opt = FIRE(atoms, logfile=None, dt=0.1 * R0 / c0, dtmax=0.3 * R0 / c0, maxstep=0.05 * R0)
    opt.run(fmax=1e-6 * units.N, steps=3000)
    assert np.abs(atoms.get_forces()).max() < 1e-6 * units.N


def test_errors():
    atoms = fcc_packing("Al", R0, size=(2, 2, 2), pbc=True)
    with pytest.raises(InputError, match="rc="):
        ClusterDynamics(rc=1.5)
    with pytest.raises(InputError, match="material='Kryptonite'"):
        a = atoms.copy()
        a.calc = ClusterDynamics(materials=["Kryptonite"], r0=R0)
        a.get_forces()
    b = atoms.copy()
    b.set_cell([[atoms.cell[0, 0], 0, 0], [1.0, atoms.cell[1, 1], 0], [0, 0, atoms.cell[2, 2]]])
    b.calc = ClusterDynamics()
    with pytest.raises(InputError, match="orthorhombic"):
        b.get_forces()
    c = atoms.copy()
    c.positions[1] = c.positions[0] + [0.2 * R0, 0, 0]
    c.calc = ClusterDynamics()
    with pytest.raises(InstabilityError, match=r"particles 0, 1.*distance r/r0 = 0.2"):
        c.get_forces()
