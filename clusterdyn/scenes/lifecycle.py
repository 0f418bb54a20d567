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

import contextlib
import math
import os
import sys
import time
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from .. import units
from ..errors import DEFER_INTERRUPT, InputError, InstabilityError, OutputError, check_interrupt
from .output import LOCKFILE, WRITE_MARGIN, _write_failure, _WriteWatch, check_out, lock_out, room_for  # noqa: F401

#: checkpoint file name in the output folder
CHECKPOINT = "checkpoint.h5"
#: the last checkpoint written in this process: {"path": str, "step": int}
LAST_CHECKPOINT = {}


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
    setup: object = None


#: metadata of a :class:`Setup` field that holds a live object (not written to a checkpoint)
LIVE = {"live": True}


@dataclass
class Setup:
    """What a scene's :meth:`SceneDef.setup` builds for a stage: the sample and its dynamics (live
    objects), and the encodable set-up facts the stage's analysis needs (index arrays, lengths,
    speeds), one field each.

    A subclass adds its fields; a field with ``metadata=LIVE`` holds a live object and is left out
    of :meth:`state`.  :meth:`state` is the checkpoint's payload for the stage, and
    :meth:`restore` builds the same set-up around the particles and dynamics a checkpoint gives back
    (nothing is computed again).
    """

    atoms: object = field(repr=False, metadata=LIVE)
    dyn: object = field(repr=False, metadata=LIVE)

    def __getitem__(self, key):
        """A field by name, so that analysis helpers read a set-up and its :meth:`state` (a summary's
        or a checkpoint's dict) alike."""
        if key in self.__dataclass_fields__:
            return getattr(self, key)
        raise KeyError(key)

    def state(self):
        """The encodable fields as a dict (tuples as lists), for a checkpoint."""
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self) if not f.metadata.get("live")}

    @classmethod
    def restore(cls, atoms, dyn, state):
        """The set-up of ``state`` (:meth:`state`, as a checkpoint gives it back) around ``atoms`` and ``dyn``."""
        kw = {}
        for f in fields(cls):
            if f.metadata.get("live") or f.name not in state:
                continue
            x = state[f.name]
            if isinstance(x, np.generic):
                x = x.item()
            if f.type in (tuple, "tuple") and isinstance(x, (list, np.ndarray)):
                x = tuple(y.item() if isinstance(y, np.generic) else y for y in x)
            kw[f.name] = x
        return cls(atoms=atoms, dyn=dyn, **kw)


def _given_text(params, overrides):
    """The overrides as the user wrote them, for refusals (a bare ASE number shown in the display unit too)."""
    known = {p.name: p for p in params}
    out = {}
    for k, x in (overrides or {}).items():
        p = known.get(k)
        if p is not None and p.takes_ase_number(x):
            out[k] = f"{float(x):g} (ASE units: {float(x) / units.NAMED[p.unit]:g} {p.unit})"
        else:
            out[k] = str(x)
    return out


