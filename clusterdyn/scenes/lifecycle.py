"""The scene lifecycle: one way to build, run, checkpoint, restart, analyse and report a scene.

Every scene, CD and MCA alike, is a :class:`SceneDef` subclass.  It declares
its parameters once (:class:`~clusterdyn.scenes.base.Param`, with ``restart=True`` on the
keys a continuation may change) and implements a few hooks; the lifecycle
does the rest the same way for every scene:

1. parse and check the parameters and the output folder (bad input is refused
   in one line before any work: :meth:`SceneDef.check`, :func:`check_out`);
2. for each stage of :meth:`SceneDef.plan` (most scenes have one; a scene
   comparing a single crystal with a polycrystal has two): build the sample,
   drives and dynamics (:meth:`SceneDef.setup`), attach the analysis
   (:meth:`SceneDef.attach`), run with a progress bar that shows the time left,
   write H5MD frames and checkpoints, then reduce the stage to an encodable
   summary (:meth:`SceneDef.finish`);
3. analyse the summaries into quantities with references and errors
   (:meth:`SceneDef.analyse`) and report them: a printed table, ``result.json``
   and the scene's PNGs with the CSV behind each (:meth:`SceneDef.report`).

A checkpoint holds the particles, the dynamics with its drives, the running
stage's analysis state, the summaries of the finished stages and the
parameters that ran.  ``--restart`` continues from it: N steps + restart + N
steps equal 2N steps bit for bit; a ``--set`` on restart may change only the
keys the scene marks ``restart=True`` (run length, output cadence), any
other key is refused, and ``result.json`` records what actually ran.
"""

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, InstabilityError

#: checkpoint file name in the output folder
CHECKPOINT = "checkpoint.h5"


@dataclass
class Stage:
    """One dynamics run of a scene.

    Attributes
    ----------
    name : str
        Stage name (``"main"`` for one-stage scenes).
    atoms, dyn :
        The sample (with its calculator and drives) and its dynamics.
    nsteps : int
        Total steps of the stage (the run stops there; a restart continues to it).
    frames : int
        Analysis frames over the stage (``on_frame`` is called every ``nsteps/frames`` steps).
    info : dict
        Encodable set-up facts the analysis needs (index arrays, lengths, speeds).
    on_frame : callable, optional
        ``on_frame(dyn)`` at every analysis frame (and at step 0 of a fresh run).
    analysis : object, optional
        The stage's analysis state: ``get_state() -> dict`` and ``set_state(dict)``.
    observers : list of (callable, interval)
        Attached to the dynamics for the stage (e.g. a free-surface velocity probe).
    observables : dict, optional
        H5MD observables ``{name: (callable(atoms) -> value, unit)}``.
    per_particle : dict, optional
        H5MD per-particle data ``{name: callable(atoms) -> (N, ...) array}``.
    stop : callable, optional
        ``stop(dyn) -> bool`` after every analysis frame: True ends the stage
        before ``nsteps`` (a run that stops when its physics is over; ``nsteps``
        is then the most it may take).
    """

    name: str
    atoms: object
    dyn: object
    nsteps: int
    frames: int
    info: dict = field(default_factory=dict)
    on_frame: object = None
    analysis: object = None
    observers: list = field(default_factory=list)
    observables: dict = None
    t_run: float = 0.0
    per_particle: dict = None
    stop: object = None


def check_out(out):
    """Refuse an output folder that cannot be written, before any work (returns a Path or None)."""
    if out is None:
        return None
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise InputError("--out", str(out), "a folder (this path is a file)")
    probe = p
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise InputError("--out", str(out), f"a folder path ({probe} is a file)")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError("--out", str(out), f"a folder you may write to (no write permission in {probe})")
    return p


