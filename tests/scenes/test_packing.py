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
    plain = build_impact(**kw)
    assert not any(q.adds_forces for q in plain["dyn"].pieces)
    assert plain["calc"].parameters["attraction"] == "all"


def test_tiny_spall_with_a_weak_law_pulls_back_less(tmp_path):
    common = {"sample": "polycrystal", "flyer": "4", "target": "8", "width": "4", "grain_size": "3.5",
              "frames": "20", "v": "1500m/s", "h5md": "false", "checkpoint_every": "0", "relax_cycles": "2"}
    weak = get_scene("spall").run({**common, "packing": _law_file(tmp_path)}, out=tmp_path / "w", progress=False)
    paper = get_scene("spall").run(common, out=tmp_path / "p", progress=False)
    qw, qp = weak.quantities, paper.quantities
    # the pullback (free-surface velocity: the law's forces are in it; its pair stresses are not in the
    # scenes' stress maps, docs/polycrystal.md)
    def pulled(q):      # the pullback strength: a spall strength, or the tension held when there was no spall
        return q["pc_spall_strength_cb" if q["pc_spalled"].value else "pc_tension_held_cb"].value
    assert pulled(qp) > 1.0                                           # GPa: the paper's packing holds tension
    assert pulled(qw) < 0.5 * pulled(qp)                              # the law's weak bonds do not
    assert abs(qw["pc_ledger_residual"].value) < 0.05


def test_taylor_refuses_an_unknown_packing():
    with pytest.raises(InputError, match="packing"):
        get_scene("taylor").run({"packing": "no-such", "r0": "1.27mm"}, progress=False)
