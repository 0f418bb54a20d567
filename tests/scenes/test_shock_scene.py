"""The main job: a piston shock in aluminium against the experimental Hugoniot."""

import json
import subprocess
import sys

import pytest

from clusterdyn.scenes import get_scene


def test_shock_3kms_small_sample(tmp_path):
    # a 40-cell sample is shorter than the start-up transient the default fit window skips (50 cells
    # at 3 km/s): fit from 20% of the sample instead (fit_from=0)
    res = get_scene("shock").run({"size": "40x4x4", "fit_from": "0", "h5md": "false"}, out=tmp_path,
                                 progress=False)
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
    # a deliberately short sample: not steady, said on one stderr line with the size that would fix it
    # (stderr also carries the progress bar, which --json keeps: the lines clusterdyn says are the rest)
    warn = [ln for ln in out.stderr.replace("\r", "\n").splitlines() if ln.startswith("clusterdyn: ")]
    assert data["steady"] is False and data["warnings"] == [warn[0][len("clusterdyn: warning: "):]]
    assert len(warn) == 1 and warn[0].startswith("clusterdyn: warning: shock not steady on 30x3x3 cells")
    assert "too short" in warn[0] and warn[0].endswith("--set size=120x3x3")
    for bad, word in [(["run", "shock", "--set", "u=3kg"], "u="), (["run", "shock", "--set", "J=0"], "J="),
                      (["run", "shock", "--set", "r0=-5um"], "r0="), (["run", "nosuch"], "scene="),
                      (["run", "shock", "--set", "material=Kryptonite"], "material=")]:
        r = subprocess.run([sys.executable, "-m", "clusterdyn.cli"] + bad, capture_output=True, text=True)
        assert r.returncode == 2, (bad, r.stderr)
        assert word in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1


def test_top_of_the_u_range_runs_and_above_is_refused():
    """The top of the u range (the last row of the size=auto rule) runs; a tiny sample keeps it quick."""
    from clusterdyn.errors import InputError
    from clusterdyn.scenes.shock import AUTO_RULE, U_MAX, shock_size
    from clusterdyn import units
    assert U_MAX == AUTO_RULE[-1][0] == 10.0
    scene = get_scene("shock")
    res = scene.run({"u": f"{U_MAX:g}km/s", "size": "16x3x3", "h5md": "false"}, progress=False)
    assert res.extra["dt_retries_used"] == 0 and res.quantities["D"].value > U_MAX
    assert res.steady is False          # 16 cells: far too short to be steady, and it says so
    assert "reference extrapolated: Al-1100 is measured to u = 6 km/s" in res.quantities["D"].note
    size, fit_from = shock_size(U_MAX * units.km_s)
    assert size == (140, 6, 6) and fit_from > 0          # what the defaults run at the top
    with pytest.raises(InputError, match="u="):
        scene.parse({"u": f"{U_MAX + 0.1:g}km/s"})


def test_two_phase_auto_size_fits_the_inclusions(tmp_path):
    """size=auto with inclusions: a cross-section of at least two inclusion diameters, so the
    default two-phase sample (56 um inclusions at r0 = 5 um) is built and exported, not refused."""
    from clusterdyn.scenes.shock import shock_size
    from clusterdyn import units
    assert shock_size(3 * units.km_s)[0] == (120, 6, 6)
    # 2 x 56 um = 22.4 r0 across; a [100] repeat cell is sqrt(2) r0: 16 cells
    assert shock_size(3 * units.km_s, min_width=22.4)[0] == (120, 16, 16)
    scene = get_scene("shock")
    v = scene.parse({"inclusion": "B4C"})
    assert scene.size(v) == (120, 16, 16)
    assert scene.size(scene.parse({"inclusion": "B4C", "size": "autox8x8"})) == (120, 8, 8)
