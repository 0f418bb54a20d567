"""The command line: bad input gives one clear line and a non-zero exit; outputs survive kills and restarts."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

CLI = [sys.executable, "-m", "clusterdyn.cli"]
SMALL = ["--set", "size=30x3x3", "--set", "frames=20"]


def run(args, **kw):
    return subprocess.run(CLI + args, capture_output=True, text=True, timeout=600, **kw)


def test_ten_kinds_of_bad_input(tmp_path):
    corrupt = tmp_path / "corrupt.h5"
    corrupt.write_bytes(b"\x89HDF\r\n\x1a\n" + os.urandom(300))
    cfg = tmp_path / "bad.toml"
    cfg.write_text("u = [[[")
    notckpt = tmp_path / "plain.txt"
    notckpt.write_text("hello")
    cases = [
        (["run", "nosuchscene"], "scene="),
        (["run", "shock", "--set", "nosuchkey=1"], "--set="),
        (["run", "shock", "--set", "u=3parsec"], "u="),
        (["run", "shock", "--set", "u=3kg"], "u="),
        (["run", "shock", "--set", "size=-4x4x4"], "size="),
        (["run", "shock", "--set", "u"], "--set="),
        (["run", "shock", "--restart", str(tmp_path / "missing.h5")], "--restart="),
        (["run", "shock", "--restart", str(corrupt)], str(corrupt)),
        (["run", "shock", "--restart", str(notckpt)], str(notckpt)),
        (["run", "shock", "--config", str(cfg)], "--config="),
        (["run", "shock", "--set", "rc=1.6"], "rc="),
        (["run", "shock", "--set", "direction=123"], "direction="),
        (["info", str(tmp_path / "nothere.h5md")], "FILE="),
        (["run", "shock", "--threads", "0"], "threads="),
        (["run", "shock", "--threads", "two"], "command line"),
        (["frobnicate"], "command line"),
    ]
    for args, word in cases:
        r = run(args)
        assert r.returncode == 2, (args, r.returncode, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in r.stderr, (args, r.stderr)
        assert word in lines[0], (args, lines[0])


def test_list_and_materials():
    r = run(["list"])
    assert r.returncode == 0 and "shock" in r.stdout and "km/s" in r.stdout
    r = run(["materials"])
    assert r.returncode == 0 and "Al-1100" in r.stdout and "source" in r.stdout


def test_config_file(tmp_path):
    cfg = tmp_path / "scene.toml"
    cfg.write_text('scene = "shock"\n[params]\nu = "2km/s"\nsize = [30, 3, 3]\nh5md = false\nframes = 20\n')
    r = run(["run", "shock", "--config", str(cfg), "--json"])
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["params"]["u"]["value"] == pytest.approx(2.0) and d["params"]["size"] == [30, 3, 3]
    # the same scene without H5MD into a folder that does not exist yet: the folder is made
    # for the result and the checkpoints
    out = tmp_path / "new" / "folder"
    r = run(["run", "shock", "--config", str(cfg), "--out", str(out), "--quiet"])
    assert r.returncode == 0, r.stderr
    assert (out / "result.json").exists() and (out / "checkpoint.h5").exists()
    assert not (out / "shock.h5md").exists()


def test_h5md_of_a_shock_opens_in_mdanalysis(tmp_path):
    mda = pytest.importorskip("MDAnalysis")
    from clusterdyn.io import read_h5md
    from clusterdyn import units
    r = run(["run", "shock", "--out", str(tmp_path), "--quiet"] + SMALL)
    assert r.returncode == 0, r.stderr
    path = tmp_path / "shock.h5md"
    u = mda.Universe(str(path))
    assert u.trajectory.n_frames >= 10
    last = read_h5md(str(path), frame=-1)
    ts = u.trajectory[-1]
    # MDAnalysis reads wrapped coordinates across the periodic y, z; read_h5md unwraps with the images
    L = last.cell.lengths()
    wrapped = last.positions.copy()
    wrapped[:, 1:] -= np.floor(wrapped[:, 1:] / L[1:]) * L[1:]
    np.testing.assert_allclose(ts.positions, wrapped, rtol=1e-6)
    np.testing.assert_allclose(ts.velocities, last.get_velocities() * units.VEL_TO_A_PER_PS, rtol=1e-6)
    assert ts.has_forces
    np.testing.assert_allclose(ts.dimensions[:3], last.cell.lengths(), rtol=1e-6)
    assert ts.time > 0


def test_sigkill_leaves_readable_h5md(tmp_path):
    mda = pytest.importorskip("MDAnalysis")
    from clusterdyn.io import H5MDReader
    proc = subprocess.Popen(CLI + ["run", "shock", "--out", str(tmp_path), "--quiet",
                                   "--set", "size=60x4x4", "--set", "h5md_frames=400"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    path = tmp_path / "shock.h5md"
    n = 0
    deadline = time.time() + 240
    while time.time() < deadline and n < 5:
        time.sleep(0.3)
        if path.exists():
            try:
                with H5MDReader(str(path)) as rd:
                    n = rd.n_frames
            except Exception:
                n = 0
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert n >= 5
    u = mda.Universe(str(path))
    assert u.trajectory.n_frames >= n
    for ts in u.trajectory:
        assert np.isfinite(ts.positions).all()


def test_restart_from_cli_gives_identical_result(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    args = ["run", "shock", "--json", "--set", "checkpoint_every=4"] + SMALL
    r1 = run(args + ["--out", str(a)])
    assert r1.returncode == 0, r1.stderr
    # a "crashed" run: its output folder as it was at the last checkpoint
    import shutil
    shutil.copytree(a, b)
    r2 = run(["run", "shock", "--json", "--restart", str(b / "checkpoint.h5"), "--out", str(b)])
    assert r2.returncode == 0, r2.stderr
    d1, d2 = json.loads(r1.stdout), json.loads(r2.stdout)
    for k in ("D", "u", "P", "rho"):
        assert d1[k]["value"] == d2[k]["value"]
    from clusterdyn.io import H5MDReader
    with H5MDReader(str(b / "shock.h5md")) as rd:
        steps = list(rd.steps)
    assert steps == sorted(set(steps))          # appended without duplicate frames


def test_help_lists_the_scenes_the_studies_and_a_scenes_parameters(capsys):
    """`run --help` and a bare `run` list every scene; `run SCENE --help` gives every parameter of it and
    the options; `study --help` lists every study (it used to fail)."""
    from clusterdyn.cli import main
    from clusterdyn.scenes import all_scenes, get_scene
    from clusterdyn.studies import study_names
    assert main(["run", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in all_scenes()) and "--restart" in out
    assert main(["run"]) == 2
    out = capsys.readouterr().out
    assert all(name in out for name in all_scenes())
    assert main(["run", "taylor", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(f"  {p.name} = " in out for p in get_scene("taylor").params) and "--out DIR" in out
    assert main(["study", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in study_names())


def test_json_keeps_the_progress_bar_on_stderr(tmp_path, capsys):
    """--json prints one JSON object on stdout and still shows the progress bar on stderr."""
    import json
    from clusterdyn.cli import main
    assert main(["run", "shock", "--json", "--set", "size=40x4x4", "--set", "fit_from=0", "--set", "h5md=false",
                 "--out", str(tmp_path / "a")]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["D"]["unit"] == "km/s"
    assert "step" in cap.err


def test_the_checkpoint_is_among_the_files_a_run_wrote(tmp_path):
    from clusterdyn.scenes import get_scene
    res = get_scene("shock").run({"size": "40x4x4", "fit_from": "0", "h5md": "false", "checkpoint_every": "1"},
                                 out=tmp_path, progress=False)
    assert tmp_path / "checkpoint.h5" in res.files and (tmp_path / "checkpoint.h5").exists()
    quiet = get_scene("shock").run({"size": "40x4x4", "fit_from": "0", "h5md": "false", "checkpoint_every": "0"},
                                   out=tmp_path / "b", progress=False)
    assert not any(f.name == "checkpoint.h5" for f in quiet.files)
