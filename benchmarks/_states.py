"""Shared by the benchmarks: the aluminium piston shock at a stated shocked fraction, saved once.

``shock_state(nx, fraction)`` runs ``build_shock(size=(nx, 16, 16), u=3 km/s, 10 m/s
noise)`` (N = 1024 nx clusters, damping off) until at least ``fraction`` of the
sample (the piston excluded) moves faster than u/2, and saves the run with
:func:`clusterdyn.io.checkpoint.save_run` under ``benchmarks/results/states/``
(or ``$CD_BENCH_STATES``).  Later calls load the file, so every benchmark and
every engine starts its timed window from the same state.  A damped (J = 50)
window starts from the same state with the damping switched on
(:func:`load_state` with ``J``).
"""

import os
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
STATES = Path(os.environ.get("CD_BENCH_STATES", HERE / "results" / "states"))


def shocked_fraction(atoms, piston_mask, u):
    """Fraction of the non-piston particles moving along the shock faster than u/2."""
    v = atoms.get_velocities()[~piston_mask, 0]
    return float((v > 0.5 * u).mean())


def warm_kernels(J=None, sort=False):
    """Compile, or load from numba's on-disk cache, every kernel a timed window of the piston
    shock calls, on a small shock of its own (1 152 clusters, 200 steps, 0.1-0.7 s measured), so
    that no load falls inside the window.  A shock of 288 clusters for 2 steps, the warm-up
    before stop 28, never ran the local rebuild test over bricks: its three kernels were loaded
    from the cache inside the first window of every process (17-24 ms, measured: 1.2-1.5% of
    a 100-step window at 128k).  ``sort``: the Atoms sort's kernels too."""
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
        st["J"] = float(J)
        dyn = DampedVerlet(atoms, timestep=dyn.dt, J=float(J))
        dyn.set_state(dict(st, J=float(J)))
        dyn.forces = None              # forces of the undamped state: recomputed with damping
    return atoms, dyn, extra


#: the states the rebuild studies start from (``rebuild_oracle.py``, ``partial_rebuild.py``): the
#: race's slab (:func:`shock_state`, 30% shocked, undamped) and the 123k debris cloud at its contact
#: and cloud steps (``debris_lammps.py``'s ``debris_state``, scene options from ``debris_cloud.py``)
SCENES = {"slab": None, "contact": 400, "cloud": 1200}


def scene_list(ap, text):
    """The comma-separated ``--scenes`` value, each checked against :data:`SCENES` (``ap.error`` else)."""
    scenes = text.split(",")
    bad = [s for s in scenes if s not in SCENES]
    if bad:
        ap.error(f"--scenes: {bad[0]!r} is not one of {', '.join(SCENES)}")
    return scenes


def load_scene(scene, a):
    """(atoms, dyn) of a scene of :data:`SCENES`; ``a``: the parsed options (``nx`` for the slab,
    the debris scene's for the others)."""
    if scene == "slab":
        atoms, dyn, _ = load_state(shock_state(a.nx, 0.3))
        return atoms, dyn
    from clusterdyn.io.checkpoint import load_run
    from debris_lammps import debris_state
    path, _ = debris_state(a, SCENES[scene])
    atoms, dyn, _ = load_run(path)
    return atoms, dyn


def write_report(out, data, lines):
    """``out``.json (``data``) and ``out``.md (``lines``), the folder made; returns the .md path."""
    import json
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(data, indent=1, default=str))
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return out.with_suffix(".md")
