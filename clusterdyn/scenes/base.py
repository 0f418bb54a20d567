"""Scene framework: parameters with units, result records, the registry.

A scene is a ready experiment: a :class:`~clusterdyn.scenes.lifecycle.SceneDef`
registered with :func:`register_scene`.  It declares its parameters (name,
default, unit, allowed range), builds only the physics it needs, runs through
the one lifecycle, and returns a :class:`SceneResult`: measured quantities
with units, each next to its reference and relative error, plus the wall
time.  The CLI prints it and writes it as JSON beside the H5MD file.
"""

import dataclasses
import importlib
import json
import math
import numbers
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import units
from ..errors import InputError

#: largest integer parameter (int64: seeds, counts)
_INT_MAX = 2 ** 63 - 1024
_NUM = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


@dataclass
class Param:
    """One scene parameter.

    ``unit`` is the label users write and read (``"km/s"``, ``"um"``); the
    value handed to the scene is in ASE units.  ``kind`` is float, int, str,
    bool, choice or ints (a tuple like ``4x4x40``).
    """

    name: str
    default: object
    doc: str
    unit: str = None
    kind: str = "float"
    choices: tuple = None
    low: float = None          # inclusive bounds on the value in `unit`
    high: float = None
    low_open: bool = False     # exclude `low` itself
    optional: bool = False     # None allowed ("none"/"off")
    restart: bool = False      # a --set on --restart may change it (run length, output cadence)

    def describe(self):
        d = self.default
        if self.unit and isinstance(d, (int, float)) and d is not None:
            dtxt = f"{d:g} {self.unit}"
        else:
            dtxt = "none" if d is None else str(d)
        rng = ""
        if self.choices:
            rng = " one of: " + ", ".join(map(str, self.choices))
        elif self.low is not None or self.high is not None:
            lo = "" if self.low is None else ("(" if self.low_open else "[") + f"{self.low:g}"
            hi = "" if self.high is None else f"{self.high:g}]"
            rng = f" range {lo or '(-inf'}, {hi or 'inf)'}"
        tag = "  [may change on --restart]" if self.restart else ""
        return f"{self.name} = {dtxt}  -- {self.doc}{rng}{tag}"

    def _check_range(self, v, text):
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            raise InputError(self.name, text, self._allowed())
        if self.high is not None and v > self.high:
            raise InputError(self.name, text, self._allowed())

    def _allowed(self):
        u = f" {self.unit}" if self.unit else ""
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices))
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        lb = "(" if (self.low is None or self.low_open) else "["
        base = {"int": "an integer", "ints": "integers like 4x4x40"}.get(self.kind, "a number")
        if self.kind == "int" and self.high is None:
            hi = f"{_INT_MAX:.3g}"
        if self.low is None and self.high is None and self.kind != "int":
            return f"a finite number{u}" + (" or none" if self.optional else "")
        rb = ")" if hi == "inf" else "]"
        return f"{base} in {lb}{lo}, {hi}{rb}{u}" + (" or none" if self.optional else "")

    def takes_ase_number(self, value):
        """True when ``value`` is a bare Python number for a parameter with a unit: from Python it is
        read in ASE units (:meth:`parse_ase`), as builders and calculators take it."""
        return (self.unit is not None and self.kind == "float" and type(self).parse is Param.parse
                and isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)))

    def parse_ase(self, value):
        """A bare number in ASE units (``5 * units.um``), checked against the range in the display unit;
        returned as given (a float)."""
        num = float(value)
        disp = num / units.NAMED[self.unit]
        shown = f"{num:g} (ASE units: {disp:g} {self.unit})"
        if not math.isfinite(num):
            raise InputError(self.name, shown, self._allowed())
        self._check_range(disp, shown)
        return num

    def parse(self, value):
        """Parse text (CLI) or a value; return the value in ASE units.

        A bare number is read in the parameter's display unit (as the defaults and the CLI
        write it); a scene's :meth:`~clusterdyn.scenes.lifecycle.SceneDef.parse` reads bare
        Python numbers in ASE units instead (:meth:`parse_ase`)."""
        text = value
        if value is None or (isinstance(value, str) and value.strip().lower() in ("none", "off")):
            if self.optional:
                return None
            raise InputError(self.name, value, self._allowed())
        if self.kind == "bool":
            if isinstance(value, bool):
                return value
            s = str(value).strip().lower()
            if s in ("1", "true", "yes", "on"):
                return True
            if s in ("0", "false", "no"):
                return False
            raise InputError(self.name, value, "true or false")
        if self.kind in ("str", "choice"):
            s = str(value)
            if self.choices and s not in [str(c) for c in self.choices]:
                raise InputError(self.name, value, self._allowed())
            return s
        if self.kind == "ints":
            if isinstance(value, str):
                parts = re.split(r"[x,\s]+", value.strip())
            else:
                parts = list(value) if hasattr(value, "__iter__") else [value]
            try:
                vals = tuple(int(p) for p in parts if p != "")
            except ValueError:
                raise InputError(self.name, value, self._allowed()) from None
            if len(vals) != len(self.default) or any(v < (self.low or 1) for v in vals):
                raise InputError(self.name, value, f"{len(self.default)} integers >= {self.low or 1}"
                                 f" like {'x'.join(map(str, self.default))}")
            return vals
        # numbers with optional unit
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            num, unit_txt = float(value), ""
            # a bare Python number is taken in the parameter's own unit
        else:
            m = _NUM.match(str(value))
            if not m:
                raise InputError(self.name, value, self._allowed())
            num, unit_txt = float(m.group(1)), m.group(2)
        if not math.isfinite(num):
            raise InputError(self.name, value, self._allowed())
        if self.kind == "int":
            if unit_txt or num != int(num) or abs(num) > _INT_MAX:
                raise InputError(self.name, value, self._allowed())
            self._check_range(num, text)
            return int(num)
        if self.unit is None:
            if unit_txt:
                raise InputError(self.name, value, "a plain number (no unit)")
            self._check_range(num, text)
            return num
        # convert to the parameter's display unit for the range check
        if unit_txt:
            if unit_txt not in units.NAMED:
                raise InputError(self.name, value, f"a number with a unit like {self.unit} "
                                 f"(known units: {', '.join(units.NAMED)})")
            ase_val = num * units.NAMED[unit_txt]
            disp = ase_val / units.NAMED[self.unit]
            # dimension check: converting between incompatible units gives absurd ratios;
            # compare against the known family of the parameter's unit
            if _family(unit_txt) != _family(self.unit):
                raise InputError(self.name, value, f"a value in units of {self.unit} "
                                 f"(same dimension: {', '.join(_same(self.unit))})")
        else:
            disp = num
            ase_val = num * units.NAMED[self.unit]
        self._check_range(disp, text)
        if not math.isfinite(ase_val) or not math.isfinite(disp) or (ase_val == 0) != (num == 0):
            raise InputError(self.name, value, self._allowed(), hint="out of the range a float can hold in "
                             "clusterdyn's units")
        return ase_val


