"""Pieces shared by the studies: parameters (with lists), running scenes, tables, files."""

import atexit
import contextlib
import csv
import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np

from .. import units
from ..errors import InputError
from ..scenes.base import _NUM, Param, _jsonable


class ListParam(Param):
    """A comma-separated list of numbers in ``unit`` (``"0.5,1,2km/s"`` or ``"500m/s,1km/s"``).

    A unit written after the last number applies to every bare number.
    ``parse`` returns a tuple of values in the *display* unit (km/s, um, ...),
    or ``None`` for ``none``/``off`` when ``optional``.
    """

    def __init__(self, name, default, doc, unit=None, low=None, high=None, low_open=False, optional=False):
        super().__init__(name, default, doc, unit=unit, kind="floats", low=low, high=high,
                         low_open=low_open, optional=optional)

    def describe(self):
        d = "none" if self.default is None else ",".join(f"{x:g}" for x in self.default)
        return f"{self.name} = {d}{' ' + self.unit if self.unit and self.default is not None else ''}  -- {self.doc}"

    def parse(self, value):
        if value is None or (isinstance(value, str) and value.strip().lower() in ("none", "off", "")):
            if self.optional:
                return None
            raise InputError(self.name, value, f"a comma-separated list of numbers in {self.unit}")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value]
        if isinstance(value, str):
            items = [x.strip() for x in value.split(",")]
            if len(items) > 1 and not all(items):
                raise InputError(self.name, value, f"a comma-separated list of numbers in {self.unit} without "
                                 "empty items")
            items = [x for x in items if x]
            parts = [_NUM.match(x) for x in items]
            tail = parts[-1].group(2) if parts and parts[-1] else ""
            items = [x + tail if (m and not m.group(2) and tail) else x for x, m in zip(items, parts)]
        else:
            items = list(value)
        if not items:
            raise InputError(self.name, value, f"at least one number in {self.unit}")
        single = Param(self.name, None, self.doc, unit=self.unit, low=self.low, high=self.high,
                       low_open=self.low_open)
        out = []
        for it in items:
            v = single.parse(it)
            out.append(float(f"{v / units.NAMED[self.unit]:.12g}") if self.unit else v)
        if len(set(out)) < len(out):
            raise InputError(self.name, value, "a list without repeated values (each run once)")
        return tuple(out)


def parse_params(params, overrides, forward=None, study="study"):
    """Split ``overrides`` into the study's own values and parameters forwarded to a scene.

    Parameters
    ----------
    params : list of Param
        The study's own parameters.
    overrides : dict
        Text (CLI) or Python values.
    forward : Scene, optional
        Keys that are this scene's parameters are checked by its parser and
        returned as given, to be passed to every run.

    Returns
    -------
    (dict of own values, dict of forwarded overrides)
    """
    own = {p.name: p for p in params}
    vals = {p.name: (p.parse(p.default) if p.default is not None else None) for p in params}
    fwd = {}
    for k, v in (overrides or {}).items():
        if k in own:
            vals[k] = own[k].parse(v)
        elif forward is not None and k in {p.name for p in forward.params}:
            fwd[k] = v
        else:
            allowed = list(own) + ([p.name for p in forward.params] if forward is not None else [])
            raise InputError("--set", k, f"a parameter of study '{study}': " + ", ".join(allowed))
    if forward is not None:
        forward.parse(fwd)          # fail early on a bad forwarded value
    if vals.get("cache") is not None:
        from ..scenes.lifecycle import check_out
        try:
            check_out(vals["cache"])
        except InputError as exc:
            raise InputError("cache", vals["cache"], exc.allowed) from None
    return vals, fwd


def display_value(param, value):
    """A value parsed by ``param`` expressed back in its display unit (for scene overrides)."""
    if value is None:
        return None
    if param.unit and isinstance(value, float):
        return value / units.NAMED[param.unit]
    return value


_HELD_FOLDERS = contextlib.ExitStack()   # the study folders this process holds (their locks go with it)
atexit.register(_HELD_FOLDERS.close)   # released at exit, before the modules are torn down


def out_folder(out, study, tag):
    """``out`` or ``runs/<study>-<tag>`` (created).  The default folder is held by this process for
    the rest of its life (:func:`clusterdyn.scenes.lifecycle.lock_out`: a second process writing it
    is refused in one line); a given ``out`` is held by the caller (``clusterdyn study --out``)."""
    from ..scenes.lifecycle import lock_out
    folder = Path(out) if out is not None else Path("runs") / f"{study}-{tag}"
    folder.mkdir(parents=True, exist_ok=True)
    if out is None:
        _HELD_FOLDERS.enter_context(lock_out(folder))
    return folder