def _parse_value(p, x):
    """One override: bare Python numbers of a parameter with a unit in ASE units, the rest as text."""
    return p.parse_ase(x) if p.takes_ase_number(x) else p.parse(x)


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
    #: the :class:`Setup` subclass :meth:`setup` returns (None: a scene whose ``setup`` still returns
    #: ``(atoms, dyn, info)`` and whose ``attach`` takes them)
    setup_class = None
    #: what a user can change from the command line after an instability (formatted with the
    #: parameters; added to the message), e.g. the MCA scenes' ``steps``
    instability_hint = None

    # -- hooks -------------------------------------------------------------------------
    def check(self, v):
        """Refuse degenerate input in one line (InputError) before any work."""

    def plan(self, v):
        """Names of the stages, run in order."""
        return ["main"]

    def setup(self, v, stage):
        """Build a stage: sample, calculator, drives, dynamics; a :attr:`setup_class` instance (or,
        for a scene without one, ``(atoms, dyn, info)``)."""
        raise NotImplementedError

    def attach(self, v, stage, setup):
        """The :class:`Stage` around a built or restored :class:`Setup` (a scene without a
        :attr:`setup_class`: ``attach(v, stage, atoms, dyn, info)``)."""
        raise NotImplementedError

    def build_stage(self, v, stage):
        """:meth:`setup` then :meth:`attach`: the :class:`Stage` of a fresh run."""
        built = self.setup(v, stage)
        if isinstance(built, Setup):
            return self._attached(v, stage, built)
        atoms, dyn, info = built
        return self.attach(v, stage, atoms, dyn, info)

    def restore_stage(self, v, stage, atoms, dyn, info):
        """The :class:`Stage` around particles and dynamics restored from a checkpoint whose stage
        payload is ``info``."""
        if self.setup_class is None:
            return self.attach(v, stage, atoms, dyn, info)
        return self._attached(v, stage, self.setup_class.restore(atoms, dyn, info))

    def _attached(self, v, name, setup):
        st = self.attach(v, name, setup)          # may change the set-up (a restart's longer run)
        st.setup = setup
        if not st.info:
            st.info = setup.state()
        return st

    def finish(self, v, stage):
        """Encodable summary of a finished stage (all that analysis and report need)."""
        raise NotImplementedError

    def analyse(self, v, summaries):
        """``(quantities, notes, extra)`` from the stages' summaries, or ``(quantities, notes, extra,
        data)``: ``data`` is what :meth:`report` needs of the analysis (fitted once here), held in
        memory as ``result.data``."""
        raise NotImplementedError

    def analysed(self, v, summaries):
        """:meth:`analyse` as ``(quantities, notes, extra, data)`` (``data`` None when it keeps nothing)."""
        out = tuple(self.analyse(v, summaries))
        return out if len(out) == 4 else out + (None,)

    def report(self, v, summaries, result, out):
        """Write the scene's PNGs and the CSVs behind them to ``out``; return the paths
        (``result.data``: what :meth:`analyse` kept for it)."""
        return []

    def verdict(self, v, summaries, result):
        """Set ``result.steady`` and ``result.warnings`` (one line each) where the scene can judge its run."""

    def retry(self, v, stage, exc, attempt):
        """Parameters for another attempt after ``exc`` (InstabilityError), or None to stop."""
        return None

    # -- the lifecycle -----------------------------------------------------------------
    @property
    def Values(self):
        """The frozen dataclass of this scene's parameter values (:func:`~clusterdyn.scenes.base.values_class`)."""
        cls = self.__dict__.get("_values_class")
        if cls is None or cls._names != tuple(p.name for p in self.params):
            from .base import values_class
            cls = self.__dict__["_values_class"] = values_class(self.name or type(self).__name__, self.params)
        return cls

    def defaults(self):
        """The default values (a :attr:`Values`, ASE units)."""
        return self.Values(**self._default_dict())

    def _default_dict(self):
        return {p.name: (p.parse(p.default) if p.default is not None else None) for p in self.params}

    def parse(self, overrides):
        """The parameter values (a :attr:`Values`, ASE units): the defaults updated with ``overrides``.

        ``overrides`` maps parameter names to text or Python values.  Text is read as on the
        command line: a number with a unit (``"5um"``, ``"3km/s"``), or a bare number in the
        parameter's display unit (``clusterdyn list`` names it).  A bare Python number for a
        parameter with a unit is in ASE units, as builders and calculators take it:
        ``{"r0": 5 * units.um}`` is 5 um (its range is checked in the display unit).  Unknown keys
        and values out of range are refused in one line (InputError).  Callers whose numbers are in
        display units write them as text first (:func:`~clusterdyn.scenes.base.display_text`).
        """
        known = {p.name: p for p in self.params}
        vals = self._default_dict()
        self._given = _given_text(self.params, overrides)
        for k, x in (overrides or {}).items():
            if k not in known:
                raise InputError("--set", k, f"a parameter of scene '{self.name}': " + ", ".join(known))
            vals[k] = _parse_value(known[k], x)
        return self.Values(**vals)

    def given(self, p, value):
        """A parameter's value as the user wrote it (for a refusal), else in its display unit."""
        text = getattr(self, "_given", {}).get(p.name if not isinstance(p, str) else p)
        if text is not None:
            return text
        if isinstance(p, str):
            p = {q.name: q for q in self.params}[p]
        return _display(p, value)

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
        self._given = _given_text(self.params, overrides)
        for k, x in (overrides or {}).items():
            if k not in known:
                raise InputError("--set", k, f"a parameter of scene '{self.name}': " + ", ".join(known))
            new = _parse_value(known[k], x)
            if k not in allowed and not _same(new, vals[k]):
                raise InputError("--set", f"{k}={x}",
                                 "on --restart only keys a continuation can change: "
                                 + (", ".join(allowed) or "none"),
                                 hint=f"the checkpoint ran with {k}={_display(known[k], vals[k])}")
            vals[k] = new
        return self.Values(**vals)

    def run(self, overrides=None, out=None, progress=True, restart=None):
        """Run the scene; returns its :class:`~clusterdyn.scenes.base.SceneResult`.

        Bad input, an output folder another run holds (:func:`lock_out`), a sample that
        cannot fit in memory and a run estimated past ``max_wall`` hours are refused in one
        line before any work.  A file that cannot be written (full disk) raises
        :class:`~clusterdyn.errors.OutputError` naming it and what is kept: the last
        checkpoint (replaced only once a new one is complete) and the H5MD frames written.
        """
        from ..io.checkpoint import read_run_extra
        t0 = time.perf_counter()
        out = check_out(out)
        resume = None
        check_interrupt()
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
        try:
            self._check_sizes(v)
            self.check(v)
            self._check_memory(v)
        except InputError as exc:
            text = getattr(self, "_given", {}).get(exc.argument)
            if text is None or exc.value == text:
                raise
            raise InputError(exc.argument, text, exc.allowed, hint=getattr(exc, "hint", None)) from None
        with lock_out(out), _WriteWatch() as watch:
            if out is not None:
                self._check_writable(v, out)
            return self._run_locked(v, out, progress, restart, resume, watch, t0)

    # -- run budget: wall time and memory, estimated before any work -------------------
    #: particle-steps per second assumed for the wall-time estimate: conservative (the CD
    #: engine does 1-3 million on two cores; MCA scenes set their own)
    rate = 3.0e5
    #: the same for MCA dynamics (pairs with state: about ten times the work per particle)
    rate_mca = 3.0e4
    #: bytes per particle assumed for the memory estimate (positions, momenta, forces, the
    #: neighbour list and the analysis: a low bound, so that only a run that cannot fit is refused)
    bytes_per_particle = 1000
    #: estimated wall times past this (s) are announced in one line on stderr
    wall_note_s = 3600.0

    def estimate_particles(self, v):
        """Particles the set-up will build, from the parameters alone (None: not known before set-up)."""
        return None

    def _check_memory(self, v):
        n = self.estimate_particles(v)
        if n is None:
            return
        need = float(n) * self.bytes_per_particle
        try:
            have = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):  # pragma: no cover - no sysconf
            return
        if need > have:
            raise InputError("parameters", _sizes_text(self, v),
                             f"a sample that fits in memory ({have / 2**30:.3g} GiB here)",
                             hint=f"about {n:.3g} particles would need at least {need / 2**30:.3g} GiB")

    def _check_wall(self, v, stage):
        """Estimate the stage's wall time (particle-steps / :attr:`rate`) before it starts; one line
        past :attr:`wall_note_s`, a refusal past ``max_wall`` hours."""
        steps = max(0, int(stage.nsteps) - int(getattr(stage.dyn, "nsteps", 0)))
        n = len(stage.atoms)
        rate = self.rate_mca if type(stage.dyn).__name__ == "MCADynamics" else self.rate
        est = float(n) * steps / rate
        limit_h = v.get("max_wall")
        if limit_h is not None and est > limit_h * 3600.0:
            raise InputError("max_wall", self.given("max_wall", limit_h),
                             f"hours >= the run's estimate, {est / 3600:.3g} h",
                             hint=f"{n} particles x {steps:.4g} steps at a conservative {rate:.3g} "
                                  f"particle-steps/s; shorten the run, or allow it with --set "
                                  f"max_wall={math.ceil(est / 3600 * 1.2):g}")
        if est > self.wall_note_s:
            upto = "up to " if stage.stop is not None else ""
            print(f"clusterdyn: note: {self.name}: this run is estimated at {upto}{_hours(est)} "
                  f"({n} particles x {upto}{steps:.4g} steps at a conservative {rate:.3g} particle-steps/s)",
                  file=sys.stderr)

    def _check_frames(self, v, stage):
        """Refuse more analysis or H5MD frames than the run has steps (they would be silently fewer).

        A default (not given) larger than a short run is lowered to the run's steps, and
        ``result.json`` records the number used.  Returns the values (changed where lowered)."""
        n = int(stage.nsteps)
        for key in ("frames", "h5md_frames"):
            want = v.get(key)
            if want is None or n < 1 or (key == "frames" and want != stage.frames):
                continue
            if int(want) > n:
                if key not in getattr(self, "_given", {}):
                    v = v.replace(**{key: n})
                    if key == "frames":
                        stage.frames = n
                    continue
                raise InputError(key, self.given(key, want), f"at most the run's {n} steps (one frame per step)")
        return v

    #: parameters that set the size of a cluster or automaton, and the range the model is checked in
    size_params = ("r0", "d", "r0_inclusion")
    size_range_m = (1e-8, 1.0)

    def _check_sizes(self, v):
        from .. import units
        lo, hi = self.size_range_m
        for p in self.params:
            val = v.get(p.name)
            if p.name in self.size_params and p.unit and isinstance(val, float):
                if not lo * units.m <= val <= hi * units.m:
                    raise InputError(p.name, self.given(p, val), f"a size in [{lo * 1e9:g} nm, {hi:g} m] (clusters "
                                     "from 10 nm to 1 m: outside it the arithmetic in Angstrom loses the physics)")

    def _check_writable(self, v, out):
        """Refuse an output folder holding a file this run would have to overwrite but may not."""
        names = [CHECKPOINT, "result.json"]
        if v.get("h5md", False):
            names += [self._h5md_path(out, n, len(self.plan(v))).name for n in self.plan(v)]
        for name in names:
            f = out / name
            if f.exists() and not os.access(f, os.W_OK):
                raise InputError("--out", str(out), "a folder whose files clusterdyn may overwrite",
                                 hint=f"{f} is read-only")

    def _run_locked(self, v, out, progress, restart, resume, watch, t0):
        from ..io.checkpoint import load_run
        from .base import SceneResult
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
                        stage = self.restore_stage(v, name, atoms, dyn, st["info"])
                        if stage.analysis is not None:
                            stage.analysis.set_state(st["analysis"])
                        stage.t_run = float(st.get("t_run", 0.0))
                        resume = None
                    else:
                        try:
                            stage = self.build_stage(v, name)
                        except MemoryError as exc:
                            raise InputError("parameters", _sizes_text(self, v), "a sample that fits in memory",
                                             hint=str(exc)) from None
                    if attempt == 0:
                        v = self._check_frames(v, stage)
                        self._check_wall(v, stage)
                    files += self._run_stage(v, k, stage, summaries, out, progress, len(names), watch)
                    break
                except InstabilityError as exc:
                    attempt += 1
                    nv = None if restart is not None else self.retry(v, name, exc, attempt)
                    if nv is None:
                        if self.instability_hint and getattr(exc, "message", None) is not None:
                            raise InstabilityError(f"{exc.message}; {self.instability_hint.format(**v)}", exc.step,
                                                   exc.particles or None, exc.quantity, exc.value,
                                                   exc.limit) from None
                        raise
                    v = nv
            summaries.append(self.finish(v, stage))
        quantities, notes, extra, data = self.analysed(v, summaries)
        if out is not None and LAST_CHECKPOINT.get("path") == str(out / CHECKPOINT):
            files.append(out / CHECKPOINT)            # written by this run: listed with what it wrote
        res = SceneResult(self.name, quantities, 0.0, params=self.display(v), notes=list(notes),
                          extra=extra, files=[f for f in files if f], data=data)
        self.verdict(v, summaries, res)
        if out is not None:
            res.files += [Path(f) for f in self.report(v, summaries, res, out) or []]
        res.wall_time_s = time.perf_counter() - t0
        if out is not None:
            try:
                res.files.append(res.write(out))
            except OSError as exc:
                raise OutputError(out / "result.json", exc, "the H5MD frames and the last checkpoint") from None
        return res

    def display(self, vals):
        """Parameter values in their display units (for JSON and tables)."""
        return {p.name: _display_json(p, vals.get(p.name)) for p in self.params}

    def _h5md_path(self, out, name, nstages):
        stem = self.h5md_stem or self.name.replace("-", "_")
        return out / (f"{stem}.h5md" if nstages == 1 else f"{stem}_{name}.h5md")

    def _run_stage(self, v, k, stage, summaries, out, progress, nstages, watch=None):
        from ..io.checkpoint import save_run
        from .common import run_frames
        watch = watch if watch is not None else _WriteWatch()
        dyn = stage.dyn
        for fn, interval in stage.observers:
            dyn.attach(fn, interval=interval)
        writer = None
        path = None
        files = []
        ckpt = (out / CHECKPOINT) if (out is not None and v.get("checkpoint_every", 0)) else None

        def kept():
            parts = []
            if writer is not None:
                parts.append(f"{writer.nframes} H5MD frames in {path}")
            if ckpt is not None:
                last = LAST_CHECKPOINT.get("path") == str(ckpt) and LAST_CHECKPOINT.get("step")
                parts.append(f"the checkpoint {ckpt} at step {last} (continue with --restart {ckpt})"
                             if last is not False and last is not None else "no checkpoint written yet")
            return "; ".join(parts) or None

        if out is not None and v.get("h5md", False):
            from ..io import H5MDWriter
            path = self._h5md_path(out, stage.name, nstages)
            kw = dict(dyn=dyn, parameters=self.display(v), observables=stage.observables or {},
                      per_particle=stage.per_particle or {})
            try:
                if dyn.nsteps > 0 and path.exists():
                    writer = H5MDWriter(str(path), stage.atoms, mode="a", restart_step=dyn.nsteps, **kw)
                else:
                    writer = H5MDWriter(str(path), stage.atoms, **kw)
                watch.check(path, kept())
            except Exception as exc:
                if not _write_failure(exc):
                    raise
                raise OutputError(path, exc, kept()) from None

            grow = [0]

            def write_frame():
                before = path.stat().st_size
                room_for(path, max(2 * grow[0], 128 * len(stage.atoms)), kept())
                try:
                    writer.write()
                    watch.check(path, None)
                    grow[0] = max(grow[0], path.stat().st_size - before)
                except Exception as exc:
                    if not _write_failure(exc):
                        raise
                    raise OutputError(path, exc, kept()) from None

            dyn.attach(write_frame, interval=max(1, stage.nsteps // max(1, int(v.get("h5md_frames", 20)))))
            files.append(path)

        def extra():
            return {"scene": self.name, "params": {kk: _plain(x) for kk, x in v.items()},
                    "stage_index": k, "summaries": list(summaries),
                    "stage": {"name": stage.name, "info": stage.info, "t_run": stage.t_run,
                              "analysis": stage.analysis.get_state() if stage.analysis is not None else {}}}

        def save(p):
            last = Path(p).stat().st_size if Path(p).is_file() else 0
            room_for(Path(p), max(last + last // 4, 600 * len(stage.atoms)), kept(), fresh=True)
            try:
                save_run(p, dyn, extra())
                watch.check(p, None)
            except Exception as exc:
                if not _write_failure(exc):
                    raise
                raise OutputError(p, exc, kept()) from None
            LAST_CHECKPOINT.update(path=str(p), step=int(dyn.nsteps))

        def on_frame(d):
            check_interrupt()
            if stage.on_frame is not None:
                stage.on_frame(d)

        desc = self.name if nstages == 1 else f"{self.name} ({stage.name})"
        failed = False
        dyn.attach(check_interrupt, interval=1)      # SIGINT stops the run at its next step
        DEFER_INTERRUPT[0] += 1
        try:
            stage.t_run += run_frames(dyn, stage.nsteps, stage.frames, on_frame, progress=progress, desc=desc,
                                      checkpoint=ckpt, checkpoint_every=v.get("checkpoint_every", 0),
                                      save=save, stop=stage.stop)
        except OutputError:
            failed = True
            raise
        finally:
            DEFER_INTERRUPT[0] -= 1
            dyn.observers.clear()
            if writer is not None:
                try:
                    writer.close()
                    watch.check(path, None)
                except Exception as exc:
                    watch.failures.clear()
                    if not failed and _write_failure(exc):
                        raise OutputError(path, exc, kept()) from None
                    if not _write_failure(exc):
                        raise
        return files


def read_history_csv(name, path, kinds=("u",), signed=False):
    """A drive history read from the CSV ``path`` given as parameter ``name``, checked before any work.

    ``kinds`` are the value columns allowed: ``"u"`` (speed, u_<unit>), ``"sigma"``
    (stress, sigma_<unit>).  Refused in one line naming ``name`` and the path as written:
    a file that is not UTF-8 text, a header or rows the table reader refuses, a column of
    another kind (a stress read as a speed), times that decrease or start after 0 (shown in
    the file's own time unit), and
    (unless ``signed``) negative values.  Returns ``(Table, kind)``.
    """
    from ..md.histories import Table
    text = str(path)
    if not os.path.isfile(text):
        raise InputError(name, text, "an existing CSV file")
    try:
        with open(text, encoding="utf-8") as fh:
            head = fh.read()
    except UnicodeDecodeError:
        raise InputError(name, text, "a text CSV file (this file is not UTF-8 text)") from None
    except OSError as exc:
        raise InputError(name, text, f"a CSV file you may read ({exc.strerror})") from None
    header = next((ln for ln in head.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    cols = [h.strip() for h in header.split(",")]
    kind = "sigma" if any(c.startswith("sigma_") for c in cols) else "u"
    want = " or ".join({"u": "a speed column u_<unit> (u_km_s, u_m_s, ...)",
                        "sigma": "a stress column sigma_<unit> (sigma_GPa, ...)"}[k] for k in kinds)
    if kind not in kinds:
        raise InputError(name, text, f"a CSV with a time column and {want}",
                         hint=f"its columns are {','.join(cols)}")
    try:
        hist = Table.read_csv(text)
    except InputError as exc:
        raise InputError(name, text, f"a CSV with a time column and {want}",
                         hint=f"{exc.allowed}; its columns are {','.join(cols)}" if exc.argument == "columns"
                         else str(exc.allowed)) from None
    t = np.asarray(hist.times, float)
    vals = np.asarray(hist.values, float)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(vals))):
        raise InputError(name, text, "a CSV of finite numbers")
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise InputError(name, text, "times that never decrease")
    if t[0] > 0:
        tcol = next((c for c in cols if c in Table.TIME_COLUMNS), None)
        shown = f"{t[0] / Table.TIME_COLUMNS[tcol]:g} {tcol[2:]}" if tcol else f"{t[0]:g}"
        raise InputError(name, text, "a history that starts at time 0 (the run starts there)",
                         hint=f"its first time is {shown}")
    if not signed and np.any(vals < 0):
        raise InputError(name, text, "values >= 0 (the drive pushes; a negative speed or stress pulls the "
                         "sample apart)")
    return hist, kind


def fcc_count(volume, r0):
    """Clusters of size ``r0`` in ``volume`` packed fcc (nearest neighbours r0 apart): sqrt(2) V / r0^3."""
    return math.sqrt(2.0) * float(volume) / float(r0) ** 3


def _hours(seconds):
    if seconds < 3600:
        return f"{seconds / 60:.3g} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.3g} h"
    if seconds < 3 * 365 * 86400:
        return f"{seconds / 86400:.3g} days"
    return f"{seconds / (365 * 86400):.3g} years"


def _sizes_text(scene, v):
    """The size-setting parameters of a run as the user would write them (for a memory refusal)."""
    sizes = [p for p in scene.params if p.unit in ("A", "Ang", "nm", "um", "mm", "m", "cm") or p.kind == "ints"]
    return " ".join(f"{p.name}={scene.given(p, v[p.name])}" for p in sizes if v.get(p.name) is not None)


def _display(p, value):
    from .. import units
    if p.unit and isinstance(value, float):
        return f"{value / units.NAMED[p.unit]:g}{p.unit}"
    if isinstance(value, (tuple, list)):
        return "x".join(str(x) for x in value)
    if isinstance(value, float):
        return f"{value:g}"
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
        Param("max_wall", 24.0, "hours: a run estimated to take longer (particle-steps at a conservative "
              "rate) is refused before it starts", low=0.0, low_open=True, restart=True),
    ]
    own = {p.name for p in params}
    return list(params) + [p for p in common if p.name not in own]


__all__ = ["Stage", "Setup", "SceneDef", "check_out", "scene_params", "CHECKPOINT", "LIVE"]