class SceneValues(Mapping):
    """Base of a scene's parameter values: a frozen dataclass with one field per declared
    :class:`Param` (ASE units), made by :func:`values_class`.

    Read a value as an attribute (``v.r0``); the values are also a read-only mapping
    (``v["r0"]``, ``v.get``, ``**v``, ``v.items()``) over the declared parameters.  A changed
    copy is ``v.replace(dt_factor=...)``.  ``retried`` holds one line per attempt the
    lifecycle started again after an instability (:meth:`SceneDef.retry`), oldest first.
    """

    def __getitem__(self, key):
        if key in self._names:
            return getattr(self, key)
        raise KeyError(key)

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def replace(self, **changes):
        """A copy with ``changes`` (parameter names or ``retried``)."""
        return dataclasses.replace(self, **changes)

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self.items())})"


def display_text(scene, overrides):
    """``overrides`` with every bare number of a parameter that has a unit written as text in that unit
    (``{"r0": 5.0}`` -> ``{"r0": "5.0um"}``): for callers whose numbers are in the display units the
    CLI and ``clusterdyn list`` use, since :meth:`SceneDef.parse` reads bare Python numbers in ASE
    units.  Exact: the text is the number's ``repr``."""
    known = {p.name: p for p in scene.params}
    out = {}
    for k, x in (overrides or {}).items():
        p = known.get(k)
        out[k] = f"{float(x)!r}{p.unit}" if p is not None and p.takes_ase_number(x) else x
    return out


def values_class(name, params):
    """The frozen dataclass of a scene's parameter values (a :class:`SceneValues`): one field per
    :class:`Param` of ``params``, in order, plus ``retried``."""
    names = tuple(p.name for p in params)
    cls_name = "".join(w.capitalize() for w in re.split(r"[^0-9a-zA-Z]+", name) if w) + "Values"
    fields = [(n, object) for n in names] + [("retried", tuple, field(default=()))]
    cls = dataclasses.make_dataclass(cls_name, fields, bases=(SceneValues,), frozen=True, eq=True)
    cls._names = names
    cls.__module__ = __name__
    return cls


_FAMILIES = {
    "length": ("A", "Ang", "nm", "um", "mm", "m", "cm"),
    "time": ("fs", "ps", "ns", "us", "ms", "s"),
    "velocity": ("m/s", "km/s", "mm/us", "um/ns"),
    "density": ("g/cm3", "kg/m3"),
    "pressure": ("GPa", "MPa", "Pa"),
    "energy": ("eV", "J"),
    "force": ("N",),
    "mass": ("kg", "g", "amu"),
}


