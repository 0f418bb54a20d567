"""Faults of the file system and the process: one writer per folder, a full disk, SIGINT.

Each fault ends a run in one line with its own exit status, and leaves what was written
before it whole: the H5MD frames open in h5py, and a restart from the last checkpoint
continues bit for bit.
"""

import errno
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from clusterdyn.cli import main

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--set", "size=20x4x4", "--set", "frames=10", "--set", "checkpoint_every=3"]


def _env():
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _values(path):
    d = json.loads(Path(path).read_text())
    return {k: x["value"] for k, x in d.items() if isinstance(x, dict) and "value" in x}


def _frames(path):
    with h5py.File(path, "r") as f:
        return list(f["particles/trajectory/position/step"][:])


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """The tiny shock run to the end, undisturbed: the reference of every restart here."""
    out = tmp_path_factory.mktemp("full")
    assert main(["run", "shock", "--quiet", "--out", str(out)] + TINY) == 0
    return out


def _one_line(err):
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert len(lines) == 1, err
    return lines[0]


def test_second_writer_is_refused_and_the_first_run_files_are_untouched(tmp_path, full_run, capsys):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("shock.h5md", "checkpoint.h5", "result.json"):
        (out / name).write_bytes((full_run / name).read_bytes())
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    # the first run: another process holding the folder
    holder = subprocess.Popen([sys.executable, "-c",
                               "import sys, time\n"
                               "from clusterdyn.scenes.lifecycle import lock_out\n"
                               f"with lock_out({str(out)!r}):\n"
                               "    print('held', flush=True); time.sleep(60)\n"],
                              stdout=subprocess.PIPE, text=True, env=_env())
    try:
        assert holder.stdout.readline().strip() == "held"
        capsys.readouterr()
        assert main(["run", "shock", "--quiet", "--out", str(out)] + TINY) == 2
        line = _one_line(capsys.readouterr().err)
        assert f"--out='{out}'" in line and "no other clusterdyn run is writing" in line
        assert f"pid {holder.pid}" in line
        # a study is refused the same way
        assert main(["study", "hugoniot", "--quiet", "--out", str(out), "--set", "u=3"]) == 2
        assert "no other clusterdyn run is writing" in _one_line(capsys.readouterr().err)
    finally:
        holder.kill()
        holder.wait()
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.name != ".clusterdyn.lock"}
    assert after == {k: v for k, v in before.items() if k != ".clusterdyn.lock"}
    assert _frames(out / "shock.h5md") == _frames(full_run / "shock.h5md")
    # the lock went with its process: the folder is free again
    assert main(["run", "shock", "--quiet", "--out", str(out)] + TINY) == 0


def _restart_matches(tmp_path, ckpt, full_run):
    cont = tmp_path / "cont"
    assert main(["run", "shock", "--quiet", "--out", str(cont), "--restart", str(ckpt)]) == 0
    assert _values(cont / "result.json") == _values(full_run / "result.json")


def test_a_file_system_that_fills_stops_the_run_with_its_files_whole(tmp_path, full_run, capsys):
    """A real limit: the child may write files of at most 1.5 MB (RLIMIT_FSIZE); the full run's
    H5MD is 1.8 MB and each checkpoint 0.5-0.7 MB, so the H5MD fills first, mid-run."""
    out = tmp_path / "a"
    code = ("import resource, signal, sys\n"
            "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
            "resource.setrlimit(resource.RLIMIT_FSIZE, (1500000, 1500000))\n"
            "from clusterdyn.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    p = subprocess.run([sys.executable, "-c", code, "run", "shock", "--quiet", "--out", str(out)] + TINY,
                       capture_output=True, text=True, env=_env(), timeout=300)
    assert p.returncode == 1, p.stderr
    line = _one_line(p.stderr)
    assert line.startswith(f"clusterdyn: error: cannot write {out / 'shock.h5md'}: File too large")
    assert "the checkpoint" in line and "--restart" in line
    steps = _frames(out / "shock.h5md")                     # opens: the frames written are whole
    assert 3 <= len(steps) < len(_frames(full_run / "shock.h5md"))
    assert steps == _frames(full_run / "shock.h5md")[:len(steps)]
    assert not [f for f in os.listdir(out) if f.endswith(".tmp")]
    _restart_matches(tmp_path, out / "checkpoint.h5", full_run)
    # a limit below one checkpoint: the first checkpoint is not begun
    out = tmp_path / "c"
    p = subprocess.run([sys.executable, "-c", code.replace("1500000", "400000"), "run", "shock", "--quiet",
                        "--out", str(out), "--set", "h5md=false"] + TINY, capture_output=True, text=True,
                       env=_env(), timeout=300)
    assert p.returncode == 1, p.stderr
    assert _one_line(p.stderr) == (f"clusterdyn: error: cannot write {out / 'checkpoint.h5'}: File too large; kept: "
                                   "no checkpoint written yet; the file-size limit is 0.381 MiB")
    assert sorted(os.listdir(out)) == [".clusterdyn.lock"]