def progress_bar(total, desc, enabled):
    if not enabled:
        return None
    from tqdm.auto import tqdm
    return tqdm(total=total, desc=desc, unit="run", dynamic_ncols=True)


def fmt(v, f):
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):
            return "-"
        return format(v, f)
    return str(v)


def format_table(rows, columns, title=None):
    """Fixed-width text table.  ``columns``: list of (key, header, format spec)."""
    cells = [[h for _, h, _ in columns]]
    for r in rows:
        cells.append([fmt(r.get(k), f) for k, _, f in columns])
    widths = [max(len(c[i]) for c in cells) for i in range(len(columns))]
    lines = []
    if title:
        lines.append(title)
    for n, c in enumerate(cells):
        lines.append("  ".join(x.rjust(w) for x, w in zip(c, widths)))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(rows, columns):
    """The same table in Markdown (for docs)."""
    head = "| " + " | ".join(h for _, h, _ in columns) + " |"
    sep = "|" + "|".join("---:" for _ in columns) + "|"
    body = ["| " + " | ".join(fmt(r.get(k), f) for k, _, f in columns) + " |" for r in rows]
    return "\n".join([head, sep] + body)


def write_csv(path, rows, columns=None):
    """Rows (dicts) as CSV; ``columns`` (keys) default to every key in order of appearance."""
    if columns is None:
        columns = []
        for r in rows:
            for k in r:
                if k not in columns:
                    columns.append(k)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([_csv(r.get(k)) for k in columns])
    return path


def _csv(v):
    if v is None:
        return ""
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return "" if not math.isfinite(v) else f"{float(v):.6g}"
    if isinstance(v, (list, tuple)):
        return " ".join(str(_csv(x)) for x in v)
    return v


def write_json(path, data):
    tmp = Path(str(path) + ".tmp")
    tmp.write_text(json.dumps(_jsonable(data), indent=2))
    tmp.replace(path)
    return path


def load_result(path):
    """A :class:`~clusterdyn.scenes.base.SceneResult` back from its JSON file."""
    from ..scenes.base import Quantity, SceneResult
    d = json.loads(Path(path).read_text())
    q = {}
    skip = {"scene", "wall_time_s", "params", "files", "notes", "extra"}
    for k, x in d.items():
        if k in skip or not isinstance(x, dict) or "value" not in x:
            continue
        val = x["value"] if x["value"] is not None else float("nan")
        q[k] = Quantity(val, x.get("unit", ""), x.get("reference"), x.get("rel_error"), x.get("spread"),
                        x.get("note", ""))
    res = SceneResult(d["scene"], q, d["wall_time_s"], params=d.get("params", {}), files=d.get("files", []),
                      notes=d.get("notes", []), extra=d.get("extra", {}), steady=d.get("steady"),
                      warnings=d.get("warnings", []))
    return res


def run_key(scene, params):
    """The parameters of a run that differ from the scene's defaults (display units, JSON-ready).

    Runs are identified by these, so a parameter added to a scene later (at
    its default) leaves earlier runs valid.
    """
    defaults = _jsonable(scene.display(scene.defaults()))
    return {k: x for k, x in _jsonable(params).items() if k not in defaults or defaults[k] != x}


def run_folder(cache, scene, overrides):
    """``cache/<scene>-<12 hex digits>``: one folder per parameter set (hash of :func:`run_key`)."""
    from ..scenes.base import display_text
    key = run_key(scene, scene.display(scene.parse(display_text(scene, overrides))))
    h = hashlib.sha1(json.dumps(key, sort_keys=True).encode()).hexdigest()[:12]
    return Path(cache) / f"{scene.name}-{h}"


def run_scene(scene, overrides, progress=False, desc=None, folder=None, reuse=True, cache=None):
    """Run a scene once; returns (SceneResult or None, error text or None, wall time s).

    An :class:`~clusterdyn.errors.InstabilityError` is caught and returned as
    text: a study records the failed run and goes on.  With ``folder`` (or
    ``cache``: the folder is then :func:`run_folder`) the result (or the
    error) is written there as JSON, and with ``reuse`` a run whose folder
    already holds the result of the same parameters is read back instead of
    run again: a study interrupted or extended resumes where it was, and
    studies sharing a cache share their runs.
    """
    from ..errors import InstabilityError
    from ..scenes.base import display_text
    overrides = display_text(scene, overrides)      # a study's numbers are in display units
    params = _jsonable(scene.display(scene.parse(overrides)))
    if folder is None and cache is not None:
        folder = run_folder(cache, scene, overrides)
    if folder is not None and reuse:
        folder = Path(folder)
        for name in ("result.json", "error.json"):
            f = folder / name
            if f.exists():
                try:
                    d = json.loads(f.read_text())
                except ValueError:
                    continue
                if run_key(scene, d.get("params") or {}) == run_key(scene, params):
                    if name == "error.json":
                        return None, d["error"], d["wall_time_s"]
                    return load_result(f), None, d["wall_time_s"]
    t0 = time.perf_counter()
    try:
        res = scene.run(overrides, out=None, progress=progress)
    except InstabilityError as exc:
        wall = time.perf_counter() - t0
        if folder is not None:
            Path(folder).mkdir(parents=True, exist_ok=True)
            for old in ("result.json",):
                if (Path(folder) / old).exists():
                    (Path(folder) / old).unlink()
            write_json(Path(folder) / "error.json", {"params": params, "error": f"InstabilityError: {exc}",
                                                     "wall_time_s": wall})
        return None, f"InstabilityError: {exc}", wall
    if folder is not None:
        if (Path(folder) / "error.json").exists():
            (Path(folder) / "error.json").unlink()
        res.write(folder, "result.json")
    return res, None, time.perf_counter() - t0


