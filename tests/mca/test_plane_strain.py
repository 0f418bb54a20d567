"""2D plane strain: automata are cylinders of unit thickness; elasticity and a short run."""

import numpy as np
import pytest

from clusterdyn.build.mca import mca_packing
from clusterdyn.mca.calculator import MCA
from clusterdyn.mca.dynamics import MCADynamics
from clusterdyn.analysis.mca_elastic import elastic_material


@pytest.mark.parametrize("packing", ["hex", "sc", "random"])
@pytest.mark.parametrize("nu", [0.1, 0.4])
def test_plane_strain_constants(packing, nu):
    mat = elastic_material(nu)
    atoms = mca_packing(mat, 1.0, (8.0, 8.0), packing, pbc=True)
    assert atoms.info["mca_dim"] == 2
    atoms.calc = MCA()
    atoms.calc.setup(atoms)
    e = 1e-6
    F = np.eye(3)
    F[0, 0] += e
    atoms.set_cell(atoms.cell.array @ F, scale_atoms=True)
    if packing == "random":
        MCADynamics(atoms, damping=0.15).run(300)
    s = atoms.calc.get_property("automaton_stresses", atoms)
    om = atoms.calc.state.per_atom("omega_n", atoms)
    sxx = (s[:, 0] * om).sum() / om.sum() / e
    syy = (s[:, 1] * om).sum() / om.sum() / e
    lam = mat.K - 2 * mat.G / 3
    tol = 0.10 if packing == "random" else 0.01
    assert sxx == pytest.approx(lam + 2 * mat.G, rel=tol)
    assert syy == pytest.approx(lam, rel=tol)


def test_plane_strain_motion_stays_in_plane():
    atoms = mca_packing(elastic_material(0.3), 1.0, (8.0, 6.0), "hex")
    atoms.calc = MCA()
    atoms.calc.setup(atoms)
    rng = np.random.default_rng(0)
    v = np.zeros((len(atoms), 3))
    v[:, :2] = rng.normal(size=(len(atoms), 2)) * 1e-3
    atoms.set_velocities(v)
    atoms.arrays["omega"][:, 2] = rng.normal(size=len(atoms)) * 1e-3
    dyn = MCADynamics(atoms)
    e0 = dyn.total_energy()
    dyn.run(500)
    assert np.all(atoms.positions[:, 2] == 0.0)
    assert np.all(atoms.arrays["omega"][:, :2] == 0.0)
    assert abs(dyn.total_energy() - e0) < 1e-2 * e0
