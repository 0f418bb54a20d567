"""Helpers shared by the benchmark scripts (imported by them; imports none of them).

- **Saved shock states.**  ``shock_state(nx, fraction)`` runs the aluminium piston shock
  ``build_shock(size=(nx, 16, 16), u=3 km/s, 10 m/s noise)`` (N = 1024 nx clusters, damping
  off) until at least ``fraction`` of the sample (the piston excluded) moves faster than u/2,
  and saves it with :func:`clusterdyn.io.checkpoint.save_run` under ``benchmarks/results/states/``
  (or ``$CD_BENCH_STATES``).  Later calls load the file, so every engine and configuration
  starts its timed window from the same state.  ``load_state(path, J)`` switches pair damping on.
- ``warm_kernels``: every kernel a timed window calls, compiled or loaded from numba's disk
  cache before the window starts.
- Process memory (Linux ``/proc``): ``status``, ``reset_peak``, ``trim``.
- ``write_report``: ``<out>.json`` and ``<out>.md``.

Every script writes its per-run output under ``benchmarks/results/`` (ignored by git); the
headline figures and the command behind each are kept by hand in ``benchmarks/RESULTS.md``.
"""

import json
import os
import time
from pathlib import Path

import numpy as np
try:
    from clusterdyn.parallel import configure_openmp
except ImportError:         # an older checkout (lammps_tune.py --against) sets it when imported
    configure_openmp = None

if configure_openmp is not None:
    configure_openmp()      # the CLI's OpenMP waiting, before any kernel runs (clusterdyn.parallel)

HERE = Path(__file__).resolve().parent
#: per-run output of every script (not in git)
RESULTS = HERE / "results"
STATES = Path(os.environ.get("CD_BENCH_STATES", RESULTS / "states"))


# -- saved shock states ----------------------------------------------------------------------------

def shocked_fraction(atoms, piston_mask, u):
    """Fraction of the non-piston particles moving along the shock faster than u/2."""
    v = atoms.get_velocities()[~piston_mask, 0]
    return float((v > 0.5 * u).mean())


def warm_kernels(J=None, sort=False):
    """Compile, or load from numba's on-disk cache, every kernel a timed window of the piston
    shock calls, on a small shock of its own (1 152 clusters, 200 steps: long enough to run
    the local rebuild test over bricks), so that no load falls inside the window.
    ``sort``: the Atoms sort's kernels too."""
    from clusterdyn import units
    from clusterdyn.scenes.shock import build_shock
    t = build_shock(size=(32, 3, 3), u=3 * units.km_s, J=J)
    t.dyn.run(200)
    if sort:
        t.dyn.sort_atoms()
    del t


def state_path(nx, fraction):
    return STATES / f"shock_al_3kms_{nx}x16x16_shocked{int(round(100 * fraction))}.h5"


def shock_state(nx, fraction=0.3, chunk=100, verbose=True):
    """Path of the saved state (made on first use); see the module docstring."""
    from clusterdyn import units
    from clusterdyn.io.checkpoint import save_run
    from clusterdyn.scenes.shock import build_shock
    path = state_path(nx, fraction)
    if path.exists():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    u = 3 * units.km_s
    s = build_shock(size=(nx, 16, 16), u=u, J=None)
    if s.piston_mask.all():
        raise ValueError(f"shock_state: nx = {nx} cells make a sample that is all piston; use nx >= 2")
    t0 = time.perf_counter()
    while True:
        s.dyn.run(chunk)
        f = shocked_fraction(s.atoms, s.piston_mask, u)
        if verbose:
            print(f"  state {nx}x16x16: step {s.dyn.nsteps}, shocked {f:.1%}, {time.perf_counter() - t0:.0f} s",
                  flush=True)
        if f >= fraction:
            break
    tmp = path.with_suffix(".tmp")
    save_run(tmp, s.dyn, extra={"nx": nx, "shocked_fraction": f, "piston": np.flatnonzero(s.piston_mask)})
    os.replace(tmp, path)
    return path


def load_state(path, J=None):
    """(atoms, dyn, extra) of a saved state; ``J`` switches the pair damping on."""
    from clusterdyn.io.checkpoint import load_run
    from clusterdyn.md import DampedVerlet
    atoms, dyn, extra = load_run(path)
    if J is not None:
        st = dyn.get_state()
        dyn = DampedVerlet(atoms, timestep=dyn.dt, J=float(J))
        dyn.set_state(dict(st, J=float(J)))
        dyn.forces = None              # forces of the undamped state: recomputed with damping
    return atoms, dyn, extra


# -- process memory (Linux /proc) ------------------------------------------------------------------

def status(key):
    """A size field of /proc/self/status in bytes (``VmRSS``: resident now, ``VmHWM``: peak); -1 when
    the field is missing."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return -1


def reset_peak():
    """Reset the peak resident size (VmHWM) to the current one; False where the kernel does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def trim():
    """glibc's malloc_trim(0): free heap pages (e.g. left by h5py's chunked reads or a builder) go back
    to the system, so the process' size counts memory in use."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


# -- output ----------------------------------------------------------------------------------------

def write_report(out, data, lines):
    """``out``.json (``data``) and ``out``.md (``lines``), the folder made; returns the .md path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(data, indent=1, default=str))
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return out.with_suffix(".md")


def median(v):
    """Median of a list (nan when empty)."""
    v = sorted(v)
    if not v:
        return float("nan")
    k = len(v) // 2
    return v[k] if len(v) % 2 else 0.5 * (v[k - 1] + v[k])
