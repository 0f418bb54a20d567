"""Scene spall and analysis.spall: pullback, wave speeds and spall plane on known inputs, a tiny run."""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.analysis.fragments import fragments
from clusterdyn.analysis.spall import (LagrangianMap, pullback, ring_thickness, spall_plane, spall_strength,
                                       wave_speeds)
from clusterdyn.build import fcc_packing
from clusterdyn.errors import InputError
from clusterdyn.scenes import get_scene

R0 = 10 * units.um


def _trace():
    """Piecewise-linear free-surface history: rise at 10, a wiggle, drop 40->50 from 2000 to 1200, a spall
    signal back to 1800, then ringing of period 20 (times in ns, velocities in m/s)."""
    t = np.arange(0.0, 130.0, 0.25)
    u = np.interp(t, [0, 10, 12, 16, 18, 40, 50, 55, 130], [0, 0, 2000, 1950, 2000, 2000, 1200, 1800, 1800])
    late = t > 55
    u[late] += 200 * np.sin(2 * math.pi * (t[late] - 55) / 20.0)
    return t, u


def test_pullback_of_a_known_trace():
    t, u = _trace()
    pb = pullback(t, u, 2000.0, pulse=30.0, c=5.0)
    assert pb["t_arrival"] == pytest.approx(10.5)                       # u_ref / 4 on the 1000 m/s/ns rise
    assert pb["u_max"] == pytest.approx(2000.0)
    assert pb["u_min"] == pytest.approx(1200.0)
    assert pb["du"] == pytest.approx(800.0)
    assert pb["spall_signal"] and 50.0 < pb["t_signal"] < 52.0
    # unloading 800 m/s in 10 ns, c = 5 km/s: (80 m/s/ns) / (2 c) = 8e6 /s (here in 1/ns x 1e-3)
    assert pb["strain_rate"] == pytest.approx(80.0 / 10.0, rel=1e-6)
    # without the pulse hint the wiggle (2000 -> 1950 -> 2000) does not count as the pullback either
    assert pullback(t, u, 2000.0)["u_min"] == pytest.approx(1200.0)
    # no spall: the surface falls to rest
    u2 = np.interp(t, [0, 10, 12, 40, 50, 130], [0, 0, 2000, 2000, 0, 0])
    pb2 = pullback(t, u2, 2000.0, pulse=30.0)
    assert not pb2["spall_signal"] and pb2["du"] == pytest.approx(2000.0)
    assert spall_strength(2.7, 5.35, 1.0) == pytest.approx(7.2225)
    h, T = ring_thickness(t, u, 56.0, 6.0)
    assert T == pytest.approx(20.0, rel=0.02) and h == pytest.approx(60.0, rel=0.02)


def _acoustic_map(Lf=20.0, Lt=40.0, D=7.0, c=5.0, P=10.0, dt=0.25, w=1.0):
    """Stress map of an ideal flyer-on-target impact in material coordinates: the flyer on [0, Lf], the
    target on [Lf, Lf + Lt]; a square pulse of amplitude P between the shock (speed D) and the releases'
    trailing edges (speed c): forward from the flyer's rear at Lf/D, backward from the rear face at Lt/D."""
    x = np.arange(0.5 * w, Lf + Lt, w)
    t = np.arange(0.0, (Lf + Lt) / c, dt)
    S = np.zeros((len(t), len(x)))
    for k, tk in enumerate(t):
        front = Lf + D * tk                                   # shock into the target
        back = Lf - D * tk                                    # shock into the flyer
        rel_f = c * (tk - Lf / D)                             # release from the flyer's rear
        rel_b = Lf + Lt - c * (tk - Lt / D)                   # release from the target's rear
        lo = max(back, rel_f) if tk > Lf / D else back
        hi = min(front, rel_b) if tk > Lt / D else front
        comp = (x > lo) & (x < hi)
        S[k, comp] = -P
    return {"t": t, "x": x, "stress": S}


