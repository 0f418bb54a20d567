"""Momentum, angular momentum and energy of a free, spinning, deforming body; rigid rotation."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clusterdyn.build.mca import mca_packing
from clusterdyn.mca.calculator import MCA
from clusterdyn.mca.dynamics import MCADynamics, wave_speeds
from clusterdyn.analysis.mca_elastic import elastic_material



def momenta(atoms, dyn):
    m = atoms.get_masses()[:, None]
    v = atoms.get_velocities()
    P = (m * v).sum(0)
    L = np.cross(atoms.positions, m * v).sum(0) + (dyn.J[:, None] * atoms.arrays["omega"]).sum(0)
    return P, L


def spinning_body(packing="fcc", nu=0.25, seed=1):
    mat = elastic_material(nu)
    atoms = mca_packing(mat, 1.0, (4, 4, 4), packing)
    atoms.calc = MCA()
    cl, _ = wave_speeds(mat)
    rng = np.random.default_rng(seed)
    x = atoms.positions - atoms.get_center_of_mass()
    W = np.array([0.1, 0.2, 0.3]) * cl / 10
    atoms.set_velocities(np.cross(W, x) + rng.normal(size=x.shape) * cl * 1e-3)
    atoms.arrays["omega"][:] = W + rng.normal(size=x.shape) * cl * 1e-3
    return atoms


def test_conservation_10k_steps():
    atoms = spinning_body()
    dyn = MCADynamics(atoms)
    P0, L0 = momenta(atoms, dyn)
    E0 = dyn.total_energy()
    E_in = sum(dyn.kinetic_energy())
    drift = []
    for _ in range(10):
        dyn.run(1000)
        drift.append(abs(dyn.total_energy() - E0) / E_in)
    P, L = momenta(atoms, dyn)
    scale = np.abs(atoms.get_masses()[:, None] * atoms.get_velocities()).sum()
    assert np.abs(P - P0).max() < 1e-12 * scale
    assert np.abs(L - L0).max() < 1e-12 * np.abs(L0).max()
    assert max(drift) < 1e-3
    assert dyn.stored_work > 1e-3 * E_in          # the body did deform


@pytest.mark.parametrize("packing", ["fcc", "random"])
def test_rigid_rotation_no_stress(packing):
    atoms = mca_packing(elastic_material(0.3), 1.0, (4, 4, 4), packing)
    atoms.calc = MCA()
    atoms.calc.setup(atoms)
    rv = np.array([0.3, -0.5, 0.4])               # ~40 degrees in one go
    R = Rotation.from_rotvec(rv).as_matrix()
    c = atoms.positions.mean(axis=0)
    atoms.positions = (atoms.positions - c) @ R.T + c + np.array([1.0, 2.0, -3.0])
    atoms.arrays["theta"][:] = rv
    s = atoms.calc.get_property("automaton_stresses", atoms)
    f = atoms.get_forces()
    t = atoms.calc.get_property("torques", atoms)
    E = elastic_material(0.3).E
    assert np.abs(s).max() < 1e-12 * E
    assert np.abs(f).max() < 1e-12 * E
    assert np.abs(t).max() < 1e-12 * E


def test_restart_bit_for_bit():
    atoms = spinning_body()
    dyn = MCADynamics(atoms)
    dyn.run(50)
    snap = atoms.copy()
    state = dyn.get_state()
    dyn.run(50)
    a2 = snap
    a2.calc = MCA()
    dyn2 = MCADynamics(a2, state=state)
    dyn2.run(50)
    assert np.array_equal(a2.positions, atoms.positions)
    assert np.array_equal(a2.get_velocities(), atoms.get_velocities())
    assert np.array_equal(a2.arrays["omega"], atoms.arrays["omega"])
    assert np.array_equal(dyn2.state.sig_p2, dyn.state.sig_p2)
    assert dyn2.stored_work == dyn.stored_work


def test_state_invalidates_cache():
    atoms = mca_packing(elastic_material(0.25), 1.0, (4, 4, 4), "sc")
    atoms.calc = MCA()
    atoms.positions[5, 0] += 0.01
    f1 = atoms.get_forces()
    atoms.arrays["theta"][5, 2] = 0.01           # only a state array changes
    f2 = atoms.get_forces()
    assert not np.array_equal(f1, f2)
    st = atoms.calc.state
    st.sig_p2 = st.sig_p2 + 1e-3
    st.version += 1
    f3 = atoms.get_forces()
    assert not np.array_equal(f2, f3)
