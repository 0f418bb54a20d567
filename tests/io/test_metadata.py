"""Analysis from files: the run's metadata in H5MD, masses, MDAnalysis, profiles, MCA pair state."""

import json
import math
import warnings

import h5py
import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.analysis.profiles import ProfileRecorder, TrajectoryProfiles, trajectory_profiles
from clusterdyn.build import fcc_packing, make_cluster_atoms
from clusterdyn.calculators import ClusterDynamics, mark_initial_bonds
from clusterdyn.errors import InputError
from clusterdyn.io import H5MDReader, H5MDWriter, format_info, h5md_info, read_h5md
from clusterdyn.materials import Material, MurnaghanCurve, get_material
from clusterdyn.md import DampedVerlet, Piston

R0 = 5 * units.um
TRAJ = "particles/trajectory"


class Tagged:
    """A do-nothing ASE constraint with describe(), as the drive family has."""

    def __init__(self, index):
        self.index = np.asarray(index, dtype=np.int64)

    def adjust_positions(self, atoms, new):
        pass

    def adjust_momenta(self, atoms, momenta):
        pass

    def adjust_forces(self, atoms, forces):
        pass

    def get_removed_dof(self, atoms):
        return 0

    def copy(self):
        return Tagged(self.index.copy())

    def describe(self):
        return {"kind": "tagged", "normal": np.array([1.0, 0.0, 0.0]), "stiffness_eV_A2": 2.5}


def soft_material():
    rho0 = 2.0 * units.g_cm3
    return Material("soft-test", rho0, MurnaghanCurve(rho0, 2.5 * units.km_s, 4.0),
                    source="test material, not in the library")


def two_material_run(path, steps=30, interval=10):
    """Pb + a non-library material, set-up bonds, damping, a piston and a tagged constraint."""
    base = fcc_packing("Pb", R0, size=(4, 3, 3), pbc=(False, True, True))
    x = base.positions[:, 0]
    mid = (x > np.median(x)).astype(np.int64)
    soft = soft_material()
    atoms = make_cluster_atoms(base.positions, ["Pb", soft], [R0, 1.02 * R0], material_id=mid,
                               cell=base.cell, pbc=base.pbc)
    atoms.info["cd_materials"] = ["Pb", soft]
    atoms.new_array("grain", (np.arange(len(atoms)) % 3).astype(np.int64))
    mark_initial_bonds(atoms, 1.2)
    calc = ClusterDynamics(rc=1.2, skin=0.1, n_table=3000, attraction="initial")
    atoms.calc = calc
    piston = x < x.min() + 0.5 * R0
    wall = x > x.max() - 0.5 * R0
    atoms.set_constraint([Piston(piston, 0.5 * units.km_s), Tagged(np.flatnonzero(wall))])
    rng = np.random.default_rng(4)
    atoms.set_velocities(rng.normal(0.0, 20 * units.m_s, (len(atoms), 3)))
    dyn = DampedVerlet(atoms, J=30)
    live = []

    def record():
        out = calc.compute(atoms, per_particle=True)
        live.append({"step": dyn.nsteps, "forces": out["forces"].copy(),
                     "energy": out["energy"], "virials": out["virials"].copy()})

    with H5MDWriter(path, atoms, dyn=dyn, parameters={"scene": "test", "u_km_s": 0.5}) as w:
        dyn.attach(w, interval=interval)
        dyn.attach(record, interval=interval)
        dyn.run(steps)
    return atoms, dyn, live, piston, wall


