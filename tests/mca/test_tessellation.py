"""The set-up tessellation (build/tessellation.py): its compiled passes over the Voronoi ridges give
the geometry of a lattice exactly (analytic cells) and the geometry the per-face Python loop gave.

``data/tessellation_reference.npz`` holds four small samples (fcc box with free surfaces, a random
packing periodic along x, a periodic hcp box, a 2D random packing) and the pairs, areas, distances and
volumes that the per-face Python loop (``_polygon_area_3d`` on every face, the loop of commit
20a2283) computed for them.  The new passes repeat that loop's operations in its order and rounding,
so on the machine that made the file they agree to the bit; the test asks 1e-12 relative, because
numpy's short dot products are its BLAS's and may round otherwise on another machine.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from clusterdyn.build import mca_packing
from clusterdyn.build import tessellation as T

REF = Path(__file__).parent / "data" / "tessellation_reference.npz"
SAMPLES = ("fcc_open", "random_mixed", "hcp_periodic", "random_2d")


@pytest.mark.parametrize("name", SAMPLES)
def test_geometry_as_the_per_face_loop_gave(name):
    ref = np.load(REF)
    g = T._tessellate(ref[name + "/pos"], ref[name + "/rad"], ref[name + "/cell"], ref[name + "/pbc"],
                      int(ref[name + "/dim"]))
    np.testing.assert_array_equal(g["i_p"], ref[name + "/i_p"])
    np.testing.assert_array_equal(g["j_p"], ref[name + "/j_p"])
    for k in ("S_p", "q_p2", "omega_n", "vcell_n"):
        np.testing.assert_allclose(g[k], ref[name + "/" + k], rtol=1e-12, atol=0, err_msg=k)


def test_periodic_fcc_cells_are_rhombic_dodecahedra():
    """fcc of nearest-neighbour distance d: 12 rhombic faces of area d^2/(2 sqrt 2) at d/2, cell
    volume d^3/sqrt 2 (a^3/4 with a = sqrt 2 d)."""
    d = 2.5
    at = mca_packing("Al6061-T6", d, (3 * math.sqrt(2) * d,) * 3, pbc=True)
    g = T._tessellate(at.positions, at.arrays["radius"], at.cell.array, at.pbc, 3)
    n = len(at)
    assert len(g["S_p"]) == 6 * n
    np.testing.assert_allclose(g["S_p"], d * d / (2 * math.sqrt(2)), rtol=1e-14)
    np.testing.assert_allclose(g["q_p2"], d / 2, rtol=1e-14)
    np.testing.assert_allclose(g["omega_n"], d ** 3 / math.sqrt(2), rtol=1e-14)
    np.testing.assert_allclose(g["vcell_n"], d ** 3 / math.sqrt(2), rtol=1e-14)


def test_open_simple_cubic_box_faces_and_clipped_cells():
    """sc of spacing d in an open box: faces d^2 at d/2; every clipped cell d^3 (mirror planes half a
    layer out); the pyramid volume counts the faces with other automata (d^3 * faces / 6)."""
    d = 1.5
    at = mca_packing("Al6061-T6", d, (4 * d, 3 * d, 5 * d), packing="sc")
    g = T._tessellate(at.positions, at.arrays["radius"], at.cell.array, at.pbc, 3)
    n = len(at)
    assert n == 60
    assert len(g["S_p"]) == 3 * 4 * 5 * 3 - (3 * 5 + 4 * 5 + 4 * 3)
    np.testing.assert_allclose(g["S_p"], d * d, rtol=1e-14)
    np.testing.assert_allclose(g["vcell_n"], d ** 3, rtol=1e-14)
    faces = np.bincount(np.concatenate([g["i_p"], g["j_p"]]), minlength=n)
    np.testing.assert_allclose(g["omega_n"], d ** 3 * faces / 6, rtol=1e-14)


def _one_polygon(xy):
    """The area pass on one face given by its vertices' in-plane coordinates (2, K)."""
    K = xy.shape[1]
    rows = np.array([[0, 1]], np.int64)
    start = np.array([0, K], np.int64)
    area = np.zeros(1)
    left = T._ridge_area_pass(rows, start, np.ascontiguousarray(xy), np.arctan2(xy[1], xy[0]), area)
    return bool(left[0]), area[0]


def test_area_pass_and_what_it_leaves_to_the_python_function():
    rng = np.random.default_rng(4)
    # a convex heptagon, vertices in shuffled order: its shoelace area, as _polygon_area_3d's
    phi = np.sort(rng.uniform(0, 2 * np.pi, 7))
    xy = np.array([np.cos(phi), np.sin(phi)]) * 1.7
    xy = xy[:, rng.permutation(7)]
    left, area = _one_polygon(xy)
    pts = np.column_stack([xy[0], xy[1], np.zeros(7)])
    assert not left
    assert area == pytest.approx(T._polygon_area_3d(pts, np.array([0.0, 0.0, 1.0])), rel=1e-14)
    assert area == pytest.approx(0.5 * 1.7 ** 2 * np.sum(np.sin(np.diff(np.r_[phi, phi[0] + 2 * np.pi]))),
                                 rel=1e-13)
    # 16 vertices or more (numpy's dot takes another kernel there) go to the Python function
    phi = np.linspace(0, 2 * np.pi, 17)[:-1]
    assert _one_polygon(np.array([np.cos(phi), np.sin(phi)]))[0]
    # two different vertices at the same angle: numpy's sort order is its own, left to it too
    assert _one_polygon(np.array([[1.0, 2.0, -1.0, 0.0], [0.0, 0.0, 0.5, -1.0]]))[0]


def test_faces_left_to_the_python_function_are_put_back_in_place(monkeypatch):
    """Every face left to ``_polygon_area_3d`` (as if each had 16 vertices): the same geometry."""
    ref = np.load(REF)
    name = "random_mixed"
    area_pass = T._ridge_area_pass

    def leave_all(rows, start, xy, ang, area):
        area_pass(rows, start, xy, ang, area)
        area[:] = -1.0
        return rows[:, 0] >= 0
    monkeypatch.setattr(T, "_ridge_area_pass", leave_all)
    g = T._tessellate(ref[name + "/pos"], ref[name + "/rad"], ref[name + "/cell"], ref[name + "/pbc"], 3)
    np.testing.assert_array_equal(g["i_p"], ref[name + "/i_p"])
    for k in ("S_p", "omega_n", "vcell_n"):
        np.testing.assert_allclose(g[k], ref[name + "/" + k], rtol=1e-12, atol=0, err_msg=k)
