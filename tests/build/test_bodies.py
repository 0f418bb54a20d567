"""Bodies: rods, spheres, plates, stacks; sizes against analytic volumes, grains, velocities,
combination into a two-material ClusterDynamics run, bad input."""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing, grain_orientation, misorientation_angle
from clusterdyn.build.bodies import (combine_bodies, crystal_rotation, place, plane_spacing, plate, plate_stack,
                                     rod, sphere, translate)
from clusterdyn.errors import InputError
from clusterdyn.materials import get_material

R0 = 10 * units.um
VC = R0 ** 3 / math.sqrt(2)          # volume per cluster of the dense packing


def granularity(n, volume, surface):
    """|N v_c / V - 1| in units of the surface layer S r0 / V."""
    return abs(n * VC / volume - 1.0) / (surface * R0 / volume)


@pytest.mark.parametrize("scale", [1, 2])
def test_counts_and_sizes_against_analytic_volumes(scale):
    L, D = 20 * scale * R0, 10 * scale * R0
    r = rod("Al", R0, L, D, axis="z", center=(1 * R0, 2 * R0, 3 * R0))
    V, S = math.pi * D ** 2 / 4 * L, math.pi * D * L + math.pi * D ** 2 / 2
    assert granularity(len(r), V, S) < 0.2
    ext = np.ptp(r.positions, axis=0)
    d = R0 / math.sqrt(2)                                              # (100) plane spacing
    assert abs(ext[2] + d - L) <= 0.5 * d + 1e-9 * R0 and abs(ext[0] - D) <= 1.0 * R0  # n d nearest L
    assert np.allclose(r.positions.mean(axis=0), (R0, 2 * R0, 3 * R0), atol=0.1 * R0)
    b = r.info["bodies"][0]
    assert b["kind"] == "rod" and b["n_clusters"] == len(r) and b["porosity"] == pytest.approx(1 - len(r) * VC / V)

    s = sphere("Al", R0, D)
    V, S = math.pi / 6 * D ** 3, math.pi * D ** 2
    assert granularity(len(s), V, S) < 0.2
    assert np.linalg.norm(s.positions, axis=1).max() < D / 2
    assert np.any(np.all(np.abs(s.positions) < 1e-3 * R0, axis=1))           # a site at the centre

    for o in ("100", "110", "111"):
        p = plate("Al", R0, 0.5 * L, radius=D, axis=1, orientation=o)
        V, S = math.pi * D ** 2 * 0.5 * L, 2 * math.pi * D ** 2 + 2 * math.pi * D * 0.5 * L
        assert granularity(len(p), V, S) < 0.2
        d = plane_spacing(R0, crystal_rotation(o, 1), 1)
        n_planes = len(np.unique(np.round(p.positions[:, 1] / (1e-3 * R0))))
        assert abs(n_planes * d - 0.5 * L) <= 0.5 * d + 1e-9 * R0           # half a plane at most
    w = (1.5 * D, 2 * D)
    p = plate("Pb", R0, 0.3 * L, width=w, axis=0)
    V = 0.3 * L * w[0] * w[1]
    S = 2 * (0.3 * L * (w[0] + w[1]) + w[0] * w[1])
    assert granularity(len(p), V, S) < 0.2
    assert np.ptp(p.positions[:, 1]) < w[0] and np.ptp(p.positions[:, 2]) < w[1]


def test_granularity_shrinks_with_size():
    small = rod("Al", R0, 12 * R0, 6 * R0)
    big = rod("Al", R0, 48 * R0, 24 * R0)
    err = [abs(len(a) * VC / a.info["bodies"][0]["volume_A3"] - 1) for a in (small, big)]
    assert err[1] < err[0] and err[1] < 0.02


def test_orientation_along_axis():
    R = crystal_rotation("111", "y")
    assert np.allclose(R[1], np.ones(3) / math.sqrt(3))       # [111] along y
    assert np.isclose(np.linalg.det(R), 1.0)
    a = rod("Al", R0, 12 * R0, 8 * R0, axis=1, orientation="111")
    assert np.allclose(a.info["grain_rotations"][0], R)
    # the rod is that lattice: crystal coordinates of the site differences are fcc vectors
    c = (a.positions - a.positions[0]) @ R / (math.sqrt(2) * R0) * 2
    assert np.allclose(c, np.round(c), atol=1e-6) and np.all(np.round(c).sum(axis=1) % 2 == 0)


@pytest.fixture(scope="module")
def poly_rod():
    return rod("Al", R0, 30 * R0, 14 * R0, axis=2, grain_size=9 * R0, seed=5,
               velocity=(0, 0, -0.3 * units.km_s))