def test_wave_speeds_and_the_releases_crossing_on_an_acoustic_map():
    Lf, Lt, D, c = 20.0, 40.0, 7.0, 5.0
    ws = wave_speeds(_acoustic_map(Lf, Lt, D, c), Lf, Lf + Lt)
    assert ws["D"] == pytest.approx(D, rel=0.03)
    assert ws["c_forward"] == pytest.approx(c, rel=0.03)
    assert ws["c_backward"] == pytest.approx(c, rel=0.05)
    # trailing edges cross where c (t - Lf/D) = Lf + Lt - c (t - Lt/D)
    tc = (Lf + Lt + c * (Lf + Lt) / D) / (2 * c)
    assert ws["d_expected"] == pytest.approx(Lf + Lt - c * (tc - Lf / D), abs=1.0)
    # acoustic (c = D): one flyer thickness from the rear face
    assert wave_speeds(_acoustic_map(Lf, Lt, 6.0, 6.0), Lf, Lf + Lt)["d_expected"] == pytest.approx(Lf, abs=1.0)


def test_spall_plane_of_a_split_target():
    target = fcc_packing("Al", R0, size=(10, 2, 2), pbc=(False, True, True))
    x0 = target.positions[:, 0].copy()
    a = target.copy()
    cut = x0 > x0.max() - 3 * math.sqrt(2) * R0 + 1e-3 * R0             # the last 3 cells: 6 planes
    a.positions[cut, 0] += 3 * R0                                        # opened by 3 r0
    f = fragments(a, b=1.15)
    rear = x0 > x0.max() - 0.1 * R0
    p = spall_plane(a, f, x0, np.ones(len(a), bool), rear)
    assert p["spalled"] and p["scab_fraction"] == pytest.approx(0.3)
    assert p["n_target_fragments"] == 2
    intact = spall_plane(target, fragments(target, b=1.15), x0, np.ones(len(a), bool), rear)
    assert not intact["spalled"] and intact["scab_fraction"] == 1.0
    with pytest.raises(InputError):
        spall_plane(target, fragments(target, b=1.15), x0, np.ones(len(a), bool), np.zeros(len(a), bool))


def test_lagrangian_map_bins_by_material_coordinate():
    x0 = np.array([0.0, 0.4, 1.2, 2.1])
    m = LagrangianMap(x0, 1.0, 2.0)
    vir = np.zeros((4, 6))
    vir[:, 0] = [1.0, 3.0, -4.0, 8.0]
    m.add(vir, 5.0)
    arr = m.arrays()
    assert arr["stress"].shape == (1, 3) and arr["t"][0] == 5.0
    assert np.allclose(arr["stress"][0], [1.0, -2.0, 4.0])               # sum W / sum V per bin
    st = m.get_state()
    m2 = LagrangianMap(x0, 1.0, 2.0)
    m2.set_state(st)
    assert np.array_equal(m2.arrays()["stress"], arr["stress"])


def test_tiny_single_crystal_spalls(tmp_path):
    res = get_scene("spall").run({"sample": "single", "flyer": "8", "target": "16", "width": "4", "frames": "60",
                                  "v": "3000m/s", "h5md": "false", "checkpoint_every": "0"}, out=tmp_path,
                                 progress=False)
    q = res.quantities
    assert q["sc_spalled"].value == 1.0
    assert q["sc_pullback"].value > 300                                   # m/s
    assert q["sc_spall_strength_cL"].value == pytest.approx(math.sqrt(1.5) * q["sc_spall_strength_cb"].value)
    assert 0 < q["sc_spall_strength_cL"].value < 19.2 and 0 < q["sc_max_tension"].value < 19.2
    assert 2 <= q["sc_spall_depth"].value <= 14                            # inside the 16 r0 target
    assert abs(q["sc_spall_depth"].rel_error) < 0.25                       # near where the releases cross
    assert abs(q["sc_ledger_residual"].value) < 1e-3
    for f in ("spall.png", "spall_visar_single.csv", "spall_stress_map_single.csv", "spall_fragments_single.csv"):
        assert (tmp_path / f).exists()


def test_spall_refuses_a_target_thinner_than_the_flyer():
    with pytest.raises(InputError, match="target"):
        get_scene("spall").run({"flyer": "20", "target": "10"}, progress=False)
