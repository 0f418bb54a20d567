"""The scene lifecycle: restarts that never lie, and bad input refused before any work."""

import json
import shutil

import pytest

from clusterdyn.cli import main
from clusterdyn.errors import InputError
from clusterdyn.scenes.lifecycle import check_out

TINY_SHOCK = ["--set", "size=20x4x4", "--set", "frames=10", "--set", "checkpoint_every=3"]
TINY_IMPACT = ["--set", "sample=both", "--set", "flyer=5", "--set", "target=10", "--set", "width=5",
               "--set", "grain_size=4", "--set", "relax_cycles=1", "--set", "frames=10",
               "--set", "checkpoint_every=3", "--set", "h5md=false"]

#: 8 x 3 x 3 automata pulled to 6 sigma_t/E in 400 steps; the checkpoint at step 200 is mid-crack
TINY_MCA = ["--set", "size=8x3x3", "--set", "steps=400", "--set", "strain_max=6", "--set", "frames=10",
            "--set", "checkpoint_every=5"]


def _values(path):
    d = json.loads(path.read_text())
    return {k: x["value"] for k, x in d.items() if isinstance(x, dict) and "value" in x}, d


def _restart_equals_full_run(tmp_path, scene, args, capsys):
    full, cont = tmp_path / "full", tmp_path / "cont"
    assert main(["run", scene, "--quiet", "--out", str(full)] + args) == 0
    ck = tmp_path / "ck.h5"
    shutil.copy(full / "checkpoint.h5", ck)          # the last checkpoint, written part way through
    assert main(["run", scene, "--quiet", "--out", str(cont), "--restart", str(ck),
                 "--set", "h5md_frames=7"]) == 0
    a, da = _values(full / "result.json")
    b, db = _values(cont / "result.json")
    assert a == b                                    # bit for bit: N steps + restart + M steps
    return da, db


def test_shock_restart_is_bit_for_bit_and_records_what_ran(tmp_path, capsys):
    da, db = _restart_equals_full_run(tmp_path, "shock", TINY_SHOCK, capsys)
    assert da["params"]["size"] == db["params"]["size"] == [20, 4, 4]
    assert db["params"]["h5md_frames"] == 7 and da["params"]["h5md_frames"] == 20


def test_plate_impact_restart_is_bit_for_bit(tmp_path, capsys):
    _restart_equals_full_run(tmp_path, "plate-impact", TINY_IMPACT, capsys)


def test_u_history_driven_shock_restart_is_bit_for_bit(tmp_path, capsys):
    """A scene driven by a U(t) piston (a ramp read from CSV): 2N = N + restart + N."""
    csv = tmp_path / "ramp.csv"
    csv.write_text("t_ns,u_km_s\n0,1.0\n20,3.0\n")
    da, db = _restart_equals_full_run(tmp_path, "shock", TINY_SHOCK + ["--set", f"u_history={csv}"], capsys)
    assert db["params"]["u_history"] == str(csv)


def test_mca_restart_is_bit_for_bit_mid_crack(tmp_path, capsys):
    from clusterdyn.io.checkpoint import read_checkpoint
    da, db = _restart_equals_full_run(tmp_path, "mca-tension", TINY_MCA, capsys)
    _, st = read_checkpoint(tmp_path / "ck.h5")
    assert st["dynamics"]["nsteps"] == 200
    assert 0 < int((st["dynamics"]["linked_p"] == 0).sum()) < da["broken_links"]["value"]   # a live crack
    assert db["params"]["h5md_frames"] == 7 and db["params"]["steps"] == 400
    capsys.readouterr()
    for bad in ("steps=800", "frames=20", "material=concrete"):
        assert main(["run", "mca-tension", "--restart", str(tmp_path / "ck.h5"), "--out", str(tmp_path / "x"),
                     "--set", bad]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and bad in err and "only keys a continuation can change" in err
    assert main(["run", "mca-compression", "--restart", str(tmp_path / "ck.h5")]) == 2
    assert "a checkpoint of scene 'mca-compression' (it is of scene 'mca-tension')" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_restart_refuses_a_physics_key_and_another_scene(tmp_path, capsys):
    out = tmp_path / "a"
    assert main(["run", "shock", "--quiet", "--out", str(out)] + TINY_SHOCK) == 0
    ck = out / "checkpoint.h5"
    capsys.readouterr()
    assert main(["run", "shock", "--restart", str(ck), "--out", str(tmp_path / "b"), "--set", "u=6km/s"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "u=6km/s" in err and "the checkpoint ran with u=3km/s" in err
    assert not (tmp_path / "b").exists()             # refused before any work
    assert main(["run", "plate-impact", "--restart", str(ck), "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "a checkpoint of scene 'plate-impact' (it is of scene 'shock')" in err
    assert main(["run", "mca-tension", "--restart", str(ck), "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "a checkpoint of scene 'mca-tension' (it is of scene 'shock')" in err and "Traceback" not in err


BAD = [
    (["run", "shock", "--set", "size=1x1x1"], "size='1x1x1'"),
    (["run", "shock", "--set", "size=3x2x2"], "at least 10 repeat cells along the shock"),
    (["run", "shock", "--set", "size=12x1x1"], "a periodic cross-section at least 2 rc r0 wide"),
    (["run", "shock", "--set", "u=-1km/s"], "u='-1km/s'"),
    (["run", "shock", "--set", "u=3"], None),          # a bare number is taken in km/s: valid
    (["run", "shock", "--set", "axis=w"], "axis='w'"),
    (["run", "shock", "--restart", "/nonexistent/ck.h5"], "an existing checkpoint file"),
    (["run", "nosuchscene"], "scene='nosuchscene'"),
    (["run", "mca-tension", "--set", "size=4x3x3"], "at least 5 automaton sizes along the bar"),
    (["run", "mca-compression", "--set", "size=2x3x3"], "size='2x3x3'"),
    (["run", "mca-tension", "--restart", "/nonexistent/ck.h5"], "an existing checkpoint file"),
    (["study", "nosuchstudy"], "study='nosuchstudy'"),
    (["run", "shock", "--set", "nokey=1"], "--set='nokey'"),
]


@pytest.mark.parametrize("argv,message", BAD)
def test_bad_input_is_one_line_exit_2_before_work(argv, message, capsys, monkeypatch):
    if message is None:                  # checked for validity only: stop right after the checks
        from clusterdyn.scenes.shock import ShockScene
        monkeypatch.setattr(ShockScene, "setup", lambda *a: (_ for _ in ()).throw(InputError("x", 0, "stop")))
    code = main(argv + ["--quiet"] if argv[0] == "run" else argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and "Traceback" not in err
    if message is not None:
        assert message in err, err


def test_out_that_is_a_file_or_not_writable(tmp_path, capsys, monkeypatch):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert main(["run", "shock", "--quiet", "--out", str(f)]) == 2
    assert "a folder (this path is a file)" in capsys.readouterr().err
    assert main(["run", "shock", "--quiet", "--out", str(f / "sub")]) == 2
    assert "is a file" in capsys.readouterr().err
    monkeypatch.setattr("os.access", lambda *a: False)       # root ignores permissions: simulate
    with pytest.raises(InputError, match="no write permission"):
        check_out(tmp_path / "new")
