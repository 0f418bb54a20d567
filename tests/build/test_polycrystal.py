"""Polycrystal builder: Voronoi grains, orientations, boundary rule, shapes, periodic wrap, bad input."""

import math
import time

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from clusterdyn import units
from clusterdyn.build import Box, Cylinder, Plate, Sphere, fcc_sites
from clusterdyn.build.polycrystal import (DEFAULT_D_MIN, grain_statistics, polycrystal,
                                          polycrystal_summary)
from clusterdyn.errors import InputError

R0 = 10 * units.um
SQRT2 = math.sqrt(2.0)


def cube(n_grains, per_grain=300):
    return ((n_grains * per_grain * R0 ** 3 / SQRT2) ** (1 / 3),) * 3


def tree_of(atoms):
    pbc = np.asarray(atoms.pbc)
    L = atoms.cell.lengths()
    pos = atoms.get_positions()
    if pbc.any():
        pos = np.where(pbc, np.mod(pos, np.where(pbc, L, 1.0)), pos)
    return cKDTree(pos, boxsize=np.where(pbc, L, 0.0) if pbc.any() else None), pos


@pytest.fixture(scope="module")
def periodic():
    return polycrystal("Al", R0, size=cube(30), n_grains=30, seed=7, pbc=True)


def test_arrays_info_and_report(periodic):
    a = periodic
    n = len(a)
    assert a.arrays["grain"].dtype == np.int64 and a.arrays["grain"].shape == (n,)
    assert a.info["grain_rotations"].shape == (30, 3, 3)
    assert a.info["grain_seeds"].shape == (30, 3)
    for k in ("material", "radius", "id"):
        assert k in a.arrays
    r = a.info["polycrystal"]
    assert r["n_clusters"] == n
    vol = a.get_volume()
    assert r["porosity"] == pytest.approx(1 - n * R0 ** 3 / SQRT2 / vol)
    assert 0.02 < r["porosity"] < 0.3
    assert r["n_grains"] == len(np.unique(a.arrays["grain"]))
    assert r["nearest_distance_r0"] >= DEFAULT_D_MIN - 1e-9
    text = polycrystal_summary(a)
    assert "porosity" in text and "grains" in text
    assert grain_statistics(a)["n_grains"] == r["n_grains"]


def test_reproducible_by_seed(periodic):
    again = polycrystal("Al", R0, size=cube(30), n_grains=30, seed=7, pbc=True)
    np.testing.assert_array_equal(again.positions, periodic.positions)
    np.testing.assert_array_equal(again.arrays["grain"], periodic.arrays["grain"])
    other = polycrystal("Al", R0, size=cube(30), n_grains=30, seed=8, pbc=True)
    assert len(other) != len(periodic) or not np.allclose(other.positions, periodic.positions)


def test_clusters_belong_to_nearest_seed_min_image(periodic):
    a = periodic
    L = a.cell.lengths()
    seeds = a.info["grain_seeds"]
    d = a.positions[:, None, :] - seeds[None, :, :]
    d -= np.round(d / L) * L
    nearest = np.argmin((d ** 2).sum(axis=2), axis=1)
    np.testing.assert_array_equal(nearest, a.arrays["grain"])


def test_each_grain_is_its_rotated_fcc_lattice(periodic):
    a = periodic
    L = a.cell.lengths()
    rots = a.info["grain_rotations"]
    for g in range(0, 30, 7):
        p = a.positions[a.arrays["grain"] == g]
        d = p - p[0]
        d -= np.round(d / L) * L          # a grain across a periodic face is one lattice
        c = d @ rots[g] / (SQRT2 * R0) * 2.0          # crystal coordinates in half cube edges
        assert np.allclose(c, np.round(c), atol=1e-6)
        assert np.all(np.round(c).sum(axis=1) % 2 == 0)


def test_grains_wrap_across_periodic_faces(periodic):
    a = periodic
    L = a.cell.lengths()
    seeds = a.info["grain_seeds"]
    g = int(np.argmin(seeds[:, 0]))        # the seed nearest x = 0: its grain crosses the face
    x = a.positions[a.arrays["grain"] == g, 0]
    assert x.min() < 0.1 * L[0] and x.max() > 0.9 * L[0]


