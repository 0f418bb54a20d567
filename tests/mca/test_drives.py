"""MCA with the drive family: grips as pistons, a traction in 2D, checkpoints through save_run."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build.mca import mca_packing
from clusterdyn.errors import InputError
from clusterdyn.io.checkpoint import load_run, read_checkpoint, save_run
from clusterdyn.materials import get_material
from clusterdyn.mca.calculator import MCA
from clusterdyn.mca.dynamics import MCADynamics, wave_speeds
from clusterdyn.mca.state import ATOM_ARRAYS, PAIR_ARRAYS
from clusterdyn.md import Piston, Traction
from clusterdyn.scenes.mca_experiments import build_uniaxial
from clusterdyn.analysis.mca_elastic import elastic_material
from clusterdyn.scenes.mca_material_point import load_unload_reload

ALUMINA = get_material("alumina")


def tiny_bar(**kw):
    """8 x 3 x 3 alumina bar pulled to 6 sigma_t/E in 400 steps: it cracks from step ~150 on."""
    return build_uniaxial(ALUMINA, "tension", size=(8, 3, 3), steps=400, scatter=0.02, damping=0.05,
                          strain_max=6 * ALUMINA.sigma_t / ALUMINA.E, **kw)


def test_save_run_load_run_is_bit_for_bit_with_a_live_crack(tmp_path):
    s = tiny_bar()
    s.dyn.run(200)
    ck = tmp_path / "ck.h5"
    save_run(ck, s.dyn, {"note": "mid-crack"})
    broken_at_save = int(np.sum(s.dyn.state.linked_p == 0))
    s.dyn.run(200)
    atoms, dyn, extra = load_run(ck)
    assert extra == {"note": "mid-crack"} and type(dyn) is MCADynamics and dyn.nsteps == 200
    assert atoms.info["mca_materials"][0].name == "alumina"          # Material records restored
    dyn.run(200)
    assert 0 < broken_at_save < int(np.sum(s.dyn.state.linked_p == 0))    # the crack grew after the save
    for k in ("positions", "momenta", "omega", "theta"):
        assert np.array_equal(atoms.arrays[k], s.atoms.arrays[k]), k
    for k in PAIR_ARRAYS + ATOM_ARRAYS:
        assert np.array_equal(getattr(dyn.state, k), getattr(s.dyn.state, k)), k
    assert dyn.stored_work == s.dyn.stored_work and dyn.dissipated == s.dyn.dissipated
    assert dyn.state.time == s.dyn.state.time and dyn.hold_layer_rotation
    for g, h in zip(atoms.constraints, s.atoms.constraints):
        assert g.lateral == "free" and g.t_sample == h.t_sample and g.work == h.work
        assert np.array_equal(g.force, h.force) and np.array_equal(g.impulse, h.impulse)
    # the file stores the materials as records (no Material objects in atoms.info)
    _, state = read_checkpoint(ck)
    assert state["dynamics_class"] == "MCADynamics" and state["calculator"]["class"] == "MCA"


def test_a_load_path_callable_is_refused_by_save_run(tmp_path):
    s = tiny_bar(path=load_unload_reload)
    with pytest.raises(InputError, match="Table") as exc:
        save_run(tmp_path / "x.h5", s.dyn)
    assert "\n" not in str(exc.value) and not (tmp_path / "x.h5").exists()


def test_grips_record_the_momentum_they_give():
    """The momentum the sample gains along the bar is the grips' recorded impulse (pair damping
    included); across the bar nothing is taken: the total lateral momentum stays zero."""
    s = tiny_bar()
    lo, hi = s.grips
    layer = np.zeros(len(s.atoms), bool)
    layer[lo.index] = layer[hi.index] = True
    P0 = s.atoms.get_momenta()
    s.dyn.run(150)
    dP = s.atoms.get_momenta() - P0
    imp = lo.impulse + hi.impulse
    scale = abs(lo.impulse[0])
    assert scale > 0 and abs(dP[~layer, 0].sum() - imp[0]) < 1e-9 * scale
    assert np.abs(dP[:, 1:].sum(axis=0)).max() < 1e-9 * scale
    v = s.atoms.get_velocities()
    np.testing.assert_allclose(v[hi.index, 0], hi.velocity[0], rtol=1e-14)
    assert np.abs(v[hi.index, 1:]).max() > 0                          # free across the bar
    assert np.all(s.atoms.arrays["omega"][layer] == 0.0)              # hold_layer_rotation


def test_traction_presses_a_plane_strain_block():
    """2D: a block on a held base, pressed by a traction layer at 0.1 GPa: at rest the layer's
    reaction is stress x area (area: periodic length x unit thickness) and the middle of the
    block carries sigma_yy = -0.1 GPa (measured -0.0996); motion stays in the plane."""
    mat = elastic_material(0.25)
    d = 1.0
    atoms = mca_packing(mat, d, (4.0, 6.0), "sc", pbc=(True, False, False))
    atoms.calc = MCA()
    y = atoms.positions[:, 1]
    top, base = y > y.max() - 0.3 * d, y < y.min() + 0.3 * d
    P = 0.1 * units.GPa
    tr = Traction(top, normal=(0, 1, 0), stress=P)
    atoms.set_constraint([Piston(base, 0.0), tr])
    dyn = MCADynamics(atoms, damping=0.5)
    assert tr.area == pytest.approx(atoms.cell[0, 0] * 1.0)
    dyn.run(2000)
    assert tr.force[1] == pytest.approx(P * tr.area, rel=1e-3) and abs(tr.normal_velocity) < 1e-6 * wave_speeds(mat)[0]
    s = atoms.calc.get_property("automaton_stresses", atoms)
    mid = np.abs(y - 0.5 * (y.min() + y.max())) < 0.6 * d           # the two middle rows
    assert s[mid, 1].mean() == pytest.approx(-P, rel=1e-2)
    assert np.all(atoms.positions[:, 2] == 0.0) and np.all(atoms.arrays["omega"][:, :2] == 0.0)
    with pytest.raises(InputError, match="x-y plane"):
        b = atoms.copy()
        b.calc = MCA()
        b.set_constraint(Piston(base, 1.0, direction=(0, 0, 1)))
        MCADynamics(b)
