"""Packings with the boundary law: presets and files, the material-point tests, the calibration."""

import json

import pytest

from clusterdyn import units
from clusterdyn.build.polycrystal import PACKINGS, packing_spec
from clusterdyn.errors import InputError
from clusterdyn.studies.calibrate import calibrate_study, g_c_for
from clusterdyn.scenes.material_point import material_point

TINY = dict(material="Al-6061-T6", size=8.0, grain_size=4.0, porosity=0.14, seed=1, relax_cycles=2,
            strains=(0.01, 0.015), hold=0.5, average=0.5)


def test_packing_presets_and_files(tmp_path):
    assert packing_spec("paper")["boundaries"] == "bonded"
    for name in PACKINGS:
        packing_spec(name)
    for name, spec in PACKINGS.items():
        if spec["boundaries"] == "law":
            assert spec.get("calibrated") and "targets" in spec and "achieved" in spec, name
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"grain_size": 5, "porosity": 0.14, "rc": 1.15, "boundaries": "law",
                             "law": {"sigma_t": 3.0, "G_c": 5e4}}))
    assert packing_spec(str(f))["law"]["sigma_t"] == 3.0
    with pytest.raises(InputError, match="packing"):
        packing_spec("no-such-packing")
    f.write_text(json.dumps({"grain_size": 5, "porosity": 0.14, "rc": 1.15, "boundaries": "law", "lw": {}}))
    with pytest.raises(InputError, match="lw"):
        packing_spec(str(f))


def test_law_sets_the_spall_strength_of_the_material_point():
    """Stronger bonds, stronger packing in tension (uniaxial strain); the history is reported."""
    out = []
    for st in (4.0, 16.0):
        law = {"sigma_t": st, "G_c": g_c_for("Al-6061-T6", 100 * units.um, st, 8.0), "select": "boundary"}
        r = material_point(law=law, tension=True, **TINY)
        assert r["boundary"]["bonds"] > 0
        out.append(r["spall_strength"])
    assert out[1] > out[0] + 0.1, out


def test_law_on_every_pair_of_a_single_crystal_carries_sigma_t_in_tension():
    """The ejecta scene's slab with the law on every pair (select=all): stretched along [100] in
    uniaxial strain, 8 of a cluster's 12 bonds lie at 45 degrees (n_x^2 = 1/2), so the axial stress
    is 2 sqrt(2) F / r0^2 and the peak is the bond strength sigma_t itself (F_t = sigma_t r0^2 /
    (2 sqrt 2)).  Without thermal noise the bonds peak together: measured within 2% (with the
    scenes' 10 m/s noise a few % below)."""
    out = {}
    for st in (0.5, 1.0):
        r = material_point("Pb", law={"sigma_t": st, "ductility": 8.0, "select": "all"}, tension=True,
                           sample="single", size=4.0, r0=2 * units.um, strains=(0.01, 0.03, 0.06), hold=2.0,
                           average=1.0, noise=0.0)
        assert r["boundary"]["bonds"] == 6 * r["n_clusters"]        # every fcc bond of the periodic crystal
        out[st] = r["spall_strength"]
        assert out[st] == pytest.approx(st, rel=0.02), out
    assert out[1.0] / out[0.5] == pytest.approx(2.0, rel=0.05)


def test_calibrate_writes_a_packing_file_the_scenes_take(tmp_path):
    res = calibrate_study({"spall_strength": "0.5GPa", "size": 8, "grain_size": 4, "sigma_ts": "4,16",
                           "selects": "boundary", "confined": False, "reference": False, "refine": False,
                           "plots": False, "unconfined": False,
                           "relax_cycles": 2}, out=tmp_path, progress=False)
    best = res["best_packing"]
    assert best["boundaries"] == "law" and best["calibrated"] is True
    assert best["law"]["sigma_t"] in (4.0, 16.0)
    spec = packing_spec(str(tmp_path / "best_packing.json"))
    assert spec["law"]["ductility"] == 8.0
    # resumable: a second run reads every point back
    again = calibrate_study({"spall_strength": "0.5GPa", "size": 8, "grain_size": 4, "sigma_ts": "4,16",
                             "selects": "boundary", "confined": False, "reference": False, "refine": False,
                             "plots": False, "unconfined": False,
                           "relax_cycles": 2}, out=tmp_path, progress=False)
    assert again["rows"][0]["spall_strength"] == res["rows"][0]["spall_strength"]
    assert again["wall_time_s"] < res["wall_time_s"]


def test_lammps_export_refuses_the_law(tmp_path):
    from clusterdyn.scenes.export import export_scene
    with pytest.raises(InputError, match="packing"):
        export_scene("plate-impact", {"sample": "polycrystal", "packing": "6061-T6"}, tmp_path / "deck")
    assert not (tmp_path / "deck").exists() or not any((tmp_path / "deck").iterdir())