def test_metadata_round_trip(tmp_path):
    path = tmp_path / "two.h5md"
    atoms, dyn, live, piston, wall = two_material_run(path)
    with H5MDReader(path) as r:
        meta = r.metadata
        assert meta["version"] == 1
        assert meta["scene"] == {"scene": "test", "u_km_s": 0.5}
        assert meta["creator"]["name"] == "clusterdyn"
        c = meta["calculator"]
        assert (c["class"], c["rc"], c["skin"], c["n_table"], c["attraction"]) == \
            ("ClusterDynamics", 1.2, 0.1, 3000, "initial")
        assert meta["J"] == 30.0 and meta["dynamics"]["J"] == 30.0
        mats = meta["materials"]
        assert [m["name"] for m in mats] == ["Pb", "soft-test"]
        assert [m["r0"] for m in mats] == [R0, 1.02 * R0]
        assert mats[0]["rho0"] == get_material("Pb").rho0
        assert mats[1]["curve"] == {"kind": "murnaghan", "rho0": 2.0 * units.g_cm3,
                                    "c0": 2.5 * units.km_s, "n": 4.0}
        assert meta["units"]["length"] == "Angstrom" and meta["units"]["energy"] == "eV"
        # drives: each described by its describe() (the piston's law in display units)
        pist, tag = meta["constraints"]
        assert pist["kind"] == "Piston" and pist["direction"] == [1.0, 0.0, 0.0]
        assert pist["velocity"] == {"law": "constant", "value_km_s": pytest.approx(0.5)}
        assert tag == {"kind": "tagged", "normal": [1.0, 0.0, 0.0], "stiffness_eV_A2": 2.5,
                       "class": "Tagged", "particles": "id", "ids": tag["ids"]}
        ids = atoms.arrays["id"]
        np.testing.assert_array_equal(np.sort(pist["ids"]), np.sort(ids[piston]))
        np.testing.assert_array_equal(np.sort(tag["ids"]), np.sort(ids[wall]))
        order = np.argsort(ids)
        np.testing.assert_array_equal(r.drive_mask(), (piston | wall)[order])
        # materials: the library one by name, the other rebuilt from the file
        b = r.get_atoms(-1)
        assert b.info["cd_materials"][0] == "Pb" and b.info["cd_r0"] == [R0, 1.02 * R0]
        rebuilt = b.info["cd_materials"][1]
        assert isinstance(rebuilt, Material) and rebuilt.name == "soft-test"
        assert rebuilt.curve.pressure(1.2) == soft_material().curve.pressure(1.2)
        np.testing.assert_array_equal(b.get_masses(), atoms.get_masses()[order])   # exact
        # the calculator rebuilt from the file alone gives the live forces, energy, virials
        assert r.n_frames == len(live) == 4
        calc = r.calculator()
        for k, ref in enumerate(live):
            a = r.get_atoms(k)
            a.calc = calc
            f = a.get_forces()
            scale = np.abs(ref["forces"]).max()
            np.testing.assert_allclose(f, ref["forces"][order], rtol=0, atol=1e-10 * scale)
            assert a.get_potential_energy() == pytest.approx(ref["energy"], rel=1e-11)
            w = calc.get_property("virials", a)
            np.testing.assert_allclose(w, ref["virials"][order], rtol=0,
                                       atol=1e-10 * np.abs(ref["virials"]).max())
    with h5py.File(path, "r") as f:
        assert f[TRAJ]["mass"].shape == (len(atoms),)          # time-independent element
        assert f["parameters"].attrs["clusterdyn_metadata"] == 1
    text = format_info(path)
    assert "calculator:   ClusterDynamics, rc 1.2 r0, skin 0.1 r0, n_table 3000, attraction initial" \
        in text
    assert "materials:    0 Pb: rho0 11.34 g/cm3, c0 1.972 km/s, r0 5 um, Murnaghan cold curve (n 3)" \
        in text
    assert "1 soft-test: rho0 2 g/cm3, c0 2.5 km/s, r0 5.1 um" in text
    assert "damping:      J = 30 (Gamma = c0/(J r0))" in text
    assert "kind=Piston" in text and "[acts on" in text and "kind=tagged" in text
    d = h5md_info(path)
    json.dumps(d)                                                 # clusterdyn info --json
    assert d["metadata"]["constraints"][1]["n_particles"] == int(wall.sum())