def test_polycrystal_rod_orientations_confirmed_by_spglib(poly_rod):
    a = poly_rod
    b = a.info["bodies"][0]
    assert b["structure"] == "polycrystal" and b["n_grains"] >= 5 and 0.02 < b["porosity"] < 0.3
    # combined behind a sphere: grain ids and the rotation table shift together
    s = sphere("Al", R0, 8 * R0, center=(0, 0, -20 * R0))
    both = combine_bodies([s, a])
    off = both.info["bodies"][1]["grain_offset"]
    assert off == 1
    rots = both.info["grain_rotations"]
    checked = 0
    for g in np.unique(a.arrays["grain"]):
        if np.count_nonzero(a.arrays["grain"] == g) < 400:      # grains with an interior (not surface slivers)
            continue
        R, d = grain_orientation(both, g + off, details=True)
        assert d["spacegroup"] == "Fm-3m (225)"
        assert misorientation_angle(R, rots[g + off]) < 0.5
        checked += 1
    assert checked >= 5


def test_velocities_and_mass_choices(poly_rod):
    v = np.array([0, 0, -0.3 * units.km_s])
    assert np.allclose(poly_rod.get_velocities(), v)
    dense = rod("Al", R0, 30 * R0, 14 * R0, axis=2, grain_size=9 * R0, seed=5, velocity=v, mass="dense")
    np.testing.assert_array_equal(dense.positions, poly_rod.positions)
    b, bd = poly_rod.info["bodies"][0], dense.info["bodies"][0]
    rho0 = get_material("Al").rho0
    V = bd["volume_A3"]
    # cluster masses: the packing is lighter than the solid by its porosity; dense: the solid's mass
    assert poly_rod.get_masses().sum() == pytest.approx((1 - b["porosity"]) * rho0 * V, rel=2e-3)
    assert dense.get_masses().sum() == pytest.approx(rho0 * V, rel=2e-3)
    assert bd["mass_factor"] == pytest.approx(1 / (1 - b["porosity"]))
    assert np.allclose(dense.get_momenta().sum(axis=0), dense.get_masses().sum() * v)
    assert bd["density_g_cm3"] == pytest.approx(rho0 / units.g_cm3)


def test_place_and_stack():
    pl = plate("Al", R0, 3 * R0, radius=8 * R0, axis=2, center=(5 * R0, 0, 0))
    s = place(sphere("Al", R0, 6 * R0), pl, axis=2, gap=0.5 * R0)
    gap = (s.positions[:, 2] - 0.5 * R0).min() - (pl.positions[:, 2] + 0.5 * R0).max()
    assert gap == pytest.approx(0.5 * R0)
    assert np.allclose(s.info["bodies"][0]["center"][:2], (5 * R0, 0))          # aligned on the plate's axis
    below = place(s, pl, axis="z", gap=2 * R0, side=-1)
    assert (pl.positions[:, 2] - 0.5 * R0).min() - (below.positions[:, 2] + 0.5 * R0).max() == pytest.approx(2 * R0)

    st = plate_stack([("Al", 3 * R0), ("Pb", 2 * R0), ("Al", 4 * R0)], R0, 8 * R0, gaps=[0.0, 2 * R0], axis=2,
                     velocity=(0, 0, 0.1 * units.km_s))
    assert st.info["cd_materials"] == ["Al", "Pb"] and st.info["cd_r0"] == [R0, R0]
    body, mat = st.arrays["body"], st.arrays["material"]
    assert set(zip(body, mat)) == {(0, 0), (1, 1), (2, 0)}
    z = [st.positions[body == k, 2] for k in range(3)]
    assert z[1].min() - z[0].max() == pytest.approx(1.0 * R0)         # in contact: clusters at r0
    assert z[2].min() - z[1].max() == pytest.approx(3.0 * R0)         # gap 2 r0 between the spheres
    assert z[0].min() == pytest.approx(3 * R0 / 2 - 1.5 * math.sqrt(2) / 2 * R0)   # 4 planes centred in [0, 3 r0]
    np.testing.assert_array_equal(st.arrays["id"], np.arange(len(st)))
    assert np.allclose(st.get_velocities()[:, 2], 0.1 * units.km_s)