def _same(a, b):
    """Parameter values equal (tuples and lists alike; floats exactly)."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def _plain(v):
    """A parameter value as stored in a checkpoint (tuples as lists)."""
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    return v


def _unplain(v, like):
    if isinstance(like, tuple) and isinstance(v, (list, tuple, np.ndarray)):
        return tuple(_unplain(x, like[0] if like else None) for x in v)
    if isinstance(v, np.generic):
        return v.item()
    return v


class SceneDef:
    """Base of every scene.  Subclasses set :attr:`name`, :attr:`description`, :attr:`params`
    and implement :meth:`setup`, :meth:`attach`, :meth:`finish`, :meth:`analyse` (and usually
    :meth:`check`, :meth:`report`)."""

    name = None
    description = ""
    params = ()
    #: H5MD file name stem (default: the scene's name)
    h5md_stem = None

    # -- hooks -------------------------------------------------------------------------
    def check(self, v):
        """Refuse degenerate input in one line (InputError) before any work."""

    def plan(self, v):
        """Names of the stages, run in order."""
        return ["main"]

    def setup(self, v, stage):
        """Build ``(atoms, dyn, info)`` of a stage: sample, calculator, drives, dynamics."""
        raise NotImplementedError

    def attach(self, v, stage, atoms, dyn, info):
        """The :class:`Stage` around a built or restored ``(atoms, dyn, info)``."""
        raise NotImplementedError

    def finish(self, v, stage):
        """Encodable summary of a finished stage (all that analysis and report need)."""
        raise NotImplementedError

    def analyse(self, v, summaries):
        """``(quantities, notes, extra)`` from the stages' summaries."""
        raise NotImplementedError

    def report(self, v, summaries, result, out):
        """Write the scene's PNGs and the CSVs behind them to ``out``; return the paths."""
        return []

    def verdict(self, v, summaries, result):
        """Set ``result.steady`` and ``result.warnings`` (one line each) where the scene can judge its run."""

    def retry(self, v, stage, exc, attempt):
        """Parameters for another attempt after ``exc`` (InstabilityError), or None to stop."""
        return None

    # -- the lifecycle -----------------------------------------------------------------
    def defaults(self):
        return {p.name: (p.parse(p.default) if p.default is not None else None) for p in self.params}

    def parse(self, overrides):
        """Defaults updated with ``overrides`` (text or values); unknown keys refused."""
        known = {p.name: p for p in self.params}
        vals = self.defaults()
        for k, x in (overrides or {}).items():
            if k not in known:
                raise InputError("--set", k, f"a parameter of scene '{self.name}': " + ", ".join(known))
            vals[k] = known[k].parse(x)
        return vals

    def restart_keys(self):
        return [p.name for p in self.params if getattr(p, "restart", False)]

    def parse_restart(self, overrides, stored):
        """The parameters of a continuation: the checkpoint's, with the allowed overrides."""
        known = {p.name: p for p in self.params}
        vals = {}
        for p in self.params:
            if p.name in stored:
                d = p.parse(p.default) if p.default is not None else None
                vals[p.name] = _unplain(stored[p.name], d)
            else:
                vals[p.name] = p.parse(p.default) if p.default is not None else None
        allowed = self.restart_keys()
        for k, x in (overrides or {}).items():
            if k not in known:
                raise InputError("--set", k, f"a parameter of scene '{self.name}': " + ", ".join(known))
            new = known[k].parse(x)
            if k not in allowed and not _same(new, vals[k]):
                raise InputError("--set", f"{k}={x}",
                                 "on --restart only keys a continuation can change: "
                                 + (", ".join(allowed) or "none"),
                                 hint=f"the checkpoint ran with {k}={_display(known[k], vals[k])}")
            vals[k] = new
        return vals

    def run(self, overrides=None, out=None, progress=True, restart=None):
        """Run the scene; returns its :class:`~clusterdyn.scenes.base.SceneResult`."""
        from ..io.checkpoint import load_run, read_run_extra
        from .base import SceneResult
        t0 = time.perf_counter()
        out = check_out(out)
        resume = None
        if restart is not None:
            if not Path(restart).is_file():
                raise InputError("--restart", str(restart), "an existing checkpoint file")
            extra = read_run_extra(restart)
            if not isinstance(extra, dict) or extra.get("scene") != self.name:
                got = extra.get("scene") if isinstance(extra, dict) else None
                raise InputError("--restart", str(restart), f"a checkpoint of scene '{self.name}'"
                                 + (f" (it is of scene '{got}')" if got else ""))
            v = self.parse_restart(overrides, extra["params"])
            resume = extra
        else:
            v = self.parse(overrides)
        self.check(v)
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
        summaries = list(resume["summaries"]) if resume else []
        names = self.plan(v)
        files = []
        for k, name in enumerate(names):
            if k < len(summaries):
                continue
            attempt = 0
            while True:
                try:
                    if resume is not None and resume.get("stage_index") == k:
                        atoms, dyn, extra = load_run(restart)
                        st = extra["stage"]
                        stage = self.attach(v, name, atoms, dyn, st["info"])
                        if stage.analysis is not None:
                            stage.analysis.set_state(st["analysis"])
                        stage.t_run = float(st.get("t_run", 0.0))
                        resume = None
                    else:
                        atoms, dyn, info = self.setup(v, name)
                        stage = self.attach(v, name, atoms, dyn, info)
                    files += self._run_stage(v, k, stage, summaries, out, progress, len(names))
                    break
                except InstabilityError as exc:
                    attempt += 1
                    nv = None if restart is not None else self.retry(v, name, exc, attempt)
                    if nv is None:
                        raise
                    v = nv
            summaries.append(self.finish(v, stage))
        quantities, notes, extra = self.analyse(v, summaries)
        res = SceneResult(self.name, quantities, 0.0, params=self.display(v), notes=list(notes),
                          extra=extra, files=[f for f in files if f])
        self.verdict(v, summaries, res)
        if out is not None:
            res.files += [Path(f) for f in self.report(v, summaries, res, out) or []]
        res.wall_time_s = time.perf_counter() - t0
        if out is not None:
            res.files.append(res.write(out))
        return res

    def display(self, vals):
        """Parameter values in their display units (for JSON and tables)."""
        return {p.name: _display_json(p, vals.get(p.name)) for p in self.params}

    def _h5md_path(self, out, name, nstages):
        stem = self.h5md_stem or self.name.replace("-", "_")
        return out / (f"{stem}.h5md" if nstages == 1 else f"{stem}_{name}.h5md")

    def _run_stage(self, v, k, stage, summaries, out, progress, nstages):
        from ..io.checkpoint import save_run
        from .common import run_frames
        dyn = stage.dyn
        for fn, interval in stage.observers:
            dyn.attach(fn, interval=interval)
        writer = None
        files = []
        if out is not None and v.get("h5md", False):
            from ..io import H5MDWriter
            path = self._h5md_path(out, stage.name, nstages)
            kw = dict(dyn=dyn, parameters=self.display(v), observables=stage.observables or {},
                      per_particle=stage.per_particle or {})
            if dyn.nsteps > 0 and path.exists():
                writer = H5MDWriter(str(path), stage.atoms, mode="a", restart_step=dyn.nsteps, **kw)
            else:
                writer = H5MDWriter(str(path), stage.atoms, **kw)
            dyn.attach(writer, interval=max(1, stage.nsteps // max(1, int(v.get("h5md_frames", 20)))))
            files.append(path)
        ckpt = (out / CHECKPOINT) if (out is not None and v.get("checkpoint_every", 0)) else None

        def extra():
            return {"scene": self.name, "params": {kk: _plain(x) for kk, x in v.items()},
                    "stage_index": k, "summaries": list(summaries),
                    "stage": {"name": stage.name, "info": stage.info, "t_run": stage.t_run,
                              "analysis": stage.analysis.get_state() if stage.analysis is not None else {}}}

        def on_frame(d):
            if stage.on_frame is not None:
                stage.on_frame(d)

        desc = self.name if nstages == 1 else f"{self.name} ({stage.name})"
        try:
            stage.t_run += run_frames(dyn, stage.nsteps, stage.frames, on_frame, progress=progress, desc=desc,
                                      checkpoint=ckpt, checkpoint_every=v.get("checkpoint_every", 0),
                                      save=lambda path: save_run(path, dyn, extra()), stop=stage.stop)
        finally:
            if writer is not None:
                writer.close()
            dyn.observers.clear()
        return files


def _display(p, value):
    from .. import units
    if p.unit and isinstance(value, float):
        return f"{value / units.NAMED[p.unit]:g}{p.unit}"
    if isinstance(value, (tuple, list)):
        return "x".join(str(x) for x in value)
    return str(value)


def _display_json(p, value):
    from .. import units
    if p.unit and isinstance(value, float):
        return {"value": value / units.NAMED[p.unit], "unit": p.unit}
    return value


def scene_params(params, *, frames=None, h5md_frames=20, checkpoint_every=10):
    """A scene's parameters followed by the lifecycle's own (output cadence; restart may change them)."""
    from .base import Param
    common = [
        Param("h5md", True, "write an H5MD trajectory (with --out)", kind="bool", restart=True),
        Param("h5md_frames", h5md_frames, "trajectory frames written to the H5MD file", kind="int", low=1,
              restart=True),
        Param("checkpoint_every", checkpoint_every, "analysis frames between checkpoints (with --out; "
              "0 = none)", kind="int", low=0, restart=True),
    ]
    own = {p.name for p in params}
    return list(params) + [p for p in common if p.name not in own]


__all__ = ["Stage", "SceneDef", "check_out", "scene_params", "CHECKPOINT"]
