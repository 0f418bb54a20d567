"""The bad inputs of issue 47: each refused in one line before any work, naming the argument,
the value as written and what is allowed (exit status 2)."""

import pytest

from clusterdyn.cli import main

BIN = bytes(range(256)) * 4


@pytest.fixture
def files(tmp_path):
    (tmp_path / "bin.dat").write_bytes(BIN)
    (tmp_path / "sigma.csv").write_text("t_us,sigma_GPa\n0,0\n0.1,10\n1,10\n")
    (tmp_path / "neg.csv").write_text("t_ns,u_km_s\n0,-1\n20,-3\n")
    (tmp_path / "back.csv").write_text("t_ns,u_km_s\n0,1\n20,2\n10,2\n")
    (tmp_path / "late.csv").write_text("t_ns,u_km_s\n5,1\n20,3\n")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "typo.toml").write_text("frmaes = 10\n")
    (tmp_path / "extra.toml").write_text('scene = "shock"\nbogus = 1\n[params]\nframes = 10\n')
    return tmp_path


#: (command, argument and value as they must appear, a word of what is allowed)
CASES = [
    ("run shock --set u_history={d}/bin.dat", "u_history='{d}/bin.dat'", "not UTF-8 text"),
    ("run ejecta --set drive_csv={d}/bin.dat", "drive_csv='{d}/bin.dat'", "not UTF-8 text"),
    ("run shock --set u_history={d}/sigma.csv", "u_history='{d}/sigma.csv'", "its columns are t_us,sigma_GPa"),
    ("run shock --set u_history={d}/neg.csv", "u_history='{d}/neg.csv'", "values >= 0"),
    ("run shock --set u_history={d}/back.csv", "u_history='{d}/back.csv'", "strictly increasing times"),
    ("run shock --set u_history={d}/late.csv", "u_history='{d}/late.csv'", "its first time is 5 ns"),
    ("run dusting --set length=1e9mm", "parameters='length=1e9mm r0=10um'", "fits in memory"),
    ("run jets --set wavelength=1e6mm --set depth=1e6mm", "wavelength=1e6mm", "fits in memory"),
    ("run hypervelocity --set radius=1e6mm", "radius=1e6mm", "fits in memory"),
    ("run mca-friction --set seed=1e20", "seed='1e20'", "an integer in [0, 9.22e+18]"),
    ("study hugoniot --set cache={d}/afile", "cache='{d}/afile'", "this path is a file"),
    ("study mca-degrading --set material=Al", "material='Al'", "one of concrete"),
    ("study mca-degrading --set material=alumina", "material='alumina'", "one of concrete"),
    ("study mca-elasticity --set material=alumina", "material='alumina'", "one of Al,"),
    ("run mca-friction --set stress=1e6GPa", "stress='1e6GPa'", "compressive or yield strength"),
    ("run mca-friction --set stress=nan", "stress='nan'", "a number in (0, inf) GPa"),
    ("run mca-friction --set V=0", "V='0'", "(0, inf) m/s"),
    ("run mca-friction --set V=1e6m/s", "V='1e6m/s'", "quasi-static"),
    ("run plate-impact --set profile_times=-1", "profile_times='-1'", ">= 0"),
    ("run plate-impact --set profile_times=", "profile_times=''", "auto or times in ns"),
    ("run hypervelocity --set image_times=1,100", "image_times='1,100'", "within the run, 0-8 us"),
    ("run ejecta --set spectrum_time=100us", "spectrum_time='100us'", "within the run"),
    ("run jets --set jet_window=100us", "jet_window='100us'", "before the end of the run"),
    ("run ejecta --set depth=10um", "depth='10um'", "amplitude + 10 r0 = 90 um"),
    ("run shock --set fit_from=1e6", "fit_from='1e6'", "front travel below"),
    ("run dusting --set probe=1e6", "probe='1e6'", "half the sample's length"),
    ("run shock --set r0=1e-30um", "r0='1e-30um'", "[10 nm, 1 m]"),
    ("run shock --set r0=5e6m", "r0='5e6m'", "[10 nm, 1 m]"),
    ("run multilayer --set diameter=1mm --set r0=3mm", "r0='3mm'", "a quarter of the sphere diameter"),
    ("study stability --set size=1x1x1", "size='1x1x1'", "at least 10 cells along the shock"),
    ("study hugoniot --set u=1,,2", "u='1,,2'", "without empty items"),
    ("study hugoniot --set u=1,1", "u='1,1'", "without repeated values"),
    ("run shock --config {d}/typo.toml", "--config='{d}/typo.toml: frmaes'", "a parameter of scene 'shock'"),
    ("run shock --config {d}/extra.toml", "--config='{d}/extra.toml: bogus'", "top-level keys scene and [params]"),
    ("run taylor --set relax_cycles=0", "relax_cycles='0'", "an integer in [1,"),
    ("run plate-impact --set grain_size=1e11", "grain_size='1e11'", "at most twice the thinner plate"),
    ("run taylor --set grain_size=1e11", "grain_size='1e11'", "at most the rod's diameter"),
]