def _family(u):
    for k, v in _FAMILIES.items():
        if u in v:
            return k
    return u


def _same(u):
    return _FAMILIES.get(_family(u), (u,))


@dataclass
class Quantity:
    """A measured quantity in a display unit, with its reference and relative error."""

    value: float
    unit: str = ""
    reference: float = None
    rel_error: float = None
    spread: float = None
    note: str = ""

    def __post_init__(self):
        if self.reference is not None and self.rel_error is None and self.reference != 0:
            self.rel_error = (self.value - self.reference) / abs(self.reference)

    def as_dict(self):
        d = {"value": _clean(self.value), "unit": self.unit}
        if self.reference is not None:
            d["reference"] = _clean(self.reference)
            d["rel_error"] = _clean(self.rel_error)
        if self.spread is not None:
            d["spread"] = _clean(self.spread)
        if self.note:
            d["note"] = self.note
        return d


def _clean(v):
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return v
    return f if math.isfinite(f) else None


@dataclass
class SceneResult:
    """What a scene returns: quantities (with units, references, errors) and wall time.

    ``data`` is what the scene's analysis kept for its report (not written).
    ``steady`` is the scene's verdict on whether what it measured had settled
    (None: the scene makes no such check); ``warnings`` are one-line messages
    the CLI prints on stderr (e.g. why a run is not steady and what would fix it).
    """

    scene: str
    quantities: dict
    wall_time_s: float
    params: dict = field(default_factory=dict)
    files: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    steady: bool = None
    warnings: list = field(default_factory=list)
    #: what the scene's analysis kept for its report (in memory only, not in the JSON)
    data: object = field(default=None, repr=False, compare=False)

    def as_dict(self):
        d = {"scene": self.scene}
        for k, q in self.quantities.items():
            d[k] = q.as_dict()
        if self.steady is not None:
            d["steady"] = bool(self.steady)
        if self.warnings:
            d["warnings"] = list(self.warnings)
        d["wall_time_s"] = _clean(round(self.wall_time_s, 4)) if math.isfinite(self.wall_time_s) else None
        d["params"] = {k: _jsonable(v) for k, v in self.params.items()}
        d["files"] = [str(f) for f in self.files]
        if self.notes:
            d["notes"] = list(self.notes)
        if self.extra:
            d["extra"] = {k: _jsonable(v) for k, v in self.extra.items()}
        return d

    def to_json(self, **kw):
        return json.dumps(self.as_dict(), **kw)

    def table(self):
        """Human summary: quantity, value, unit, reference, error."""
        lines = [f"{'quantity':<22}{'value':>14} {'unit':<8}{'reference':>14}{'rel. error':>12}"]
        for k, q in self.quantities.items():
            ref = "" if q.reference is None else f"{q.reference:14.6g}"
            err = "" if q.rel_error is None else f"{100 * q.rel_error:+11.2f}%"
            sp = "" if q.spread is None else f"  (+- {q.spread:.3g})"
            lines.append(f"{k:<22}{q.value:14.6g} {q.unit:<8}{ref:>14}{err:>12}{sp}")
        lines.append(f"{'wall time':<22}{self.wall_time_s:14.3f} s")
        if self.steady is not None:
            lines.append(f"{'steady':<22}{'yes' if self.steady else 'NO':>14}")
        for n in self.notes:
            lines.append(f"note: {n}")
        return "\n".join(lines)

    def write(self, folder, name="result.json"):
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / name
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(self.to_json(indent=2))
        tmp.replace(path)
        return path


def _jsonable(v):
    if isinstance(v, (str, int, bool)) or v is None:
        return v
    if isinstance(v, float):
        return _clean(v)
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    try:
        return _clean(float(v))          # numpy scalars: a NaN becomes null, as for floats
    except (TypeError, ValueError):
        return str(v)


SCENES = {}


def register_scene(scene):
    """Register a :class:`~clusterdyn.scenes.lifecycle.SceneDef` instance under its name."""
    SCENES[scene.name] = scene
    return scene


#: scene modules, imported on first use (each adds its scenes to SCENES)
SCENE_MODULES = ["shock", "plate_impact", "polycrystal_shock", "mca", "dusting", "spall", "taylor", "hypervelocity", "multilayer",
                 "ejecta", "jets", "mca_friction"]


def all_scenes():
    """Every registered scene (imports the scene modules on first use)."""
    for m in SCENE_MODULES:
        importlib.import_module(f"{__package__}.{m}")
    return SCENES


def get_scene(name):
    all_scenes()
    if name not in SCENES:
        raise InputError("scene", name, "one of " + ", ".join(sorted(SCENES)))
    return SCENES[name]
