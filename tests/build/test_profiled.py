"""Profiled free surfaces: sinusoid, grooves, random roughness (Rz, correlation length), periodicity."""

import math

import numpy as np
import pytest
from ase.neighborlist import neighbor_list

from clusterdyn import units
from clusterdyn.build.profiled import (Grooves, RandomRoughness, Sinusoid, correlation_length, gaussian_field,
                                       profiled_sample, rz_of_profile, surface_amplitude, surface_heights,
                                       surface_roughness)
from clusterdyn.errors import InputError

R0 = 1 * units.um


@pytest.fixture(scope="module")
def sine2d():
    return profiled_sample("Pb", R0, Sinusoid(3 * R0, 20 * R0), depth=12 * R0, width=60 * R0, axis="z")


def test_sinusoid_amplitude_and_wavelength_by_fft(sine2d):
    a = sine2d
    p = a.info["profile"]
    assert p["orientation"] == {"normal": "[100]", "u": "[010]", "v": "[001]"}
    assert p["n_periods"] == 3 and a.pbc.tolist() == [True, True, False]
    m = surface_amplitude(a)
    assert m["mode"][0] == 3
    assert abs(m["amplitude"] - 3 * R0) < R0
    assert abs(m["wavelength"] - 20 * R0) < R0
    # the surface follows the cosine, not only its strongest mode
    s = surface_heights(a)
    u = np.arange(len(s["heights"])) * s["spacing"][0]
    h = s["heights"] - s["heights"].mean()
    assert np.sqrt(np.mean((h - 3 * R0 * np.cos(2 * np.pi * u / p["period_A"])) ** 2)) < 0.5 * R0
    # no cluster above the surface, none missing below it (one plane spacing)
    x = a.positions
    top = 12 * R0 + 3 * R0 * np.cos(2 * np.pi * x[:, 0] / p["period_A"])
    assert np.all(x[:, 2] < top)


def test_sinusoid_3d_crossed_and_orientation():
    a = profiled_sample("Al", R0, Sinusoid(2 * R0, 12 * R0, crossed=True), depth=8 * R0, width=24 * R0, dims=3,
                        direction="110")
    p = a.info["profile"]
    assert p["orientation"] == {"normal": "[110]", "u": "[-110]", "v": "[001]"}
    m = surface_amplitude(a)
    assert m["mode"] == (2, 2)
    assert abs(m["amplitude"] - 2 * R0) < R0 and abs(m["wavelength"] - 12 * R0) < R0
    assert abs(m["wavelength_v"] - 12 * R0) < R0


def test_grooves():
    g = Grooves(6 * R0, 16 * R0)
    a = profiled_sample("Al", R0, g, depth=10 * R0, width=48 * R0, axis=1, direction="111")
    s = surface_heights(a)
    h = s["heights"]
    u = np.arange(len(h)) * s["spacing"][0]
    assert abs(np.ptp(h) - 6 * R0) < R0
    tri = g.heights(u, None, a.info["profile"]["period_A"])
    assert np.sqrt(np.mean((h - h.mean() - tri) ** 2)) < 0.5 * R0
    m = surface_amplitude(a)
    assert abs(m["wavelength"] - 16 * R0) < R0
    # a triangle wave's fundamental: 8/pi^2 of its half height
    assert m["amplitude"] == pytest.approx(8 / math.pi ** 2 * 3 * R0, abs=0.5 * R0)


def test_rz_definition():
    h = np.concatenate([np.zeros(10), np.zeros(10) + [0, 4] * 5, np.zeros(10), np.zeros(10), np.zeros(10)])
    assert rz_of_profile(h) == pytest.approx(4 / 5)            # one sampling length of five has 4
    x = np.linspace(0, 1, 500, endpoint=False)
    assert rz_of_profile(np.sin(2 * np.pi * 5 * x)) == pytest.approx(2.0, abs=1e-3)   # a period per length
    f = gaussian_field((4000,), 0.5, 3.0, np.random.default_rng(0))
    assert correlation_length(f, 0.5) == pytest.approx(3.0, rel=0.1)
    assert np.mean(f) == pytest.approx(0, abs=1e-12) and np.mean(f ** 2) == pytest.approx(1.0)


def test_random_quasi2d_rz_and_correlation_length():
    rz, xi = 8 * R0, 2.5 * R0
    a = profiled_sample("Pb", R0, RandomRoughness(rz, xi, seed=1), depth=12 * R0, width=500 * R0)
    p = a.info["profile"]
    r = surface_roughness(a)                     # measured on the built sample's surface clusters
    assert r["rz"] == pytest.approx(p["rz_A"])
    assert abs(r["rz"] / rz - 1) < 0.10
    assert abs(r["correlation_length"] / xi - 1) < 0.25
    assert r["sampling_length"] == pytest.approx(p["width_A"] / 5)


