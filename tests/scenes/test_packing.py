"""The impact and free-surface scenes take a packing (clusterdyn.scenes.packing): tiny runs."""

import json

import numpy as np
import pytest

from clusterdyn.errors import InputError
from clusterdyn.scenes import get_scene
from clusterdyn.scenes.plate_impact import build_impact


def _law_file(tmp_path, sigma_t=2.0):
    f = tmp_path / "weak.json"
    f.write_text(json.dumps({"grain_size": 4, "porosity": 0.14, "rc": 1.15, "boundaries": "law",
                             "law": {"sigma_t": sigma_t, "G_c": 3e3, "select": "all"}}))
    return str(f)


def test_impact_plates_with_the_law_attach_the_term_and_keep_the_default(tmp_path):
    kw = dict(sample="polycrystal", flyer=6.0, target=10.0, width=5.0, grain_size=4.0, relax_cycles=1)
    s = build_impact(packing=_law_file(tmp_path), **kw)
    assert [q.name for q in s["dyn"].pieces if q.adds_forces] == ["boundary"]
    assert s["relax"]["boundary"]["bonds"] > 0
    # the scenes' stress maps (spall, plate-impact) carry the law's pair stresses
    from clusterdyn.analysis.stress import particle_virials
    from types import SimpleNamespace
    from clusterdyn.scenes.plate_impact import ImpactRecord
    dyn, atoms = s["dyn"], s["atoms"]
    dyn.run(3)
    term = next(q for q in dyn.pieces if q.adds_forces)
    setup = SimpleNamespace(atoms=atoms, dyn=dyn, r0=s["r0"], v=s["v"], rear=np.flatnonzero(s["rear"]))
    W = ImpactRecord(setup).frame(dyn)
    total = particle_virials(atoms).sum(axis=0) + term.virial
    assert np.allclose(W.sum(axis=0), total, rtol=1e-10, atol=1e-10 * np.abs(total).max())
    plain = build_impact(**kw)
    assert not any(q.adds_forces for q in plain["dyn"].pieces)
    assert plain["calc"].parameters["attraction"] == "all"


def test_tiny_spall_with_a_weak_law_pulls_back_less(tmp_path):
    common = {"sample": "polycrystal", "flyer": "4", "target": "8", "width": "4", "grain_size": "3.5",
              "frames": "20", "v": "1500m/s", "h5md": "false", "checkpoint_every": "0", "relax_cycles": "2"}
    weak = get_scene("spall").run({**common, "packing": _law_file(tmp_path)}, out=tmp_path / "w", progress=False)
    paper = get_scene("spall").run(common, out=tmp_path / "p", progress=False)
    qw, qp = weak.quantities, paper.quantities
    # the pullback (free-surface velocity: the law's forces are in it)
    def pulled(q):      # the pullback strength: a spall strength, or the tension held when there was no spall
        return q["pc_spall_strength_cb" if q["pc_spalled"].value else "pc_tension_held_cb"].value
    assert pulled(qp) > 1.0                                           # GPa: the paper's packing holds tension
    assert pulled(qw) < 0.5 * pulled(qp)                              # the law's weak bonds do not
    assert abs(qw["pc_ledger_residual"].value) < 0.05
    # the stress map carries the law's pair stresses: the largest tension is the bonds' (0 without them)
    assert 0.1 < qw["pc_max_tension"].value < 2.0


def test_taylor_refuses_an_unknown_packing():
    with pytest.raises(InputError, match="packing"):
        get_scene("taylor").run({"packing": "no-such", "r0": "1.27mm"}, progress=False)


