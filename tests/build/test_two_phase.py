"""Two-phase samples: spherical inclusions in a matrix, placed at random without overlap, by seed."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import PAPER_CASES, two_phase
from clusterdyn.build.two_phase import SQRT2, place_spheres, volume_fraction
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError
from clusterdyn.materials import get_material

R0 = 4 * units.um


def small(seed=1, **kw):
    args = dict(r0=R0, size=(16, 6, 6), seed=seed)
    args.update(kw)
    return two_phase("h-BN", "B4C", 0.28, 12 * units.um, **args)


def test_reproducible_by_seed():
    a, b, c = small(1), small(1), small(2)
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.arrays["material"], b.arrays["material"])
    assert not np.array_equal(a.arrays["material"], c.arrays["material"])


def test_spheres_do_not_overlap_and_hold_the_inclusions():
    a = small(3)
    info = a.info["two_phase"]
    c, d = info["centres"], info["diameters"]
    L = a.cell.lengths()
    for i in range(len(c)):
        for j in range(i):
            dv = c[i] - c[j]
            dv -= L * np.round(dv / L)
            assert np.linalg.norm(dv) >= 0.5 * (d[i] + d[j]) - 1e-9
    # every inclusion cluster lies in a sphere, every matrix cluster outside all spheres
    pos = a.positions
    dist = np.min([np.linalg.norm((pos - cc) - L * np.round((pos - cc) / L), axis=1) - 0.5 * dd
                   for cc, dd in zip(c, d)], axis=0)
    inc = a.arrays["material"] == 1
    assert np.all(dist[inc] <= 1e-9) and np.all(dist[~inc] > 0)


def test_mass_fraction_masses_and_density():
    a = small(4)
    info = a.info["two_phase"]
    assert info["mass_fraction"] == pytest.approx(0.28, abs=0.05)
    assert info["matrix"] == "h-BN" and info["inclusion"] == "B4C"
    m = a.get_masses()
    for mid, name in ((0, "h-BN"), (1, "B4C")):
        assert np.allclose(m[a.arrays["material"] == mid], get_material(name).rho0 * R0 ** 3 / SQRT2)
    phi = volume_fraction(0.28, get_material("B4C").rho0, get_material("h-BN").rho0)
    assert info["volume_fraction_target"] == pytest.approx(phi)
    assert a.info["cd_materials"] == ["h-BN", "B4C"]


def test_unlike_pairs_work_in_the_calculator():
    a = small(5)
    a.calc = ClusterDynamics()
    f = a.get_forces()
    assert np.all(np.isfinite(f))
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * np.abs(f).max()


def test_different_cluster_sizes_keep_a_gap():
    a = small(6, r0_inclusion=5 * units.um)
    from scipy.spatial import cKDTree
    L = a.cell.lengths()
    inc = a.arrays["material"] == 1
    tree = cKDTree(np.mod(a.positions[inc], L), boxsize=L)
    dmin, _ = tree.query(np.mod(a.positions[~inc], L))
    assert dmin.min() >= 0.9 * 0.5 * (R0 + 5 * units.um) - 1e-9


def test_bad_input():
    with pytest.raises(InputError, match="mass_fraction"):
        two_phase("h-BN", "B4C", 1.2, 12 * units.um, r0=R0, size=(16, 6, 6))
    with pytest.raises(InputError, match="inclusion_diameter"):
        two_phase("h-BN", "B4C", 0.28, 200 * units.um, r0=R0, size=(16, 6, 6))
    with pytest.raises(InputError, match="mass_fraction"):       # too many spheres for the box
        place_spheres([10.0, 10.0, 10.0], [6.0] * 8, seed=1, max_tries=200)


def test_paper_cases():
    assert PAPER_CASES["hBN-B4C"][:3] == ("h-BN", "B4C", 0.28)
    assert PAPER_CASES["B4C-hBN"][:3] == ("B4C", "h-BN", 0.25)
    assert PAPER_CASES["B4C-hBN"][3] == pytest.approx(56 * units.um)
