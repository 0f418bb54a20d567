"""Impact measures (analysis.impact) and the tiny versions of the scenes taylor, hypervelocity, multilayer."""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.analysis.impact import (axial_outline, cone_half_angle, find_taylor_test, hole_diameter,
                                        outline_deviation, taylor_measures, taylor_outline, taylor_tests,
                                        taylor_yield)
from clusterdyn.errors import InputError
from clusterdyn.scenes import get_scene
from clusterdyn.scenes.common import run_frames

mm = units.mm


# ----------------------------------------------------------------------------- measures
def _cylinder(rng, n, radius, length, r_of_z=None):
    z = rng.uniform(0, length, n)
    R = radius if r_of_z is None else r_of_z(z)
    r = R * np.sqrt(rng.uniform(0, 1, n))
    a = rng.uniform(0, 2 * np.pi, n)
    return np.column_stack([r * np.cos(a) + 3.0, r * np.sin(a) - 1.0, z])


def test_outline_and_taylor_measures_of_a_known_mushroom():
    rng = np.random.default_rng(0)
    L, R0 = 30 * mm, 4 * mm

    def prof(z):                       # a mushroom: 2 R0 at the face, R0 beyond 10 mm
        return np.where(z < 10 * mm, R0 * (2.0 - z / (10 * mm)), R0)
    pos = _cylinder(rng, 200_000, R0, L, prof)
    out = axial_outline(pos, 2, 1 * mm, q=100.0)
    assert out["r"][0] == pytest.approx(prof(out["edges"][0]), rel=0.01)   # the slab's widest point
    m = taylor_measures(out["z"], out["r"], L0=35 * mm, D0=2 * R0, top=L)
    assert m["Lf"] == pytest.approx(L)
    assert m["Df"] == pytest.approx(4 * R0, rel=0.01)
    assert m["X"] == pytest.approx(L - 9.8 * mm, abs=0.6 * mm)            # 1.02 R0 at z = 9.8 mm; slabs of 1 mm
    assert m["W"] == pytest.approx(2 * prof(0.2 * 35 * mm), rel=0.05)
    # the outline against itself: no deviation; against a narrower one: the difference
    assert outline_deviation(out["z"], out["r"], out["z"], out["r"], 2 * R0) == pytest.approx(0.0)
    assert outline_deviation(out["z"], out["r"], out["z"][-5:], out["r"][-5:] - 0.4 * mm, 2 * R0) == \
        pytest.approx(0.1, rel=1e-6)


def test_taylor_yield_and_data():
    # Y = rho V^2 (L0 - X) / (2 (L0 - Lf) ln(L0/X)), by hand for the W-G 373 m/s test
    t = find_taylor_test(23.47 * mm, 7.62 * mm, 373 * units.m_s)
    assert t["name"] == "Wilkins-Guinan-1973_V373_L23.47" and t["has_outline"]
    rho, V = 2700 * units.kg / units.m ** 3, 373 * units.m_s
    Y = taylor_yield(rho, V, 23.47, 16.499, 7.5)
    assert Y / units.GPa == pytest.approx(2700 * 373 ** 2 * (23.47 - 7.5) / (2 * (23.47 - 16.499)
                                          * math.log(23.47 / 7.5)) / 1e9, rel=1e-12)
    assert math.isnan(taylor_yield(rho, V, 10.0, 10.0, 5.0))
    rows = [r for r in taylor_tests() if r["has_outline"] and r["T0_K"] < 300]
    assert len(rows) == 4                                # the four room-temperature tests with outlines
    z, r = taylor_outline("Gust-1982_V200_295K")
    assert np.all(np.diff(z) >= 0) and r.max() == pytest.approx(4.178557 * mm)
    assert find_taylor_test(23.47 * mm, 7.62 * mm, 380 * units.m_s) is None
    assert find_taylor_test(32.2 * mm, 6.3 * mm, 194 * units.m_s) is None       # 635 K: not room temperature


def test_hole_and_cone():
    # a plate of points on a 0.1 mm grid with a 10 mm hole
    g = np.arange(-20, 20, 0.1) * mm
    X, Y = np.meshgrid(g, g)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) > 5 * mm]
    h = hole_diameter(pts, (0.0, 0.0), 0.5 * mm, extent=[[-21 * mm, 21 * mm]] * 2)
    # cells partly over material count as full: low by up to a cell on the diameter
    assert 9.0 * mm < h["d"] < 10 * mm
    assert hole_diameter(pts, (10 * mm, 10 * mm), 0.5 * mm)["d"] == 0.0          # on material: no hole
    cut = pts[np.abs(pts[:, 1]) > 1 * mm]                                           # cut through to the rim
    assert math.isnan(hole_diameter(cut, (0.0, 0.0), 0.5 * mm, extent=[[-21 * mm, 21 * mm]] * 2)["d"])
    # cone: unit vectors spread uniformly in angle 0..60 deg: 90% of the mass within 54 deg
    ang = np.radians(np.linspace(0, 60, 10001))
    v = np.column_stack([np.sin(ang), np.zeros_like(ang), np.cos(ang)])
    assert math.degrees(cone_half_angle(v, np.ones(len(v)), (0, 0, 1), 0.9)) == pytest.approx(54.0, abs=0.05)