def test_hypervelocity_takes_the_packing_and_lammps_refuses_the_law(tmp_path):
    """packing=FILE: plate and sphere are polycrystals of the packing, quenched apart, then the
    sphere set flying at START_GAP; the law's term rides on the dynamics.  The LAMMPS engine refuses
    the law in one line before any work."""
    from clusterdyn import units
    from clusterdyn.cli import main
    from clusterdyn.scenes.hypervelocity import START_GAP, build_hypervelocity
    scene = get_scene("hypervelocity")
    small = {"r0": "0.6mm", "radius": "5mm", "diameter": "4.5mm", "noise": "0"}
    f = tmp_path / "law.json"
    f.write_text(json.dumps({"grain_size": 4, "porosity": 0.14, "rc": 1.15, "boundaries": "law",
                             "law": {"sigma_t": 2.0, "ductility": 8.0, "select": "all"}}))
    v = scene.parse({**small, "packing": str(f)})
    scene.check(v)
    atoms, dyn, info = build_hypervelocity(v)
    assert [q.name for q in dyn.pieces if q.adds_forces] == ["boundary"]
    body, r0 = atoms.arrays["body"], 0.6 * units.mm
    assert len(np.unique(atoms.arrays["grain"][body == 0])) > 1 and len(np.unique(atoms.arrays["grain"][body == 1])) > 1
    vz = atoms.get_velocities()[:, 2]
    assert np.allclose(vz[body == 1], -6.7 * units.km_s) and np.all(vz[body == 0] == 0)
    z, rad = atoms.positions[:, 2], atoms.arrays["radius"]
    gap = (z - rad)[body == 1].min() - (z + rad)[body == 0].max()
    assert abs(gap - START_GAP * r0) < 1e-9 * r0
    assert any("boundary law" in n for n in info["packing_notes"])
    out = tmp_path / "law"
    argv = ["run", "hypervelocity", "--engine", "lammps", "--deck-only", "--set", "packing=6061-T6", "--out", str(out)]
    assert main(argv) == 2
    assert not out.exists() or not any(out.iterdir())


def _select_all_file(tmp_path, porosity=0.14, grain_size=4):
    f = tmp_path / "all.json"
    f.write_text(json.dumps({"grain_size": grain_size, "porosity": porosity, "rc": 1.15, "boundaries": "law",
                             "law": {"sigma_t": 2.0, "ductility": 8.0, "select": "all"}}))
    return str(f)


def test_multilayer_takes_the_packing(tmp_path):
    """Every layer and the sphere polycrystals of the packing, the sphere launched along +axis after
    the quench; LAMMPS refuses the law in one line."""
    from clusterdyn import units
    from clusterdyn.cli import main
    from clusterdyn.scenes.multilayer import LAYERS, build_multilayer
    scene = get_scene("multilayer")
    v = scene.parse({"r0": "3mm", "radius": "14mm", "noise": "0",
                     "packing": _select_all_file(tmp_path, porosity=0.2, grain_size=3.2)})
    scene.check(v)
    atoms, dyn, info = build_multilayer(v)
    assert [q.name for q in dyn.pieces if q.adds_forces] == ["boundary"]
    body = atoms.arrays["body"]
    vz = atoms.get_velocities()[:, 2]
    assert np.allclose(vz[body == len(LAYERS)], 6.5 * units.km_s) and np.all(vz[body < len(LAYERS)] == 0)
    assert info["t_contact"] > 0 and any("boundary law" in n for n in info["packing_notes"])
    out = tmp_path / "ml"
    assert main(["run", "multilayer", "--engine", "lammps", "--deck-only", "--set", "packing=6061-T6",
                 "--out", str(out)]) == 2


def test_ejecta_takes_a_law_on_every_pair_and_refuses_grains(tmp_path):
    """ejecta: the law on every pair of the single-crystal slab (select=all); a packing that needs
    grains is refused in one line; the run's probe stresses carry the bonds' share."""
    # the tiny slab of tests/scenes/test_ejecta.py
    TINY = {"r0": "1um", "rz": "6um", "wavelength": "16um", "n_periods": 1, "depth": "30um", "t_end": "0.018us",
            "frames": 6, "probes": 6, "snapshot_every": "0.009us", "spectrum_time": "0.018us", "h5md": False}
    sc = get_scene("ejecta")
    with pytest.raises(InputError, match="packing"):
        sc.check(sc.parse({**TINY, "packing": "paper"}))
    v = sc.parse({**TINY, "packing": _select_all_file(tmp_path)})
    sc.check(v)
    atoms, dyn, info = sc.setup(v, "main")
    term = next(q for q in dyn.pieces if q.adds_forces)
    assert term.name == "boundary" and term.bonds.shape[0] > 3 * len(atoms)
    assert atoms.calc.parameters["attraction"] == "initial"
    plain_atoms, plain_dyn, _ = sc.setup(sc.parse(TINY), "main")
    assert not any(q.adds_forces for q in plain_dyn.pieces)