def test_random_3d_rz_and_correlation_length():
    rz, xi = 4.5 * R0, 3 * R0
    a = profiled_sample("Pb", R0, RandomRoughness(rz, xi, seed=2), depth=15 * R0, width=48 * R0, dims=3)
    r = surface_roughness(a)
    assert surface_heights(a)["heights"].ndim == 2
    assert abs(r["rz"] / rz - 1) < 0.10
    assert abs(r["correlation_length"] / xi - 1) < 0.25
    # same seed, same surface
    b = profiled_sample("Pb", R0, RandomRoughness(rz, xi, seed=2), depth=15 * R0, width=48 * R0, dims=3)
    np.testing.assert_array_equal(a.positions, b.positions)


@pytest.mark.parametrize("dims", [2, 3])
def test_periodic_faces_join(dims):
    prof = Sinusoid(2 * R0, 10 * R0)
    a = profiled_sample("Al", R0, prof, depth=8 * R0, width=20 * R0, dims=dims, axis=0)
    p = a.info["profile"]
    iu = p["u_axis"]
    # the lattice continues across both periodic faces: every cluster away from the free surface and
    # the base has its 12 neighbours at r0 (minimum image)
    i, d = neighbor_list("id", a, 1.05 * R0)
    nn = np.bincount(i, minlength=len(a))
    x = a.positions
    below = 8 * R0 + 2 * R0 * np.cos(2 * np.pi * x[:, iu] / p["period_A"]) - x[:, 0]
    inner = (below > 1.5 * R0) & (x[:, 0] > 1.0 * R0)
    near_face = inner & ((x[:, iu] < 1.5 * R0) | (x[:, iu] > p["width_A"] - 1.5 * R0))
    assert near_face.sum() > 10 and np.all(nn[inner] == 12)
    assert np.allclose(d, R0)
    # the surface joins: the step across the periodic face is no larger than the steps inside
    h = surface_heights(a)["heights"]
    h1 = h if h.ndim == 1 else h.mean(axis=1)
    inside = np.abs(np.diff(h1)).max()
    assert abs(h1[0] - h1[-1]) <= inside + 1e-9 * R0


def test_periodic_slab_has_no_force_in_its_interior(sine2d):
    from clusterdyn.calculators import ClusterDynamics
    a = sine2d.copy()
    a.calc = ClusterDynamics()
    f = np.linalg.norm(a.get_forces(), axis=1)
    p = a.info["profile"]
    x = a.positions
    below = 12 * R0 + 3 * R0 * np.cos(2 * np.pi * x[:, 0] / p["period_A"]) - x[:, 2]
    inner = (below > 1.5 * R0) & (x[:, 2] > 1.0 * R0)
    assert inner.sum() > 100 and f[inner].max() < 1e-9 * f.max()


@pytest.mark.parametrize("call, arg", [
    (lambda: Sinusoid(-1.0, 10 * R0), "amplitude"),
    (lambda: Sinusoid(R0, 0.0), "wavelength"),
    (lambda: Grooves(0.0, 10 * R0), "depth"),
    (lambda: RandomRoughness(-R0, 3 * R0), "rz"),
    (lambda: profiled_sample("Al", R0, Sinusoid(R0, 10 * R0), depth=8 * R0, width=25 * R0), "width"),
    (lambda: profiled_sample("Al", R0, Sinusoid(7 * R0, 10 * R0), depth=8 * R0, width=20 * R0), "depth"),
    (lambda: profiled_sample("Al", R0, Sinusoid(R0, 10 * R0), depth=-1.0, width=20 * R0), "depth"),
    (lambda: profiled_sample("Al", R0, Sinusoid(R0, 10 * R0), depth=8 * R0, width=20 * R0, dims=4), "dims"),
    (lambda: profiled_sample("Al", R0, Sinusoid(R0, 10 * R0, crossed=True), depth=8 * R0, width=20 * R0),
     "profile"),
    (lambda: profiled_sample("Al", R0, RandomRoughness(2 * R0, 10 * R0), depth=8 * R0, width=40 * R0), "width"),
    (lambda: profiled_sample("Al", R0, RandomRoughness(2 * R0, 0.5 * R0), depth=8 * R0, width=40 * R0),
     "correlation_length"),
    (lambda: profiled_sample("Al", R0, Sinusoid(R0, 10 * R0), depth=8 * R0, width=20 * R0, slab_cells=0),
     "slab_cells"),
    (lambda: profiled_sample("Al", R0, Sinusoid(R0, 10 * R0), depth=8 * R0, width=20 * R0, direction="120"),
     "direction"),
    (lambda: profiled_sample("Al", R0, "sinusoid", depth=8 * R0, width=20 * R0), "profile"),
])
def test_bad_input_refused_in_one_line(call, arg):
    with pytest.raises(InputError) as exc:
        call()
    assert exc.value.argument == arg
    assert "\n" not in str(exc.value)