ROW_KEYS = ("D", "D_err", "D_ref", "err_ref", "u", "u_dev", "D_mass", "mass_check", "rho", "P", "P_momentum",
            "momentum_check", "sigma_u", "fit_rms_slabs", "D_half1", "D_half2", "n_particles", "n_steps",
            "particle_steps", "stepping_s", "ejecta")


def shock_row(res, err=None, wall=None):
    """One table row (plain floats in km/s, GPa, g/cm3) from a shock SceneResult."""
    if res is None:
        row = {k: float("nan") for k in ROW_KEYS}
        row.update({"error": err, "wall_s": wall, "steady": False, "why_unsteady": err})
        return row
    q, x = res.quantities, res.extra

    def val(k):
        return q[k].value if k in q else float("nan")
    row = {
        "u_piston": res.params["u"]["value"] if isinstance(res.params.get("u"), dict) else None,
        "D": val("D"), "D_err": q["D"].spread, "D_ref": q["D"].reference,
        "err_ref": q["D"].rel_error, "u": val("u"), "u_dev": q["u"].rel_error,
        "D_mass": val("D_mass"), "mass_check": x.get("mass_check"),
        "rho": val("rho"), "P": val("P"), "P_momentum": val("P_momentum"),
        "momentum_check": x.get("momentum_check"), "sigma_u": val("sigma_u"),
        "fit_rms_slabs": x.get("fit_rms_slabs"),
        "D_half1": x.get("D_halves_km_s", [None, None])[0], "D_half2": x.get("D_halves_km_s", [None, None])[1],
        "steady": x.get("steady"), "why_unsteady": "; ".join(x.get("steady_reasons", [])),
        "n_particles": x.get("n_particles"), "n_steps": x.get("n_steps"),
        "particle_steps": x.get("particle_steps"), "wall_s": res.wall_time_s if wall is None else wall,
        "stepping_s": x.get("stepping_time_s"), "ejecta": x.get("ejecta_fraction"), "error": None,
    }
    return row


def pareto_front(cost, err):
    """Indices of the runs not beaten in both cost and ``|err|`` by another run, by cost."""
    cost = np.asarray(cost, float)
    err = np.abs(np.asarray(err, float))
    ok = np.isfinite(cost) & np.isfinite(err)
    idx = [i for i in np.argsort(cost) if ok[i]]
    front, best = [], math.inf
    for i in idx:
        if err[i] < best:
            front.append(int(i))
            best = err[i]
    return front



class StudyPoint:
    """A study's unit of work that is one function call rather than a scene's dynamics run.

    It declares its parameters like a scene (``params``: list of Param) and is
    cached by :func:`run_scene` like one: ``parse``, ``defaults``, ``display``
    are the scene lifecycle's; ``run(overrides, out=None, progress=False)``
    calls ``runner(values, out, progress)``, which returns a SceneResult.
    """

    def __init__(self, name, description, params, runner):
        from ..scenes.lifecycle import SceneDef
        self.name, self.description, self.params, self.runner = name, description, list(params), runner
        self._def = SceneDef()
        self._def.name, self._def.params = name, self.params

    def defaults(self):
        return self._def.defaults()

    def parse(self, overrides):
        from ..scenes.base import display_text
        return self._def.parse(display_text(self._def, overrides))

    def display(self, vals):
        return self._def.display(vals)

    def run(self, overrides=None, out=None, progress=False):
        vals = self.parse(overrides)
        t0 = time.perf_counter()
        res = self.runner(vals, out=Path(out) if out else None, progress=progress)
        if res.wall_time_s is None:
            res.wall_time_s = time.perf_counter() - t0
        res.params = self.display(vals)
        if out is not None:
            res.files.append(res.write(out))
        return res
