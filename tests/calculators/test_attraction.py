"""attraction='initial': pairs bonded at set-up attract, pairs that meet later only repel."""

import numpy as np
import pytest
from ase.calculators.fd import calculate_numerical_forces

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics, mark_initial_bonds
from clusterdyn.errors import InputError

R0 = 5 * units.um


def test_bonds_of_a_lattice():
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    b = mark_initial_bonds(atoms)
    assert b.shape == (len(atoms), 12) and (b >= 0).all()


def test_bonds_within_labels():
    """Only pairs with equal labels >= 0 are bonded: e.g. no attraction across grain boundaries."""
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=True)
    x = atoms.get_scaled_positions()[:, 0]
    label = np.where(x < 0.5, 0, 1)
    label[0] = -1
    atoms.new_array("grain", label)
    b = mark_initial_bonds(atoms, within="grain")
    ids = atoms.arrays["id"]
    n_bonded = 0
    for i in range(len(atoms)):
        partners = b[i][b[i] >= 0]
        n_bonded += len(partners)
        j = np.searchsorted(ids, partners)
        assert (label[j] == label[i]).all() and (len(partners) == 0 or label[i] >= 0)
    assert len(b[0][b[0] >= 0]) == 0 and 0 < n_bonded < 12 * len(atoms)
    with pytest.raises(InputError, match="within"):
        mark_initial_bonds(atoms, within="no_such_array")


def test_conservative_with_new_contacts():
    atoms = fcc_packing("Al", R0, size=(4, 4, 4), pbc=False)
    mark_initial_bonds(atoms)
    rng = np.random.default_rng(5)
    atoms.positions += rng.normal(0, 0.08 * R0, atoms.positions.shape)
    atoms.calc = ClusterDynamics(attraction="initial")
    F = atoms.get_forces()
    Fn = calculate_numerical_forces(atoms, eps=1e-6 * R0)
    assert np.abs(F - Fn).max() < 1e-6 * np.abs(F).max()
    # unlike 'all', where the new pairs attract as well
    b = atoms.copy()
    b.calc = ClusterDynamics()
    assert np.abs(b.get_forces() - F).max() > 1e-3 * np.abs(F).max()


def longitudinal_stress(eta, attraction):
    """-sigma_xx of a [100] lattice compressed uniaxially to x-length (1 - eta)."""
    atoms = fcc_packing("Al", R0, size=(4, 4, 4), pbc=True)
    mark_initial_bonds(atoms)
    cell = atoms.cell.array.copy()
    cell[0, 0] *= 1 - eta
    atoms.set_cell(cell, scale_atoms=True)
    atoms.calc = ClusterDynamics(attraction=attraction)
    return -atoms.get_stress()[0]


def test_uniaxial_compression_stiffens_only_with_initial_bonds():
    # second neighbours along x (at sqrt(2) r0 at rest) enter rc = 1.15 r0 past rho/rho0 ~ 1.23
    # (rho/rho0 = 1/(1 - eta)); they are on the attractive branch until eta ~ 0.293
    etas = np.linspace(0.10, 0.28, 10)
    s_all = np.array([longitudinal_stress(e, "all") for e in etas])
    s_ini = np.array([longitudinal_stress(e, "initial") for e in etas])
    assert np.all(np.diff(s_ini) > 0)                      # monotone with initial bonds
    assert np.any(np.diff(s_all) < 0)                       # softening with all pairs attracting
    early = etas < 0.185
    np.testing.assert_allclose(s_all[early], s_ini[early], rtol=1e-12)
    assert np.all(s_ini[~early] > 1.05 * s_all[~early])


def test_requires_setup_bonds():
    atoms = fcc_packing("Al", R0, size=(2, 2, 2), pbc=True)
    atoms.calc = ClusterDynamics(attraction="initial")
    with pytest.raises(InputError, match="bonds0"):
        atoms.get_forces()
    with pytest.raises(InputError, match="attraction="):
        ClusterDynamics(attraction="sometimes")
