"""The flow-stress study: refusals, the plan, resume and advice (the material point itself: tests/scenes)."""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError
from clusterdyn.studies import get_study, study_params
from clusterdyn.studies import flow_stress as fs
from clusterdyn.studies.common import parse_params

#: a study that runs in about a second: an 8 r0 cube of 4 r0 grains, 2% strain
TINY = {"size": "8", "grain_size": "4", "porosity": "0.2", "grain_sizes": "4", "porosities": "0.2", "rcs": "1.15",
        "boundary_kinds": "bonded", "rates": "0.01", "rate": "0.01", "strains": "0.01,0.02", "hold": "2",
        "average": "1", "seeds": "2", "relax_cycles": "2", "plots": "false"}


def test_refusals():
    study = get_study("flow-stress")
    assert {p.name for p in study_params("flow-stress")} >= {"grain_sizes", "porosities", "rcs", "boundary_kinds",
                                                             "target", "seeds", "strains"}
    bad = [({"boundary_kinds": "bonded,glued"}, "boundary_kinds="), ({"strains": "0.1,0.05"}, "strains="),
           ({"hold": "5", "average": "10"}, "average="), ({"grain_sizes": "5,20"}, "grain_sizes="),
           ({"target": "-1"}, "target="), ({"porosities": "0.6"}, "porosities="), ({"rcs": "1.5"}, "rcs="),
           ({"seeds": "0"}, "seeds="), ({"nosuch": "1"}, "--set="), ({"target": "1km/s"}, "target=")]
    for ov, match in bad:
        with pytest.raises(InputError, match=match):
            study(ov, out=None, progress=False)


def test_plan_one_factor_and_grid():
    v, _ = parse_params(fs.PARAMS, {}, study="flow-stress")
    points = fs.plan_points(v, ("bonded", "repulsive"))
    assert points[0][0] == ["boundaries", "default", "grain_size", "grid", "porosity", "rate", "rc"]
    # 4 x 4 grid (holding the grain and porosity lines), 2 more cutoffs, repulsive, 2 more rates
    assert len(points) == 16 + 2 + 1 + 2
    keys = {tuple(p[k] for k in (*fs.FACTORS, "rate")) for _, p in points}
    assert len(keys) == len(points)


def test_resume_and_advice(tmp_path, capsys):
    study = get_study("flow-stress")
    n0 = fs.RUNS[0]
    ov = {**TINY, "porosities": "0.2,0.01"}                    # 1% porosity: out of the boundary rule's reach
    res = study(ov, out=tmp_path, progress=False, quiet=False)
    assert res["runs_computed"] == 5 == fs.RUNS[0] - n0       # two seeds at two porosities, the single crystal
    assert res["runs_reused"] == 0
    unreachable = [r for r in res["rows"] if r["porosity_target"] == 0.01]
    assert len(unreachable) == 1 and unreachable[0]["runs"] == 0 and unreachable[0]["failed"] == 2
    assert "target_porosity" in unreachable[0]["error"]
    d = res["default"]
    assert d["runs"] == 2 and np.isfinite(d["flow_stress_spread"])
    assert 0.15 < d["porosity"] < 0.25
    assert d["flow_stress"] == pytest.approx(np.mean([r["flow_stress"] for r in res["runs"][:2]]))
    assert res["single"]["flow_stress"] > d["flow_stress"]
    out = capsys.readouterr().out
    assert "closest packing: grain_size=4 r0, porosity=0.2" in out and "(target 0.35 GPa)" in out
    for f in ("flow_stress.csv", "flow_stress_runs.csv", "flow_stress.md", "flow_stress.json"):
        assert (tmp_path / f).stat().st_size > 100
    # the same folder again: every run is read back, nothing is computed
    n1 = fs.RUNS[0]
    again = study(ov, out=tmp_path, progress=False)
    assert again["runs_computed"] == 0 and fs.RUNS[0] == n1 and again["runs_reused"] == 5
    assert again["default"]["flow_stress"] == d["flow_stress"]
    # one more seed: only its two runs are computed
    more = study({**ov, "seeds": "3"}, out=tmp_path, progress=False)
    assert more["runs_computed"] == 2 and more["default"]["runs"] == 3


def test_advice_when_no_packing_reaches_the_target():
    v, _ = parse_params(fs.PARAMS, {"grain_sizes": "5,11", "porosities": "0.14,0.2", "rcs": "1.1,1.15",
                                       "boundary_kinds": "bonded", "rates": "0.001", "grid": "false"})

    def row(sweeps, g, p, rc, flow):
        return {"sweeps": sweeps, "sample": "polycrystal", "grain_size": g, "porosity_target": p, "porosity": p,
                "rc": rc, "boundaries": "bonded", "rate": 1e-3, "flow_stress": flow}
    rows = [row("default", 11, 0.14, 1.15, 3.9), row("grain_size", 5, 0.14, 1.15, 2.0),
            row("porosity", 11, 0.2, 1.15, 3.0), row("rc", 11, 0.14, 1.1, 4.2)]
    adv = fs.advise(rows, v)
    assert not adv["reached"] and adv["closest"]["grain_size"] == 5
    text = "\n".join(adv["lines"])
    assert "no packing reaches the target" in text and "above it" in text
    assert [d["change"] for d in adv["directions"]] == ["smaller grain_size", "higher porosity"]
    assert math.isclose(adv["directions"][0]["drop"], 1.9)


def test_combined_point_when_the_target_is_out_of_reach(tmp_path):
    ov = {**TINY, "seeds": "1", "single": "false", "grain_sizes": "4,5", "porosities": "0.2,0.26", "grid": "false",
          "rcs": "1.1,1.15", "boundary_kinds": "bonded,repulsive", "target": "0.001"}
    res = get_study("flow-stress")(ov, out=tmp_path, progress=False)
    adv = res["advice"]
    assert not adv["reached"]
    combined = [r for r in res["rows"] if r["sweeps"] == "combined"]
    if len(adv["directions"]) >= 2:
        assert len(combined) == 1
        c = combined[0]
        for d in adv["directions"]:
            assert c[{"porosity": "porosity_target"}.get(d["factor"], d["factor"])] == d["to"]
    else:
        assert not combined
    assert res["runs_computed"] == 5 + len(combined)
    assert len(combined) == 1


def test_relax_sample_rescales_only_periodic_axes():
    from clusterdyn.build import Plate, polycrystal
    from clusterdyn.scenes.plate_impact import relax_sample
    r0 = 10 * units.um
    atoms = polycrystal("Al", r0, Plate(8 * r0, 8 * r0), grain_size=4 * r0, seed=1, pbc=(False, True, True))
    atoms.calc = ClusterDynamics()
    with pytest.raises(InputError, match="axes="):
        relax_sample(atoms, cycles=1, steps=1, axes=(0, 1, 2))
