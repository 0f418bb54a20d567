"""Scene dusting and analysis.dusting: exact counts on built configurations, tiny runs, ledger, restart."""

import json
import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.analysis.dusting import cross_section, dispersed, layer_counts
from clusterdyn.build import fcc_packing, make_cluster_atoms
from clusterdyn.cli import main
from clusterdyn.errors import InputError
from clusterdyn.scenes import get_scene

R0 = 10 * units.um
TINY = {"length": "0.3mm", "frames": "12", "h5md": "false", "checkpoint_every": "0"}


def _slab_with_debris(debris):
    """A [100] slab 10 cells long, 2 x 2 periods, periodic across, with extra clusters (rows at the end)."""
    a = fcc_packing("Al", R0, size=(10, 2, 2), pbc=(False, True, True))
    x_rear = a.positions[:, 0].max()
    pos = np.vstack([a.positions, np.asarray(debris, float).reshape(-1, 3)])
    b = make_cluster_atoms(pos, a.info["cd_materials"], a.info["cd_r0"])
    b.set_cell(a.cell)
    b.pbc = a.pbc
    return b, x_rear


def test_dispersed_counts_exactly_what_left_the_surface():
    a0, x_rear = _slab_with_debris(np.zeros((0, 3)))
    y, z = 0.3 * a0.cell[1, 1], 0.3 * a0.cell[2, 2]
    debris = [[x_rear + 3 * R0, y, z],                                   # a single cluster, 3 r0 out: dispersed
              [x_rear + 6 * R0, y, z], [x_rear + 6.9 * R0, y, z],        # a pair (bonded at 0.9 r0): dispersed
              [x_rear + 0.8 * R0, y + 0.5 * R0, z + 0.2 * R0],           # bonded to the surface: main body
              [-3 * R0, y, z]]                                           # off the front face: not the rear
    chain = [[x_rear + 12 * R0 + k * 0.95 * R0, y, z] for k in range(11)]  # 11 clusters: a large fragment
    a, _ = _slab_with_debris(debris + chain)
    d = dispersed(a, b=1.1)
    assert d.surface == pytest.approx(x_rear + 0.8 * R0)            # the bonded cluster is the surface
    assert (d.n_fragments, d.n_clusters) == (2, 3)
    assert (d.n_large, d.large_clusters) == (1, 11)
    assert d.mass_fraction == pytest.approx(3 / len(a))
    area = a.cell[1, 1] * a.cell[2, 2]
    assert d.area == pytest.approx(area)
    assert d.per_mm2 == pytest.approx(3 / (area / units.mm ** 2))
    g, n = d.spectrum()
    assert n[0] == 1 and n[1] == 1 and n.sum() == 2
    # facing the other way, only the cluster off the front face is out
    back = dispersed(a, b=1.1, side=-1)
    assert (back.n_fragments, back.n_clusters) == (1, 1)
    # without a free surface (no debris) nothing is dispersed
    assert dispersed(a0, b=1.1).n_clusters == 0


def test_bad_input_and_layer_counts():
    a, _ = _slab_with_debris(np.zeros((0, 3)))
    with pytest.raises(InputError, match="side"):
        dispersed(a, b=1.1, side=2)
    with pytest.raises(InputError, match="g_max"):
        dispersed(a, b=1.1, g_max=0)
    a.pbc = (False, False, True)
    with pytest.raises(InputError, match="area"):
        cross_section(a)
    # 10 cells of [100]: 20 (200) planes of 8 clusters, one per layer of a plane spacing
    a.pbc = (False, True, True)
    x, n = layer_counts(a, R0 / math.sqrt(2), lo=a.positions[:, 0].min() - 0.25 * R0)
    assert n.sum() == len(a) and set(n.tolist()) <= {0, 8} and (n == 8).sum() == 20


def test_tiny_dusting_runs_close_their_ledger_and_write_files(tmp_path):
    res = get_scene("dusting").run({**TINY, "u": "4km/s", "J": "none"}, out=tmp_path, progress=False)
    q = res.quantities
    assert q["dispersed_clusters"].value > 0                 # 0.3 mm undamped at 4 km/s sheds clusters
    assert abs(q["ledger_residual"].value) < 1e-3
    assert q["fsv_plateau"].value == pytest.approx(8.0, rel=0.2)
    for f in ("dusting.png", "dusting_time.csv", "dusting_layers.csv", "result.json"):
        assert (tmp_path / f).exists()
    head = (tmp_path / "dusting_time.csv").read_text().splitlines()[0]
    assert "dispersed_per_mm2" in head and "mass_fraction" in head
    # a weak shock with damping: the surface holds
    calm = get_scene("dusting").run({**TINY, "u": "0.5km/s"}, progress=False)
    assert calm.quantities["dispersed_clusters"].value == 0
    assert abs(calm.quantities["ledger_residual"].value) < 1e-3
    assert calm.quantities["fsv_plateau"].value == pytest.approx(1.0, rel=0.05)


def test_dusting_refuses_a_short_sample_before_work():
    with pytest.raises(InputError, match="length"):
        get_scene("dusting").run({"length": "0.1mm"}, progress=False)


def test_dusting_restart_is_bit_for_bit(tmp_path):
    args = ["--set", "length=0.2mm", "--set", "u=3km/s", "--set", "J=none", "--set", "frames=10",
            "--set", "checkpoint_every=4", "--set", "h5md=false"]
    full, cont = tmp_path / "full", tmp_path / "cont"
    assert main(["run", "dusting", "--quiet", "--out", str(full)] + args) == 0
    ck = tmp_path / "ck.h5"
    ck.write_bytes((full / "checkpoint.h5").read_bytes())
    assert main(["run", "dusting", "--quiet", "--out", str(cont), "--restart", str(ck)]) == 0
    a = json.loads((full / "result.json").read_text())
    b = json.loads((cont / "result.json").read_text())
    vals = [k for k, x in a.items() if isinstance(x, dict) and "value" in x]
    assert vals and all(a[k]["value"] == b[k]["value"] for k in vals)
    assert a["extra"]["series"] == b["extra"]["series"]


def test_dusting_study_tiny_resumes_from_its_runs(tmp_path):
    from clusterdyn.studies import get_study
    args = {"length": "0.25mm", "us": "1,4", "rcs": "1.1", "Js": "none", "seeds": "1,2", "r0s": "none",
            "frames": "8", "plots": "false", "profile_u": "4"}
    res = get_study("dusting")(args, out=tmp_path, progress=False)
    assert len(res["runs"]) == 4 and {r["u"] for r in res["runs"]} == {1.0, 4.0}
    assert all(abs(r["ledger"]) < 1e-3 for r in res["runs"])
    sweep = {(r["u"], r["J"]): r for r in res["sweep"]}
    assert sweep[(4.0, "none")]["n"] == 2 and sweep[(4.0, "none")]["per_mm2_mean"] > 0
    # a second call reads every run back from OUT/runs (same numbers, no new run folders)
    folders = sorted(p.name for p in (tmp_path / "runs").iterdir())
    again = get_study("dusting")(args, out=tmp_path, progress=False)
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == folders
    assert [r["per_mm2"] for r in again["runs"]] == [r["per_mm2"] for r in res["runs"]]
    for f in ("dusting_runs.csv", "dusting_sweep.csv", "dusting.json"):
        assert (tmp_path / f).exists()
