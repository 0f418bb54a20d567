"""Property-based tests (hypothesis) of the parameter parser and of the scenes' checks.

For any text given to any declared parameter of any scene or study:

* the parser returns a value or refuses with one InputError; never another exception;
* a value it returns is the one written: a number with the parameter's unit (or none, or another
  unit of the same dimension) comes back equal to it, inside the declared range; nothing is clipped;
* the scene's checks before any work (cluster size, the scene's own check, the memory estimate)
  pass or refuse with InputError, for any combination of up to three parameters;
* ``result.json`` never holds a NaN or an infinity, whatever a run measured.

Settings: derandomized (the same examples every run, so the suite is reproducible), no deadline;
400 examples for the parser, 400 for the scene checks, 150 for result.json: about 10 s in all.
"""

import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.scenes import all_scenes
from clusterdyn.scenes.base import Quantity, SceneResult, _family
from clusterdyn.studies import study_names, study_params

SCENES = all_scenes()
SCENE_PARAMS = [(name, p) for name, sc in sorted(SCENES.items()) for p in sc.params]
STUDY_PARAMS = [(name, p) for name in study_names() for p in study_params(name)]
ALL_PARAMS = SCENE_PARAMS + STUDY_PARAMS

SETTINGS = dict(derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e4, max_value=1e4),
    st.integers(min_value=-10**25, max_value=10**25),
    st.sampled_from([0, 1, 2, 3, 5, 10, 100, 1e-30, 1e-9, 0.5, 1e6, 1e9, 1e20, 2**63, -1, 1e308, 5e-324]),
)
unit_names = st.sampled_from(["", "um", "mm", "m", "nm", "A", "km/s", "m/s", "GPa", "MPa", "us", "ns", "ps",
                              "g/cm3", "eV", "furlong", " um", "%"])
junk = st.one_of(st.text(max_size=10), st.sampled_from(["none", "off", "auto", "", " ", "nan", "inf", "-inf",
                                                         "1,,2", "1,1", "4x4x40", "0x0x0", "1e400", "true",
                                                         "yes", "1e20x1x1", "x", ",", "1;2"]))


def _text(p, data):
    if p.kind == "ints":
        n = len(p.default) if isinstance(p.default, (tuple, list)) else 3
        parts = data.draw(st.lists(st.integers(-5, 10**12), min_size=max(0, n - 1), max_size=n + 1))
        return data.draw(st.sampled_from(["x", ","])).join(map(str, parts))
    if p.kind in ("choice", "str") and p.choices:
        return data.draw(st.one_of(st.sampled_from([str(c) for c in p.choices]), junk))
    if p.kind == "bool":
        return data.draw(st.one_of(st.sampled_from(["true", "false", "1", "0", "yes", "no"]), junk))
    if p.kind == "floats":                     # a study's list
        xs = data.draw(st.lists(numbers, min_size=0, max_size=4))
        return ",".join(repr(x) for x in xs) + data.draw(unit_names)
    return data.draw(st.one_of(st.builds(lambda x, u: f"{x!r}{u}", numbers, unit_names), junk))


def _plain_number(text):
    """The number of ``text`` and its unit when it is a plain number (as the parser reads it)."""
    from clusterdyn.scenes.base import _NUM
    m = _NUM.match(text)
    if not m:
        return None, None
    return float(m.group(1)), m.group(2)


@settings(max_examples=400, **SETTINGS)
@given(st.data())
def test_the_parser_returns_what_was_written_or_refuses(data):
    name, p = data.draw(st.sampled_from(ALL_PARAMS), label="parameter")
    text = _text(p, data)
    try:
        val = p.parse(text)
    except InputError as exc:
        assert str(exc).count("\n") == 0 and p.name in str(exc)
        return
    if val is None:
        assert p.optional
        return
    if p.kind in ("float", "int") and not p.choices:
        num, unit = _plain_number(text)
        if num is None:
            return                               # e.g. "auto" of a parameter that takes it
        assert math.isfinite(num)
        if p.kind == "int":
            assert val == int(num) and not unit
            disp = val
        elif p.unit is None:
            assert val == num and not unit
            disp = val
        else:
            u = unit or p.unit
            assert _family(u) == _family(p.unit)
            assert math.isclose(val / units.NAMED[u], num, rel_tol=1e-12, abs_tol=0.0) or (num == 0 and val == 0)
            disp = val / units.NAMED[p.unit]
        if p.low is not None:
            assert disp > p.low if p.low_open else disp >= p.low * (1 - 1e-12)
        if p.high is not None:
            assert disp <= p.high * (1 + 1e-12)
    if p.kind == "floats":
        items = [x for x in text.split(",")]
        assert len(val) == len(items) and len(set(val)) == len(val)
        for x in val:
            assert math.isfinite(x)
    if p.choices:
        assert str(val) in [str(c) for c in p.choices]


@settings(max_examples=400, **SETTINGS)
@given(st.data())
def test_scene_checks_pass_or_refuse_in_one_line(data):
    name = data.draw(st.sampled_from(sorted(SCENES)), label="scene")
    sc = SCENES[name]
    chosen = data.draw(st.lists(st.sampled_from(list(sc.params)), min_size=1, max_size=3,
                                unique_by=lambda p: p.name), label="parameters")
    overrides = {p.name: _text(p, data) for p in chosen}
    try:
        v = sc.parse(overrides)
        sc._check_sizes(v)
        sc.check(v)
        sc._check_memory(v)
    except InputError as exc:
        assert str(exc).count("\n") == 0
        return
    # accepted: every value given is recorded as parsed (display units), nothing moved
    shown = sc.display(v)
    for p in chosen:
        if v[p.name] is not None and p.unit and isinstance(v[p.name], float):
            assert shown[p.name]["value"] * units.NAMED[p.unit] == pytest.approx(v[p.name], rel=1e-12)


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.none())


@settings(max_examples=150, **SETTINGS)
@given(st.dictionaries(st.text(min_size=1, max_size=6), st.tuples(finite_or_not, finite_or_not, finite_or_not),
                       max_size=4),
       st.dictionaries(st.text(min_size=1, max_size=6), st.one_of(finite_or_not, st.lists(finite_or_not, max_size=3)),
                       max_size=3))
def test_result_json_never_holds_nan(qs, extra):
    import numpy as np
    quantities = {k: Quantity(a if a is not None else 0.0, "km/s", reference=b, spread=c)
                  for k, (a, b, c) in qs.items()}
    extra = {k: (np.float32(x) if isinstance(x, float) and not abs(x) < math.inf or (isinstance(x, float)
                                                                                  and abs(x) < 1e38) else x)
             for k, x in extra.items()}
    res = SceneResult("shock", quantities, float("nan"), params={"u": float("inf")}, extra=extra)
    text = res.to_json()

    def refuse(c):
        raise AssertionError(f"{c} in result.json")

    json.loads(text, parse_constant=refuse)