def test_mdanalysis_universe_with_masses_no_warning(tmp_path):
    pytest.importorskip("MDAnalysis")
    from clusterdyn.io.mda import universe
    path = tmp_path / "two.h5md"
    atoms, dyn, live, piston, wall = two_material_run(path, steps=20)
    order = np.argsort(atoms.arrays["id"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")                   # any warning fails the load
        u = universe(path)
        for ts in u.trajectory:                          # reading frames warns about nothing
            pass
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(u.atoms.masses, f[TRAJ]["mass"][()])
    np.testing.assert_array_equal(u.atoms.masses, atoms.get_masses()[order])
    np.testing.assert_array_equal(u.atoms.ids, atoms.arrays["id"][order])
    np.testing.assert_array_equal(u.atoms.materials, atoms.arrays["material"][order])
    np.testing.assert_array_equal(u.atoms.grains, atoms.arrays["grain"][order])
    assert u.atoms[0].material == atoms.arrays["material"][order][0]
    assert set(u.atoms.types) == {"Pb", "soft-test"}
    assert u.trajectory.n_frames == 3
    assert u.atoms.total_mass() == pytest.approx(atoms.get_masses().sum(), rel=1e-12)
    # the parser by name, once clusterdyn.io.mda is imported
    import MDAnalysis as mda
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        u2 = mda.Universe(str(path), topology_format="CDH5MD", format="H5MD")
    np.testing.assert_array_equal(u2.atoms.masses, u.atoms.masses)


def test_trajectory_profiles_from_the_path_equal_the_live_ones(tmp_path):
    """A small piston shock: profiles live on the written frames == from the file alone."""
    atoms = fcc_packing("Al", R0, size=(12, 2, 2), pbc=(False, True, True))
    atoms.calc = calc = ClusterDynamics(rc=1.15)
    x = atoms.positions[:, 0]
    piston = x < x.min() + 1.5 * R0 - 1e-6 * R0
    atoms.set_velocities(np.random.default_rng(1).normal(0, 10 * units.m_s, (len(atoms), 3)))
    atoms.set_constraint(Piston(piston, 3 * units.km_s))
    atoms.set_momenta(atoms.get_momenta())
    dyn = DampedVerlet(atoms, J=50)
    width = math.sqrt(2) * R0
    rec = ProfileRecorder(width)

    def live():
        out = calc.compute(atoms, per_particle=True)
        rec.add(atoms, out["virials"].copy(), dyn.get_time(), exclude=piston)

    path = tmp_path / "shock.h5md"
    with H5MDWriter(path, atoms, dyn=dyn) as w:
        dyn.attach(w, interval=40)
        dyn.attach(live, interval=40)
        dyn.run(240)
    ref = rec.arrays()
    # from the path alone: default width sqrt(2) r0, calculator and piston from the metadata
    prof = trajectory_profiles(path, exclude="drives")
    assert prof["width"] == width and len(prof["t"]) == 7
    np.testing.assert_array_equal(prof["frames"], np.arange(7))
    np.testing.assert_array_equal(prof["count"], ref["count"])
    np.testing.assert_array_equal(prof["edges"], ref["edges"])      # x is exact (open axis)
    np.testing.assert_array_equal(prof["density"], ref["density"])  # masses are exact
    # velocities go through Angstrom/ps and back, periodic y, z through wrap + image: round-off
    for k in ("stress", "von_mises", "pressure", "velocity", "t"):
        scale = np.abs(ref[k]).max()
        np.testing.assert_allclose(prof[k], ref[k], rtol=0, atol=1e-13 * scale, err_msg=k)
    assert np.abs(ref["stress"]).max() > 1 * units.GPa                # a real shock
    # AnalysisBase shape: run(start, stop, step), results as attributes
    an = TrajectoryProfiles(str(path), exclude="drives", lo=ref["edges"][0],
                            hi=ref["edges"][-1]).run(start=1, step=2)
    assert an.frames == [1, 3, 5]
    np.testing.assert_allclose(an.results.stress, ref["stress"][1::2], rtol=0,
                               atol=1e-13 * np.abs(ref["stress"]).max())
    with H5MDReader(path) as r:                                         # an open reader works too
        last = TrajectoryProfiles(r, exclude="drives", lo=ref["edges"][0],
                                  hi=ref["edges"][-1]).run(start=-1).results
    np.testing.assert_array_equal(last.count, ref["count"][-1:])


def strip_metadata(path):
    """Make ``path`` look like a file written before the metadata: no /parameters sections
    but scene and dynamics, masses per frame."""
    with h5py.File(path, "a") as f:
        for k in ("calculator", "materials", "damping", "units", "constraints"):
            del f["parameters"][k]
        del f["parameters"].attrs["clusterdyn_metadata"]
        t = f[TRAJ]
        m = t["mass"][()]
        nf = t["position/value"].shape[0]
        del t["mass"]
        g = t.create_group("mass")
        g.create_dataset("value", data=np.tile(m, (nf, 1)), maxshape=(None, len(m)),
                         chunks=(1, len(m))).attrs["unit"] = "u"
        g["step"] = t["position/step"]
        g["time"] = t["position/time"]
    return m


def test_file_without_metadata_one_line_error(tmp_path):
    path = tmp_path / "old.h5md"
    atoms, dyn, live, piston, wall = two_material_run(path, steps=20)
    masses = strip_metadata(path)
    with pytest.raises(InputError) as err:
        trajectory_profiles(path)
    msg = str(err.value)
    assert "\n" not in msg and "missing /parameters/materials" in msg
    with pytest.raises(InputError) as err:
        trajectory_profiles(path, width=R0)
    msg = str(err.value)
    assert "\n" not in msg
    assert "missing /parameters/calculator, /parameters/materials" in msg
    with pytest.raises(InputError, match="missing /parameters/constraints"):
        trajectory_profiles(path, width=R0, calc=ClusterDynamics(
            rc=1.2, materials=["Pb", soft_material()], r0=[R0, 1.02 * R0], attraction="initial"),
            exclude="drives")
    # still readable: frames, masses per frame, MDAnalysis, info says what is missing
    b = read_h5md(path)
    np.testing.assert_array_equal(b.get_masses(), masses)
    assert "cd_materials" not in b.info
    assert "metadata:     missing calculator, materials, damping, constraints" in format_info(path)
    prof = trajectory_profiles(path, width=R0, calc=ClusterDynamics(
        rc=1.2, materials=["Pb", soft_material()], r0=[R0, 1.02 * R0], attraction="initial"))
    assert prof["stress"].shape[0] == 3
    # appending to such a file keeps its layout (masses per frame)
    dyn.observers.clear()                                 # the first run's writer is closed
    with H5MDWriter(path, atoms, mode="a", dyn=dyn) as w:
        dyn.attach(w, interval=10)
        dyn.run(10)
    with h5py.File(path, "r") as f:
        assert f[TRAJ]["mass/value"].shape == (4, len(atoms))
        assert "calculator" in f["parameters"]           # the appending writer describes its run


def test_mca_pair_state_every_frame(tmp_path):
    from clusterdyn.analysis.fragments import fragments
    from clusterdyn.scenes.mca_experiments import uniaxial
    captured, live = {}, []

    def record():
        st = captured["atoms"].calc.state
        live.append((st.step, st.linked_pairs(), np.sort(fragments(captured["atoms"], pairs=st).g)[::-1]))

    path = tmp_path / "mca.h5md"
    res = uniaxial(get_material("alumina"), "tension", size=(10, 3, 3), steps=1000, scatter=0.02,
                   damping=0.05, h5md=path, frames=5, prepare=lambda a: captured.update(atoms=a),
                   observers=[(record, 200)])
    assert res["h5md_path"] == path
    with H5MDReader(path) as r:
        assert r.n_frames == len(live) == 6
        np.testing.assert_array_equal(r.steps, [s for s, _, _ in live])
        counts = []
        for k, (step, pairs, frag) in enumerate(live):
            stored = r.linked_pairs(k)
            np.testing.assert_array_equal(stored, pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))])
            counts.append(len(stored))
            # fragments from the file alone: connected components of the stored bond graph
            from scipy.sparse import coo_matrix
            from scipy.sparse.csgraph import connected_components
            ids = r.get_atoms(k).arrays["id"]
            row = np.full(ids.max() + 1, -1)
            row[ids] = np.arange(len(ids))
            g = coo_matrix((np.ones(len(stored)), (row[stored[:, 0]], row[stored[:, 1]])),
                           shape=(len(ids), len(ids)))
            lab = connected_components(g, directed=False)[1]
            np.testing.assert_array_equal(np.sort(np.bincount(lab))[::-1], frag)
        assert counts[0] > counts[-1]                    # links broke during the run
        # the project's fragment analysis on the file alone (pairs from /connectivity) agrees
        from clusterdyn.analysis import FragmentAnalysis
        fa = FragmentAnalysis(r).run()
        for frag, f in zip([x for _, _, x in live], fa.results.fragments):
            np.testing.assert_array_equal(np.sort(f.g)[::-1], frag)
        a = r.get_atoms(0)
        assert a.info["mca_materials"] == ["alumina"] and a.info["mca_dim"] == 3
        assert r.metadata["calculator"]["class"] == "MCA"
        assert r.metadata["damping"]["damping"] == 0.05
        assert [c["class"] for c in r.metadata["constraints"]] == ["Piston", "Piston"]
        with pytest.raises(InputError, match="ClusterDynamics"):
            r.calculator()
    with h5py.File(path, "r") as f:
        v = f["connectivity/linked_pairs/value"]
        assert v.shape == (6, counts[0], 2) and v.dtype == np.int64
        assert f["connectivity/linked_pairs/step"] == f[TRAJ]["position/step"]   # hard link
    assert "pair state:   linked pairs per frame" in format_info(path)
    # a CD file has none, said in one line
    cd = tmp_path / "cd.h5md"
    two_material_run(cd, steps=10)
    with H5MDReader(cd) as r, pytest.raises(InputError, match="missing /connectivity/linked_pairs"):
        r.linked_pairs(0)


def test_the_cold_curves_tail_travels_with_the_file():
    """A tabulated curve's tail (murnaghan or tait) is stored and rebuilt; info names it as the material
    library does (it said "Tait tail" for every tabulated curve)."""
    from clusterdyn.io.metadata import curve_from_description, describe_curve
    from clusterdyn.materials import get_material
    for name, tail in (("Al", "murnaghan"), ("Al-tait", "tait")):
        c = get_material(name).curve
        d = describe_curve(c)
        assert d["tail"] == tail
        back = curve_from_description(d)
        assert back.tail == tail and back.n_tail == c.n_tail
        assert float(back.pressure(1.9)) == float(c.pressure(1.9))
