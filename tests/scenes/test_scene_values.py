"""A scene's parameters from Python: a frozen dataclass of ASE values; bare Python numbers in ASE units;
the encodable set-up a checkpoint carries (#41 item 4, #46 item 7)."""
import dataclasses

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.scenes import get_scene
from clusterdyn.scenes.base import SceneValues, display_text


def test_bare_python_numbers_are_ase_units_and_text_is_read_as_on_the_cli():
    sc = get_scene("shock")
    v = sc.parse({"r0": 5 * units.um, "u": 3 * units.km_s})
    assert v.r0 == 5 * units.um and v.u == 3 * units.km_s          # as given, to the bit
    assert sc.parse({"r0": "5um"}).r0 == v.r0
    assert sc.parse({"r0": "5"}).r0 == v.r0                         # text: the display unit (um)
    assert sc.parse({"u": "3000m/s"}).u == pytest.approx(v.u, rel=1e-15)
    assert sc.parse({"rc": 1.2}).rc == 1.2                          # no unit: the number itself
    with pytest.raises(InputError, match=r"u='10.18\S* \(ASE units: 100 km/s\)'.*\(0, 10\] km/s"):
        sc.parse({"u": 100 * units.km_s})                           # range checked in the display unit
    with pytest.raises(InputError, match="r0"):
        sc.parse({"r0": -1.0})


def test_display_text_writes_display_numbers_exactly():
    sc = get_scene("shock")
    ov = display_text(sc, {"r0": 5.1, "u": 2.7, "rc": 1.2, "size": "40x4x4", "seed": 3})
    assert ov == {"r0": "5.1um", "u": "2.7km/s", "rc": 1.2, "size": "40x4x4", "seed": 3}
    assert sc.parse(ov).r0 == 5.1 * units.um and sc.parse(ov).u == 2.7 * units.km_s


def test_values_are_a_frozen_dataclass_and_a_read_only_mapping():
    sc = get_scene("taylor")
    v = sc.parse({"V": "373"})
    assert isinstance(v, SceneValues) and dataclasses.is_dataclass(v)
    assert list(v) == [p.name for p in sc.params]
    assert v["V"] == v.V == 373 * units.m_s and v.get("nosuch", 1) == 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.V = 1.0
    w = v.replace(V=2.0, retried=("one",))
    assert (w.V, w.retried, v.V, v.retried) == (2.0, ("one",), 373 * units.m_s, ())
    assert "retried" not in dict(**w)
    assert sc.parse({"V": "373"}) == v


def test_the_shock_setup_is_its_own_checkpoint_payload():
    from clusterdyn.scenes.shock import ShockScene, ShockSetup
    sc = get_scene("shock")
    v = sc.parse({"size": "12x3x3", "fit_from": "0", "inclusion": "none"})
    s = sc.setup(v, "main")
    assert isinstance(s, ShockSetup) and ShockScene.setup_class is ShockSetup
    state = s.state()
    assert "atoms" not in state and "material" not in state and state["size"] == [12, 3, 3]
    back = ShockSetup.restore(s.atoms, s.dyn, state)
    for f in dataclasses.fields(ShockSetup):
        if f.metadata.get("live"):
            continue
        a, b = getattr(s, f.name), getattr(back, f.name)
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, f.name
    assert np.array_equal(back.piston_mask, s.piston_mask) and back.piston is s.piston
    st = sc.attach(v, "main", s)
    assert st.analysis.rest_volume is s.rest_volume                # not computed again
