"""MDAnalysis on clusterdyn H5MD files: open axes are open, LinearDensity works, EinsteinMSD
sees unwrapped coordinates (#46 items 8 and 13)."""

import warnings

import numpy as np
import pytest
from ase import Atoms
from scipy.spatial.distance import pdist

from clusterdyn.io import H5MDWriter, read_h5md

mda = pytest.importorskip("MDAnalysis")
from MDAnalysis.lib.distances import self_distance_array  # noqa: E402

from clusterdyn.io.mda import universe  # noqa: E402


def _atoms(pos, cell, pbc):
    n = len(pos)
    a = Atoms(numbers=np.full(n, 13), positions=pos, cell=cell, pbc=pbc)
    a.set_masses(np.full(n, 2.0e9))
    a.new_array("id", np.arange(n, dtype=np.int64))
    a.new_array("material", np.zeros(n, dtype=np.int64))
    return a


def _write(path, atoms, frames=None):
    with H5MDWriter(path, atoms) as w:
        for k, pos in enumerate(frames if frames is not None else [atoms.positions.copy()]):
            atoms.positions = pos
            w.write(step=k, time=float(k))


def _sphere(R, n=400, seed=1):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    r = R * rng.uniform(0.5, 1.0, n) ** (1 / 3)
    return R + v / np.linalg.norm(v, axis=1)[:, None] * r[:, None]   # inside a cube of edge 2R


def test_an_open_sphere_has_no_box_and_no_minimum_image(tmp_path):
    R = 5.0e4                                     # 10 r0 of 5 um, in Angstrom
    pos = _sphere(R)
    path = tmp_path / "sphere.h5md"
    _write(path, _atoms(pos, np.diag([2 * R] * 3), False))
    true = pdist(pos)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = mda.Universe(str(path))           # MDAnalysis alone, no clusterdyn topology
    assert plain.dimensions is None
    d = self_distance_array(plain.atoms.positions, box=plain.dimensions)
    assert np.abs(d - true).max() < 1e-6 * 2 * R  # float32 precision
    # the cell as a periodic box (what the files said before) gets far pairs wrong
    wrong = self_distance_array(pos.astype(np.float32), box=[2 * R] * 3 + [90] * 3)
    assert np.abs(wrong - true).max() > 0.5 * R
    # clusterdyn's own reader still gives the Atoms their cell
    back = read_h5md(path)
    np.testing.assert_allclose(back.cell[:], np.diag([2 * R] * 3))
    assert not back.pbc.any()
    assert universe(path).dimensions is None


def test_a_shock_box_is_open_along_x_and_periodic_across(tmp_path):
    L = np.array([100.0, 10.0, 10.0])
    # x open (the sample has grown past its cell), y and z periodic
    pos = np.array([[5.0, 0.5, 5.0], [95.0, 0.5, 5.0], [50.0, 9.5, 5.0], [50.0, 0.5, 5.0],
                    [130.0, 5.0, 5.0]])
    path = tmp_path / "shock.h5md"
    _write(path, _atoms(pos, np.diag(L), [False, True, True]))
    u = universe(path)
    d = self_distance_array(u.atoms.positions, box=u.dimensions)
    # pairs in pdist order: (0,1) along the open x: 90, not 10; (2,3) across periodic y: 1, not 9
    k = {(i, j): n for n, (i, j) in enumerate((i, j) for i in range(5) for j in range(i + 1, 5))}
    assert d[k[0, 1]] == pytest.approx(90.0, rel=1e-6)
    assert d[k[2, 3]] == pytest.approx(1.0, rel=1e-5)
    assert d[k[0, 4]] == pytest.approx(np.linalg.norm([125.0, 4.5, 0.0]), rel=1e-6)
    assert u.dimensions[1:3] == pytest.approx(L[1:])


def test_linear_density_from_the_topology_masses(tmp_path):
    from MDAnalysis.analysis.lineardensity import LinearDensity
    rng = np.random.default_rng(3)
    L = 20.0
    pos = rng.uniform(0, L, (200, 3))
    path = tmp_path / "box.h5md"
    _write(path, _atoms(pos, np.diag([L] * 3), True))
    u = universe(path)
    assert np.all(u.atoms.charges == 0.0)
    ld = LinearDensity(u.atoms, grouping="atoms", binsize=2.0).run()
    amu_per_A3_in_g_cm3 = 1.66053906660
    expect = 200 * 2.0e9 / L ** 3 * amu_per_A3_in_g_cm3
    assert ld.results.x.mass_density.mean() == pytest.approx(expect, rel=1e-5)


def test_einstein_msd_on_unwrapped_coordinates(tmp_path):
    from MDAnalysis.analysis.msd import EinsteinMSD
    L = 10.0
    start = np.array([[1.0, 1.0, 1.0], [5.0, 5.0, 5.0], [9.0, 2.0, 7.0]])
    v = np.array([[7.0, 0.0, 0.0], [0.0, -6.0, 0.0], [3.0, 4.0, -5.0]])   # per frame: crosses the box
    frames = [start + k * v for k in range(6)]
    path = tmp_path / "drift.h5md"
    _write(path, _atoms(start.copy(), np.diag([L] * 3), True), frames)
    exact = np.array([np.mean(np.sum((k * v) ** 2, axis=1)) for k in range(6)])
    msd = EinsteinMSD(universe(path, unwrap=True), select="all", msd_type="xyz", fft=False).run()
    np.testing.assert_allclose(msd.results.timeseries, exact, rtol=1e-5)
    wrapped = EinsteinMSD(universe(path), select="all", msd_type="xyz", fft=False).run()
    assert not np.allclose(wrapped.results.timeseries, exact, rtol=0.1)
