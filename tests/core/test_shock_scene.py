"""The main job: a piston shock in aluminium against the experimental Hugoniot."""

import json
import subprocess
import sys

import pytest

from clusterdyn.scenes import get_scene


def test_shock_3kms_small_sample(tmp_path):
    res = get_scene("shock").run({"size": "40x4x4", "h5md": "false"}, out=tmp_path, progress=False)
    D = res.quantities["D"]
    assert D.unit == "km/s" and D.reference == pytest.approx(5.392 + 1.341 * 3)
    assert abs(D.rel_error) < 0.03
    assert abs(res.quantities["u"].rel_error) < 0.03
    assert abs(res.quantities["D_mass"].rel_error) < 0.02          # mass conservation
    assert abs(res.quantities["P_momentum"].rel_error) < 0.05      # momentum conservation
    assert res.extra["steady"]
    data = json.loads((tmp_path / "result.json").read_text())
    for k in ("D", "u", "P", "rho"):
        assert set(data[k]) >= {"value", "unit", "reference", "rel_error"}
    assert data["wall_time_s"] > 0
    assert (tmp_path / "shock.png").stat().st_size > 1000


def test_cli_json_and_errors(tmp_path):
    cmd = [sys.executable, "-m", "clusterdyn.cli", "run", "shock", "--set", "size=30x3x3",
           "--set", "u=3km/s", "--set", "h5md=false", "--json", "--out", str(tmp_path)]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert data["D"]["unit"] == "km/s" and abs(data["D"]["rel_error"]) < 0.03
    for bad, word in [(["run", "shock", "--set", "u=3kg"], "u="), (["run", "shock", "--set", "J=0"], "J="),
                      (["run", "shock", "--set", "r0=-5um"], "r0="), (["run", "nosuch"], "scene="),
                      (["run", "shock", "--set", "material=Kryptonite"], "material=")]:
        r = subprocess.run([sys.executable, "-m", "clusterdyn.cli"] + bad, capture_output=True, text=True)
        assert r.returncode == 2, (bad, r.stderr)
        assert word in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
