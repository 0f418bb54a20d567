"""Reports say "not measured" with a reason instead of NaN, energies in J, one range format (#46 item 5)."""
import math
import re

import numpy as np

from clusterdyn import units
from clusterdyn.cli import main
from clusterdyn.scenes.base import Quantity
from clusterdyn.scenes.common import ledger_joules
from clusterdyn.scenes.spall import _crossing, _strengths
from clusterdyn.scenes.taylor import _unmeasured


def test_taylor_leaves_out_what_a_rod_without_an_undeformed_rear_cannot_give():
    def quantities():
        return {"Lf_over_L0": Quantity(0.9), "X_over_L0": Quantity(0.0, "", 0.32), "Y_taylor": Quantity(math.nan)}
    q = quantities()
    notes = _unmeasured(q, {"X": 0.0, "Y": math.nan})
    assert set(q) == {"Lf_over_L0"} and len(notes) == 1 and "X = 0" in notes[0]
    q = quantities()
    assert _unmeasured(q, {"X": 1.0, "Y": math.nan}) and set(q) == {"Lf_over_L0", "X_over_L0"}
    q = quantities()
    assert _unmeasured(q, {"X": 1.0, "Y": 0.4}) == [] and len(q) == 3


def test_spall_names_a_pullback_without_spall_the_tension_held_and_never_prints_nan():
    a = {"sigma_cb": 1.0 * units.GPa, "sigma_cL": 1.2 * units.GPa, "c_b": 5 * units.km_s, "c_L": 6 * units.km_s,
         "rho0": 2.7 * units.g_cm3}
    held = _strengths("pc_", a, False, 1.3, None, 1.0, 1.6)
    assert set(held) == {"pc_tension_held_cb", "pc_tension_held_cL"}
    assert "lower bound" in held["pc_tension_held_cb"].note and held["pc_tension_held_cb"].value == 1.0
    assert set(_strengths("pc_", a, True, 1.3, None, 1.0, 1.6)) == {"pc_spall_strength_cb", "pc_spall_strength_cL"}
    r0 = 10 * units.um
    assert "nan" not in _crossing({"d_expected": math.nan, "t_cross": math.nan}, r0)
    assert "8.44 r0" in _crossing({"d_expected": 8.44 * r0, "t_cross": 30 * units.ns}, r0)


def test_ledgers_are_reported_in_joules():
    led = {"kinetic": 2.0 * units.J, "residual": -1e-3 * units.J, "removed_momentum": np.array([1.0, 0, 0]) * units.N * units.s}
    j = ledger_joules(led)
    assert j["kinetic"] == 2.0 and math.isclose(j["residual"], -1e-3, rel_tol=1e-12)
    assert np.allclose(j["removed_momentum_N_s"], [1.0, 0.0, 0.0]) and "removed_momentum" not in j


def test_list_writes_ranges_one_way(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert not re.search(r"\(>=? 0[;)]", out)                        # ranges only as "range [0, inf)"
    assert not re.search(r"= none \S+/", out) and "none km/s" not in out
