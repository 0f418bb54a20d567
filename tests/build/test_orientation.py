"""Grain orientations: recovery with spglib confirmation, misorientation, Mackenzie distribution."""

import math

import numpy as np
import pytest
from ase.build import bulk
from scipy.spatial.transform import Rotation

from clusterdyn import units
from clusterdyn.build import make_cluster_atoms
from clusterdyn.build.orientation import (MACKENZIE_MAX_DEG, cubic_rotations, fit_fcc_rotation,
                                          grain_orientation, mackenzie_pdf, misorientation_angle,
                                          misorientation_distribution, neighbouring_grains, FCC_NN)
from clusterdyn.build.polycrystal import polycrystal
from clusterdyn.errors import InputError

R0 = 10 * units.um


@pytest.fixture(scope="module")
def known():
    """27 grains on a jittered 3x3x3 periodic grid with known random rotations."""
    rng = np.random.default_rng(11)
    L = 3 * 9.0 * R0
    grid = (np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * (L / 3)
    seeds = np.mod(grid + rng.normal(scale=0.08 * L / 3, size=grid.shape), L)
    rots = Rotation.random(27, rng=rng)
    return polycrystal("Al", R0, size=(L, L, L), seeds=seeds, rotations=rots, pbc=True), rots.as_matrix()


def test_cubic_group():
    g = cubic_rotations()
    assert g.shape == (24, 3, 3)
    assert np.allclose(np.linalg.det(g), 1.0)
    # closed under multiplication
    prods = np.einsum("aij,bjk->abik", g, g).reshape(-1, 9)
    assert all(np.any(np.all(np.isclose(p, g.reshape(-1, 9)), axis=1)) for p in prods)


def test_misorientation_modulo_cubic_symmetry():
    rng = np.random.default_rng(0)
    R = Rotation.random(50, rng=rng).as_matrix()
    S = cubic_rotations()[rng.integers(0, 24, 50)]
    assert np.allclose(misorientation_angle(R, R @ S), 0.0, atol=1e-5)
    t = Rotation.from_rotvec([0, 0, math.radians(30)]).as_matrix()
    assert misorientation_angle(np.eye(3), t) == pytest.approx(30.0)
    assert misorientation_angle(np.eye(3), Rotation.from_rotvec([0, 0, math.radians(80)]).as_matrix()) \
        == pytest.approx(10.0)
    ang = misorientation_angle(np.broadcast_to(np.eye(3), R.shape), R)
    assert ang.max() <= MACKENZIE_MAX_DEG + 1e-6
    assert MACKENZIE_MAX_DEG == pytest.approx(62.80, abs=0.01)


def test_mackenzie_density():
    th = np.linspace(0, 63, 631)
    p = mackenzie_pdf(th)
    assert np.trapezoid(p, th) == pytest.approx(1.0, abs=2e-3)
    assert np.trapezoid(th * p, th) == pytest.approx(40.7, abs=0.1)          # Mackenzie's mean
    small = np.array([5.0, 20.0, 40.0])                                       # exact below 45 degrees
    exact = 24 / math.pi * (1 - np.cos(np.radians(small))) * math.pi / 180
    assert np.allclose(mackenzie_pdf(small), exact, rtol=1e-12)
    assert th[np.argmax(p)] == pytest.approx(45.0, abs=1.0)
    # against random pairs
    R = Rotation.random(40000, rng=np.random.default_rng(5)).as_matrix()
    ang = misorientation_angle(R[::2], R[1::2])
    h, e = np.histogram(ang, bins=np.arange(0, 62.5, 5), density=True)
    assert np.allclose(h, mackenzie_pdf(0.5 * (e[1:] + e[:-1])), atol=2.5e-3)


def test_fit_rotation_from_noisy_neighbour_vectors():
    rng = np.random.default_rng(3)
    R = Rotation.random(random_state=4).as_matrix()
    v = np.tile(FCC_NN @ R.T, (10, 1)) + rng.normal(scale=0.02, size=(120, 3))
    Rf, rms = fit_fcc_rotation(v)
    assert misorientation_angle(R, Rf) < 0.5
    assert 0.2 < rms < 3.0


def test_recover_known_rotations_with_spglib(known):
    atoms, rots = known
    assert atoms.info["polycrystal"]["n_grains"] == 27
    errors = []
    for g in range(27):
        R, d = grain_orientation(atoms, g, details=True)
        assert d["spacegroup"] == "Fm-3m (225)"
        errors.append(misorientation_angle(R, rots[g]))
    assert max(errors) < 0.5


def test_recover_after_thermal_noise(known):
    atoms, rots = known
    noisy = atoms.copy()
    noisy.positions += np.random.default_rng(1).normal(scale=0.02 * R0, size=noisy.positions.shape)
    for g in range(0, 27, 3):
        R = grain_orientation(noisy, g)
        assert misorientation_angle(R, rots[g]) < 0.5


def test_not_fcc_refused():
    hcp = bulk("Mg", "hcp", a=1.0, c=math.sqrt(8 / 3), orthorhombic=True).repeat((6, 4, 4))
    pos = hcp.positions * R0
    atoms = make_cluster_atoms(pos, ["Al"], [R0], cell=hcp.cell * R0, pbc=True)
    atoms.new_array("grain", np.zeros(len(atoms), dtype=np.int64))
    with pytest.raises(InputError, match="225"):
        grain_orientation(atoms, 0)
    with pytest.raises(InputError, match="grain"):
        grain_orientation(atoms, 5)


def test_misorientation_distribution(known):
    atoms, rots = known
    pairs, contacts = neighbouring_grains(atoms)
    assert len(pairs) >= 27 * 3 and np.all(pairs[:, 0] < pairs[:, 1]) and np.all(contacts > 0)
    md = misorientation_distribution(atoms)
    assert len(md["angles_deg"]) == len(pairs)
    assert np.all(md["angles_deg"] <= MACKENZIE_MAX_DEG + 1e-6)
    assert md["mackenzie_mean_deg"] == pytest.approx(40.7, abs=0.1)
    assert 30 < md["mean_deg"] < 50
    # the same from recovered orientations
    rec = np.array([grain_orientation(atoms, g) for g in range(27)])
    md2 = misorientation_distribution(atoms, rotations=rec)
    assert np.allclose(md2["angles_deg"], md["angles_deg"], atol=0.5)


def test_spacegroup_of_a_111_packing_in_angstrom_and_bulk_atoms():
    """spglib's tolerance is a length: spacegroup() takes it in r0, so a perfect [111] packing at
    r0 = 5 um is Fm-3m at a tolerance that fails when handed to spglib in Angstrom; Atoms from
    ase.build.bulk (no 'grain', no 'cd_r0') go through grain_orientation as one grain."""
    import spglib
    from ase.build import bulk
    from clusterdyn import units
    from clusterdyn.build import fcc_packing, spacegroup
    a = fcc_packing("Al", r0=5 * units.um, size=(6, 6, 6), pbc=True, direction="111")
    raw = (a.cell[:], a.get_scaled_positions(), a.get_atomic_numbers())
    assert spglib.get_spacegroup(raw, symprec=1e-3 * 5 * units.um) is None     # the pitfall
    assert spacegroup(a, symprec=1e-3) == "Fm-3m (225)"
    cu = bulk("Cu", "fcc", a=3.6, cubic=True).repeat(4)
    R = grain_orientation(cu, 0)
    assert misorientation_angle(R, np.eye(3)) < 1e-3            # degrees: the cube axes, modulo cubic symmetry
    assert spacegroup(cu) == "Fm-3m (225)"