def test_a_write_that_fails_with_enospc_is_one_line_and_exit_1(tmp_path, full_run, capsys, monkeypatch):
    """The writer's file system made to fail: the 6th H5MD frame and then the 3rd checkpoint
    raise OSError(ENOSPC)."""
    from clusterdyn.io import H5MDWriter
    from clusterdyn.io import checkpoint as ck
    real = H5MDWriter.write
    calls = []

    def failing(self, **kw):
        calls.append(1)
        if len(calls) == 6:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, **kw)

    monkeypatch.setattr(H5MDWriter, "write", failing)
    out = tmp_path / "a"
    assert main(["run", "shock", "--quiet", "--out", str(out)] + TINY) == 1
    line = _one_line(capsys.readouterr().err)
    assert "No space left on device" in line and "5 H5MD frames" in line
    assert len(_frames(out / "shock.h5md")) == 5
    monkeypatch.setattr(H5MDWriter, "write", real)

    real_put = ck._put
    saves = []

    def failing_put(group, name, value, where):
        if where == "state['run_format']":
            saves.append(1)
            if len(saves) == 3:
                raise RuntimeError("Can't write data (file write failed: errno = 28, "
                                   "error message = 'No space left on device')")
        return real_put(group, name, value, where)

    monkeypatch.setattr(ck, "_put", failing_put)
    out = tmp_path / "b"
    assert main(["run", "shock", "--quiet", "--out", str(out), "--set", "h5md=false", "--set", "frames=20",
                 "--set", "checkpoint_every=3"] + TINY[:2]) == 1
    line = _one_line(capsys.readouterr().err)
    assert f"cannot write {out / 'checkpoint.h5'}: No space left on device" in line
    assert not [f for f in os.listdir(out) if f.endswith(".tmp")]
    monkeypatch.setattr(ck, "_put", real_put)
    _, st = ck.read_checkpoint(out / "checkpoint.h5")         # the second checkpoint, whole
    assert st["extra"]["params"]["frames"] == 20


def test_checkpoint_has_the_mode_of_every_other_output(full_run):
    umask = os.umask(0o022)
    os.umask(umask)
    for name in ("checkpoint.h5", "result.json", "shock.h5md"):
        assert stat.S_IMODE((full_run / name).stat().st_mode) == 0o666 & ~umask, name


def test_sigint_stops_a_run_with_130_and_keeps_the_checkpoint(tmp_path, full_run):
    out = tmp_path / "a"
    p = subprocess.Popen([sys.executable, "-m", "clusterdyn.cli", "run", "shock", "--quiet", "--out", str(out),
                          "--set", "size=20x4x4", "--set", "frames=400", "--set", "checkpoint_every=1",
                          "--set", "h5md_frames=400"],
                         stderr=subprocess.PIPE, text=True, env=_env())
    t0 = time.time()
    while not (out / "checkpoint.h5").exists() and time.time() - t0 < 120 and p.poll() is None:
        time.sleep(0.05)
    time.sleep(0.3)
    p.send_signal(signal.SIGINT)
    err = p.communicate(timeout=60)[1]
    assert p.returncode == 130, err
    line = _one_line(err)
    assert line.startswith("clusterdyn: interrupted; the last checkpoint") and "--restart" in line
    _frames(out / "shock.h5md")
    from clusterdyn.io.checkpoint import read_checkpoint
    read_checkpoint(out / "checkpoint.h5")


def test_an_interrupt_a_library_swallowed_still_stops_the_run(tmp_path, monkeypatch, capsys):
    """SIGINT arriving inside a callback that ignores exceptions ("Exception ignored in ...") only sets
    the flag: the run stops at its next frame, and never exits 0."""
    from clusterdyn import errors
    from clusterdyn.scenes import common
    real = common.run_frames

    def swallowing(dyn, nsteps, nframes, on_frame, **kw):
        def hit(d):
            if d.nsteps > 0:
                errors.INTERRUPTED[0] = True           # what the handler does before its exception is lost
            on_frame(d)
        return real(dyn, nsteps, nframes, hit, **kw)

    monkeypatch.setattr(common, "run_frames", swallowing)
    assert main(["run", "shock", "--quiet", "--out", str(tmp_path / "a")] + TINY) == 130
    assert "interrupted" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "a" / "result.json").exists()


def test_a_study_in_its_default_folder_holds_it(tmp_path, monkeypatch):
    """A study run without --out writes runs/<study>-<tag>: that folder is locked too (a second
    process is refused in one line)."""
    from clusterdyn.studies.common import out_folder
    monkeypatch.chdir(tmp_path)
    folder = out_folder(None, "hugoniot", "Al")
    code = ("from clusterdyn.studies.common import out_folder; out_folder(None, 'hugoniot', 'Al')")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=_env())
    assert p.returncode != 0 and "no other clusterdyn run is writing" in p.stderr
    assert (folder / ".clusterdyn.lock").exists()