def test_no_pair_closer_than_d_min_and_no_holes(periodic):
    a = periodic
    tree, pos = tree_of(a)
    d, _ = tree.query(pos, k=2)
    assert d[:, 1].min() >= DEFAULT_D_MIN * R0 * (1 - 1e-9)
    # clusters farther than (1 + d_min) r0 from any boundary keep all 12 neighbours: no site was lost
    seeds = a.info["grain_seeds"]
    L = a.cell.lengths()
    dd = a.positions[:, None, :] - seeds[None]
    dd -= np.round(dd / L) * L
    dist = np.sort(np.linalg.norm(dd, axis=2), axis=1)
    # distance to the nearest Voronoi face is at least (d2 - d1)/2
    deep = (dist[:, 1] - dist[:, 0]) / 2 > (1 + DEFAULT_D_MIN) * R0
    cnt = np.array([len(x) - 1 for x in tree.query_ball_point(pos[deep], 1.05 * R0)])
    assert deep.sum() >= 20 and np.all(cnt == 12)


def test_single_grain_is_the_single_crystal():
    size = np.array([8.0, 7.0, 6.0]) * R0
    rot = Rotation.from_euler("zyx", [20, 30, 40], degrees=True).as_matrix()
    a = polycrystal("Al", R0, size=size, n_grains=1, rotations=[rot], seed=0)
    ref = fcc_sites(R0, rot, np.zeros(3), size)
    assert len(a) == len(ref)
    assert a.info["polycrystal"]["n_removed"] == 0
    assert abs(a.info["polycrystal"]["porosity"]) < 0.15     # surface layer of a small box only


@pytest.mark.parametrize("shape, pbc", [
    (Cylinder((0.0, 12 * R0, 12 * R0), 12 * R0, 40 * R0, axis=0), False),   # Taylor rod
    (Sphere((15 * R0,) * 3, 15 * R0), False),
    (Plate(10 * R0, 30 * R0, axis=0), (False, True, True)),                   # free along x
])
def test_shapes(shape, pbc):
    a = polycrystal("Al", R0, shape, grain_size=8 * R0, seed=1, pbc=pbc)
    lo, hi = shape.bounds()
    if isinstance(shape, Box):
        assert np.all(a.positions >= lo - 1e-6) and np.all(a.positions < hi)
    else:
        assert shape.contains(a.positions).all()
    r = a.info["polycrystal"]
    assert r["nearest_distance_r0"] >= DEFAULT_D_MIN - 1e-9
    assert 0.0 < r["porosity"] < 0.35
    assert r["n_grains"] >= 5
    assert list(a.pbc) == list(np.broadcast_to(pbc, 3))


def test_target_porosity():
    a = polycrystal("Al", R0, size=cube(20, 600), n_grains=20, seed=2, pbc=True, target_porosity=0.06,
                    porosity_tol=0.003)
    r = a.info["polycrystal"]
    assert r["porosity"] == pytest.approx(0.06, abs=0.003)
    assert r["nearest_distance_r0"] >= r["d_min_r0"] - 1e-9
    b = polycrystal("Al", R0, size=cube(20, 600), n_grains=20, seed=2, pbc=True, d_min=1.0)
    assert b.info["polycrystal"]["porosity"] > r["porosity"]          # larger d_min, more removed
    with pytest.raises(InputError, match="target_porosity"):
        polycrystal("Al", R0, size=cube(20, 600), n_grains=20, seed=2, pbc=True, target_porosity=0.6)


def test_build_time_report(capsys):
    t = time.perf_counter()
    a = polycrystal("Al", R0, size=cube(200, 250), n_grains=200, seed=3, pbc=True)
    wall = time.perf_counter() - t
    assert wall < 5.0
    assert a.info["polycrystal"]["build_time_s"] <= wall
    print(polycrystal_summary(a))


def test_bad_input_refused():
    with pytest.raises(InputError, match="n_grains"):
        polycrystal("Al", R0, size=cube(10), n_grains=0)
    with pytest.raises(InputError, match="grain_size"):
        polycrystal("Al", R0, size=cube(10), grain_size=2.5 * R0)
    with pytest.raises(InputError, match="grain_size"):         # shape smaller than one grain
        polycrystal("Al", R0, size=(5 * R0,) * 3, grain_size=10 * R0)
    with pytest.raises(InputError, match="n_grains"):           # grains below 3 r0 in this shape
        polycrystal("Al", R0, size=(10 * R0,) * 3, n_grains=100)
    with pytest.raises(InputError, match="pbc"):
        polycrystal("Al", R0, Sphere((0, 0, 0), 10 * R0), n_grains=3, pbc=True)
    with pytest.raises(InputError, match="rotations"):
        polycrystal("Al", R0, size=cube(3), n_grains=3, rotations=np.ones((3, 3, 3)))
    with pytest.raises(InputError, match="n_grains"):
        polycrystal("Al", R0, size=cube(3), n_grains=3, grain_size=8 * R0)
    with pytest.raises(InputError, match="d_min"):
        polycrystal("Al", R0, size=cube(3), n_grains=3, d_min=0.2)
