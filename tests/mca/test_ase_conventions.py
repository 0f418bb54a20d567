"""The MCA calculator follows ASE's conventions (#46 item 14): extensive per-automaton ``stresses``
that sum to ``stress``, filled ``parameters``/``todict()``, a total energy (MDLogger's Etot) that
includes rotation and stored work, and a warning under an ASE integrator."""

import io
import warnings

import numpy as np
import pytest
from ase.md import MDLogger
from ase.md.verlet import VelocityVerlet

from clusterdyn.build.mca import mca_packing
from clusterdyn.mca.calculator import MCA
from clusterdyn.mca.dynamics import MCADynamics, wave_speeds
from clusterdyn.analysis.mca_elastic import elastic_material


def _body(seed=1, cell=True):
    mat = elastic_material(0.25)
    atoms = mca_packing(mat, 1.0, (3, 3, 3), "fcc")
    if cell:
        atoms.cell = np.diag(np.ptp(atoms.positions, axis=0) + 1.0)
    atoms.calc = MCA()
    cl, _ = wave_speeds(mat)
    rng = np.random.default_rng(seed)
    x = atoms.positions - atoms.get_center_of_mass()
    W = np.array([0.1, 0.2, 0.3]) * cl / 10
    atoms.set_velocities(np.cross(W, x) + rng.normal(size=x.shape) * cl * 1e-3)
    atoms.arrays["omega"][:] = W + rng.normal(size=x.shape) * cl * 1e-3
    return atoms


def test_stresses_are_extensive_and_sum_to_the_stress():
    atoms = _body()
    atoms.positions += np.random.default_rng(0).normal(0, 0.01, atoms.positions.shape)  # strained
    calc = atoms.calc
    stress = atoms.get_stress()
    per = atoms.get_stresses()
    np.testing.assert_allclose(per.sum(axis=0), stress, rtol=1e-12, atol=1e-12 * np.abs(stress).max())
    sig = calc.get_property("automaton_stresses", atoms)         # the automata's own tensors
    om = calc.state.per_atom("omega_n", atoms)
    np.testing.assert_allclose(per, sig * (om / atoms.get_volume())[:, None], rtol=1e-12)
    assert np.abs(stress).max() > 0
    d = calc.todict()
    assert d["materials"] == [calc.state.materials[0].name] and d["dim"] == 3
    assert calc.parameters["materials"] == d["materials"]


def test_total_energy_includes_rotation_and_stored_work_and_is_conserved():
    atoms = _body()
    dyn = MCADynamics(atoms)
    assert atoms.calc.todict()["materials"] == [atoms.calc.state.materials[0].name]
    log = io.StringIO()
    dyn.attach(MDLogger(dyn, atoms, log, peratom=False), interval=50)
    E0 = atoms.get_total_energy()
    assert E0 == pytest.approx(dyn.total_energy(), rel=1e-12)
    dyn.run(400)
    assert atoms.get_total_energy() == pytest.approx(dyn.total_energy(), rel=1e-12)
    assert dyn.stored_work > 0
    kt, kr = dyn.kinetic_energy()
    assert kr > 0.05 * kt                      # a spinning body: rotation is a fair share
    etot = np.array([float(s.split()[1]) for s in log.getvalue().splitlines()[1:]])
    assert len(etot) == 9
    # MDLogger's Etot (eV) conserved to the MCA integration error; without rotation it would
    # be off by the rotational energy
    assert np.ptp(etot) < 1e-3 * (kt + kr)
    assert kr > 100 * np.ptp(etot)


def test_an_ase_integrator_warns_that_it_ignores_rotations():
    atoms = _body(cell=False)
    dyn = VelocityVerlet(atoms, timestep=1e-3 * MCADynamics(_body(cell=False)).dt)
    with pytest.warns(UserWarning, match="VelocityVerlet drives an MCA calculator: it ignores"):
        dyn.run(2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")         # once
        dyn.run(1)
    atoms.cell = np.zeros((3, 3))                # no cell: no volume to divide by
    with pytest.raises(Exception, match="3D cell"):
        atoms.get_stresses()
    assert atoms.calc.get_property("automaton_stresses", atoms).shape == (len(atoms), 6)