def test_run_frames_stops_when_asked():
    class Dyn:
        nsteps = 0

        def run(self, k):
            self.nsteps += k
    d = Dyn()
    run_frames(d, 1000, 100, lambda dyn: None, progress=False, stop=lambda dyn: dyn.nsteps >= 30)
    assert d.nsteps == 30


# ----------------------------------------------------------------------------- scenes (tiny)
TAYLOR_TINY = {"L0": "23.47mm", "V": "373", "r0": "1.27mm", "relax_cycles": "2", "t_max": "40"}


def test_taylor_tiny(tmp_path):
    res = get_scene("taylor").run(TAYLOR_TINY, out=tmp_path, progress=False, )
    q = res.quantities
    assert q["Lf_over_L0"].reference == pytest.approx(16.499 / 23.47)
    assert 0.7 < q["Lf_over_L0"].value < 1.0             # shortened (coarse CD rods are too stiff)
    assert q["Df_over_D0"].value > 1.05                  # a mushroom at the impact face
    assert np.isfinite(q["outline_deviation"].value)
    # the ledger closes: kinetic + potential change + damping loss = initial kinetic, to the integration
    # error (a barely relaxed polycrystal also releases stored energy, which the damping takes)
    e0 = q["E_kinetic_initial"].value
    assert abs(q["E_residual"].value) < 5e-3 * (e0 + q["E_damping_loss"].value)
    assert q["E_damping_loss"].value > 0 and q["E_wall_work"].value == 0.0
    for f in ("taylor_outline.png", "taylor_outline.csv", "taylor_history.png", "result.json"):
        assert (tmp_path / f).exists()
    assert "experiment" in (tmp_path / "taylor_outline.csv").read_text()


def test_hypervelocity_tiny(tmp_path):
    res = get_scene("hypervelocity").run({"r0": "0.8mm", "radius": "12mm", "t_end": "3", "h5md": "false"},
                                         out=tmp_path, progress=False)
    q = res.quantities
    assert 0.5 * 9.53 < q["hole_diameter"].value < 24.0   # perforated, the hole inside the plate
    assert 4.0 < q["cloud_lead_speed"].value < 7.5
    assert abs(q["E_residual"].value) < 1e-3 * q["E_kinetic_initial"].value
    for f in ("hypervelocity_radiographs.png", "hypervelocity_radiographs.csv", "hypervelocity_fragments.png",
              "hypervelocity_fragments.csv", "hypervelocity_history.csv"):
        assert (tmp_path / f).exists()


def test_multilayer_tiny():
    res = get_scene("multilayer").run({"r0": "2.5mm", "radius": "15mm", "t_end": "8"}, progress=False)
    q = res.quantities
    assert q["layer1_textolite_hole"].value != 0.0        # the first layer is perforated
    assert q["layer7_steel_hole"].value == 0.0            # the last is not
    assert abs(q["E_residual"].value) < 1e-3 * q["E_kinetic_initial"].value


def test_bad_input_refused_before_work():
    with pytest.raises(InputError, match="r0"):
        get_scene("taylor").run({"r0": "3mm"}, progress=False)              # fewer than 4 across D0
    with pytest.raises(InputError, match="grain_size"):
        get_scene("taylor").run({"grain_size": "0.5mm", "r0": "0.5mm"}, progress=False)
    with pytest.raises(InputError, match="radius"):
        get_scene("hypervelocity").run({"radius": "5mm"}, progress=False)
    with pytest.raises(InputError, match="image_times"):
        get_scene("hypervelocity").run({"image_times": "soon"}, progress=False)
    with pytest.raises(InputError, match="r0"):
        get_scene("multilayer").run({"r0": "5mm"}, progress=False)


def test_hypervelocity_removes_the_debris_beyond_its_region(tmp_path):
    """keep_within: clusters leaving the cube are removed, their energy booked (the ledger still
    closes), the H5MD file keeps its rows with fill values; a region that cuts the set-up is refused."""
    from clusterdyn.errors import InputError
    from clusterdyn.io import read_h5md
    scene = get_scene("hypervelocity")
    p = {"r0": "0.8mm", "radius": "12mm", "t_end": "3", "h5md_frames": "3"}
    res = scene.run({**p, "keep_within": "14mm"}, out=tmp_path, progress=False)
    q = res.quantities
    assert q["E_removed"].value > 0.01 * q["E_kinetic_initial"].value      # debris took energy out
    assert abs(q["E_residual"].value) < 1e-3 * q["E_kinetic_initial"].value
    assert any("removed" in n for n in res.notes)
    first, last = read_h5md(tmp_path / "hypervelocity.h5md", 0), read_h5md(tmp_path / "hypervelocity.h5md", -1)
    assert len(last) < len(first)                  # the fill rows are dropped on reading
    with pytest.raises(InputError, match="keep_within"):
        scene.run({**p, "keep_within": "10mm"}, progress=False)