def test_combined_two_materials_run_conserves_energy():
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.md import DampedVerlet
    pl = plate("Pb", R0, 2 * R0, radius=6 * R0, axis=2)
    sp = place(sphere("Al", R0, 6 * R0, velocity=(0, 0, -2 * units.km_s)), pl, axis=2, gap=0.5 * R0)
    atoms = combine_bodies([pl, sp])
    assert atoms.info["cd_materials"] == ["Pb", "Al"] and not atoms.pbc.any()
    assert np.array_equal(np.unique(atoms.arrays["material"][atoms.arrays["body"] == 1]), [1])
    atoms.calc = ClusterDynamics()
    dyn = DampedVerlet(atoms, J=None)
    assert len(atoms.calc.potentials) == 2
    dyn.run(1)
    k0 = atoms.get_kinetic_energy()
    e0 = k0 + dyn.potential_energy
    dyn.run(220)
    k1 = atoms.get_kinetic_energy()
    zgap = atoms.positions[atoms.arrays["body"] == 1, 2].min() - atoms.positions[atoms.arrays["body"] == 0, 2].max()
    assert zgap < 0.2 * R0 and k1 < 0.9 * k0               # the sphere has hit the plate and slowed
    assert abs(k1 + dyn.potential_energy - e0) < 3e-3 * k0   # energy conserved (undamped)
    # momentum: no external force
    p = atoms.get_momenta().sum(axis=0)
    assert np.allclose(p, sp.get_momenta().sum(axis=0), atol=1e-9 * np.abs(p).max())


def test_translate_keeps_info():
    s = sphere("Al", R0, 6 * R0, grain_size=3.5 * R0, seed=1)
    t = translate(s, (R0, 0, 0))
    assert np.allclose(t.positions - s.positions, (R0, 0, 0))
    assert np.allclose(np.asarray(t.info["grain_seeds"]) - s.info["grain_seeds"], (R0, 0, 0))


@pytest.mark.parametrize("call, arg", [
    (lambda: rod("Al", R0, -1.0, 5 * R0), "length"),
    (lambda: rod("Al", R0, 5 * R0, 0.0), "diameter"),
    (lambda: sphere("Al", 0.0, 5 * R0), "r0"),
    (lambda: plate("Al", R0, 2 * R0), "radius"),
    (lambda: plate("Al", R0, 2 * R0, radius=3 * R0, width=3 * R0), "radius"),
    (lambda: plate("Al", R0, 2 * R0, width=(3 * R0, -1)), "width"),
    (lambda: rod("Al", R0, 5 * R0, 5 * R0, axis=3), "axis"),
    (lambda: rod("Al", R0, 5 * R0, 5 * R0, mass="heavy"), "mass"),
    (lambda: rod("Al", R0, 5 * R0, 5 * R0, velocity=(1, 2)), "velocity"),
    (lambda: rod("Al", R0, 9 * R0, 9 * R0, grain_size=4 * R0, orientation="110"), "orientation"),
    (lambda: plate_stack([("Al", R0)] * 2, R0, 4 * R0, gaps=-R0), "gaps"),
    (lambda: plate_stack([], R0, 4 * R0), "layers"),
    (lambda: combine_bodies([sphere("Al", R0, 6 * R0), sphere("Pb", R0, 6 * R0, center=(3 * R0, 0, 0))]),
     "bodies"),
    (lambda: place(sphere("Al", R0, 4 * R0), sphere("Al", R0, 4 * R0), axis=0, gap=-R0), "gap"),
    (lambda: combine_bodies([sphere("Al", R0, 4 * R0), fcc_packing("Al", R0, pbc=True)]), "bodies[1]"),
])
def test_bad_input_refused_in_one_line(call, arg):
    with pytest.raises(InputError) as exc:
        call()
    assert exc.value.argument == arg
    assert "\n" not in str(exc.value)


def test_combine_accepts_any_clusterdyn_atoms():
    block = fcc_packing("Pb", 2 * R0, size=(3, 3, 3))                 # another r0: a third material id
    s = place(sphere("Al", R0, 5 * R0), block, axis=0, gap=0.0)
    p = plate("Al", R0, 2 * R0, radius=3 * R0, center=(-20 * R0, 0, 0))
    both = combine_bodies([block, s, p])
    assert both.info["cd_materials"] == ["Pb", "Al"] and both.info["cd_r0"] == [2 * R0, R0]
    assert [b["body"] for b in both.info["bodies"]] == [0, 1, 2] and both.info["bodies"][0]["kind"] == "block"
    assert np.bincount(both.arrays["body"]).tolist() == [len(block), len(s), len(p)]
    # ids: offset by the earlier bodies' id ranges, all distinct
    assert len(np.unique(both.arrays["id"])) == len(both)
    assert "grain_rotations" not in both.info                             # the block has no grain table