@pytest.mark.parametrize("cmd,named,allowed", CASES, ids=[c[0].split("--set ")[-1][:40] for c in CASES])
def test_refused_in_one_line_before_any_work(cmd, named, allowed, files, capsys):
    out = files / "out"
    argv = cmd.format(d=files).split(" ") + ["--quiet", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    assert named.format(d=files) in err and allowed in err, err
    assert not any(p.suffix in (".h5md", ".h5", ".json") for p in out.glob("*")) if out.exists() else True


@pytest.mark.parametrize("cmd,named,allowed", [
    ("run shock --set size=20x4x4 --set frames=1000000", "frames='1000000'", "at most the run's 647 steps"),
    ("run plate-impact --set profile_times=1e9 --set flyer=5 --set target=10 --set width=5",
     "profile_times='1e9'", "times within the run"),
    ("run shock --set size=20x4x4 --set dt_factor=1e-9", "max_wall='24'", "hours >= the run's estimate"),
    ("run dusting --set duration=1e6us", "max_wall='24'", "hours >= the run's estimate"),
    ("run ejecta --set t_end=1e9us", "snapshot_every='1us'", "at most 1000 velocity snapshots"),
    ("run ejecta --set t_end=1e9us --set snapshot_every=1e7us", "max_wall='24'", "hours >= the run's estimate"),
])
def test_refused_after_set_up_before_the_first_step(cmd, named, allowed, files, capsys):
    """Refusals that need the built sample (its steps, its particles): still before stepping."""
    argv = cmd.split(" ") + ["--quiet", "--out", str(files / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and named in err and allowed in err, err
    assert not (files / "out" / "checkpoint.h5").exists()


def test_max_wall_allows_a_long_run_and_a_default_frames_fits_a_short_run(tmp_path, capsys):
    import json
    # a short run (8x3x3 automata, 100 steps) under a small max_wall; the default 150 frames are
    # lowered to the 100 steps, and result.json records what ran
    assert main(["run", "mca-tension", "--quiet", "--out", str(tmp_path / "a"), "--set", "size=8x3x3",
                 "--set", "steps=100", "--set", "max_wall=0.001"]) == 0
    d = json.loads((tmp_path / "a" / "result.json").read_text())
    assert d["params"]["frames"] == 100 and d["params"]["steps"] == 100
    # the same run refused under a max_wall below its estimate (3.6 ms)
    capsys.readouterr()
    assert main(["run", "mca-tension", "--quiet", "--out", str(tmp_path / "b"), "--set", "size=8x3x3",
                 "--set", "steps=100", "--set", "max_wall=1e-6"]) == 2
    assert "max_wall='1e-6' is not allowed: expected hours >= the run's estimate" in capsys.readouterr().err


def test_fcc_packing_refuses_an_mca_material():
    from clusterdyn import units
    from clusterdyn.build import fcc_packing
    from clusterdyn.errors import InputError
    with pytest.raises(InputError, match="material='alumina' is not allowed: expected a Cluster Dynamics"):
        fcc_packing("alumina", 5 * units.um)


def test_mca_instability_names_the_command_line_setting(tmp_path, capsys):
    """The MCA advice "reduce the time step" had no command-line setting: it now names `steps`, and the
    time step carries its unit."""
    assert main(["run", "mca-compression", "--quiet", "--set", "steps=100", "--set", "strain_max=200",
                 "--set", "size=8x3x3"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--set steps= above 100" in err and " ns, default " in err, err
