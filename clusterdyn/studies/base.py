"""The one lifecycle of a study, and the registry of studies.

A study is a :class:`Study` subclass whose instance is registered with :func:`register_study`
(``clusterdyn study NAME`` finds it by ``name``).  Calling it runs the lifecycle:

1. **parse** -- the study's own parameters (``params``) and, when ``scene`` names one, the
   parameters forwarded to every run of that scene
   (:func:`~clusterdyn.studies.common.parse_params`); then ``prepare`` makes the checks the
   parameters cannot make alone.  Bad input stops here, before any work or folder;
2. **plan** -- ``plan(run)``: the list of scene runs or calls;
3. **collect** -- ``collect(run, plan)`` runs them; scene runs go through the cache
   (:meth:`StudyRun.run_scene`: ``OUT/runs`` or the ``cache`` parameter, read back when
   ``reuse``), so an interrupted or extended study only runs what is missing;
4. **report** -- ``report(run, collected)`` returns a :class:`Report`: the JSON-ready result, the
   text to print and the files it wrote;
5. **finish** (the base, the same for every study) -- the wall time, the JSON file
   ``json_name``, ``result["files"]``, and the text printed unless ``quiet``.

A study's folder is ``OUT`` (``--out``) or ``runs/<name>-<tag(run)>``.
"""

import importlib
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from .common import out_folder, parse_params, progress_bar, run_scene, write_json

#: study name -> registered Study instance (in the order of registration)
STUDIES = {}

#: the modules that register studies, imported on first use (in the order ``clusterdyn study`` lists them)
STUDY_MODULES = ["hugoniot", "convergence", "stability", "mca", "mca_flow", "mca_taylor", "flow_stress",
                 "calibrate", "dusting"]


def register_study(study):
    """Register a :class:`Study` instance under its ``name``; returns it."""
    STUDIES[study.name] = study
    return study


def all_studies():
    """Every registered study (imports the study modules on first use), in the order of
    :data:`STUDY_MODULES` whatever the order the modules were imported in (studies registered
    from elsewhere come last)."""
    for m in STUDY_MODULES:
        importlib.import_module(f"{__package__}.{m}")
    modules = [f"{__package__}.{m}" for m in STUDY_MODULES]
    order = list(STUDIES)

    def rank(name):
        mod = type(STUDIES[name]).__module__
        return (modules.index(mod) if mod in modules else len(modules), order.index(name))
    return {name: STUDIES[name] for name in sorted(STUDIES, key=rank)}


def get_study(name):
    """The study registered as ``name`` (callable: ``study(overrides, out=None, progress=True, quiet=None)``)."""
    studies = all_studies()
    if name not in studies:
        raise InputError("study", name, "one of " + ", ".join(studies))
    return studies[name]


@dataclass
class Report:
    """What a study's ``report`` step returns: the JSON-ready ``result``, the ``text`` blocks to
    print (joined by blank lines) and the ``files`` written (the JSON file is added by the base)."""

    result: dict
    text: list = field(default_factory=list)
    files: list = field(default_factory=list)


class StudyRun:
    """One call of a study: its parsed values ``v``, the forwarded scene overrides ``fwd``, the
    folder, and the cache its scene runs go through.  A study's steps keep what they share on it
    (``prepare`` sets what ``plan``, ``collect`` and ``report`` read, e.g. the parsed scene values)."""

    def __init__(self, study, v, fwd, progress, quiet):
        self.study, self.v, self.fwd = study, v, fwd
        self.progress, self.quiet = progress, quiet
        self.t_start = time.perf_counter()
        self.folder = None

    @property
    def cache(self):
        """The folder of the runs' results: the ``cache`` parameter, or ``OUT/runs``."""
        given = self.v.get("cache")
        return Path(given) if given else self.folder / "runs"

    def run_scene(self, scene, overrides, progress=None):
        """One run through the cache (:func:`~clusterdyn.studies.common.run_scene`):
        (SceneResult or None, error text or None, wall time s)."""
        return run_scene(scene, overrides, progress=self.progress if progress is None else progress,
                         cache=self.cache, reuse=self.v.get("reuse", True))

    def bar(self, total, desc):
        """A tqdm bar over runs, or None without ``progress``."""
        return progress_bar(total, desc, self.progress)


class Study:
    """Base of every study: subclasses set the class attributes and the steps they need.

    Attributes
    ----------
    name : str
        The CLI name (``clusterdyn study NAME``).
    summary : str
        One line for ``clusterdyn study`` and ``clusterdyn list``.
    params : list of Param
        The study's own parameters.
    scene : str or None
        A scene whose parameters are forwarded to every run (checked by its parser).
    json_name : str or None
        The JSON file the base writes in the folder (None: none).
    """

    name = None
    summary = ""
    params = []
    scene = None
    json_name = None

    # ---- the steps a study fills in
    def tag(self, run):
        """The default folder's suffix: ``runs/<name>-<tag>``."""
        return ""

    def prepare(self, run):
        """Checks beyond the parameters' own (InputError), before any work; may complete ``run.v``."""

    def plan(self, run):
        """The runs (scene overrides or calls) of the study."""
        return None

    def collect(self, run, plan):
        """Run the plan; returns what ``report`` needs."""
        raise NotImplementedError

    def report(self, run, collected):
        """Tables, figures and the result: a :class:`Report`."""
        raise NotImplementedError

    # ---- the lifecycle
    def __call__(self, overrides=None, out=None, progress=True, quiet=None):
        """Run the study; returns its JSON-ready result (every run listed, ``files``, ``wall_time_s``)."""
        quiet = (not progress) if quiet is None else quiet
        forward = None
        if self.scene is not None:
            from ..scenes import get_scene
            forward = get_scene(self.scene)
        v, fwd = parse_params(self.params, overrides, forward=forward, study=self.name)
        run = StudyRun(self, v, fwd, progress, quiet)
        self.prepare(run)
        plan = self.plan(run)
        run.folder = out_folder(out, self.name, self.tag(run))
        collected = self.collect(run, plan)
        return self.finish(run, self.report(run, collected))

    def finish(self, run, rep):
        """The tail every study shares: wall time, the JSON file, the file list, the printed text."""
        result = rep.result
        result["wall_time_s"] = time.perf_counter() - run.t_start
        files = list(rep.files)
        if self.json_name is not None:
            files.append(write_json(run.folder / self.json_name, result))
        result["files"] = [str(f) for f in files]
        text = list(rep.text)
        if files:
            text.append("wrote " + ", ".join(str(f) for f in files))
        if not run.quiet and text:
            print("\n\n".join(text))
        return result
