"""H5MDWriter / H5MDReader / read_h5md: MDAnalysis compatibility, round trips, append, crash safety."""

import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import h5py
import numpy as np
import pytest
from ase import Atoms, units
from ase.calculators.emt import EMT
from ase.md.verlet import VelocityVerlet

from cdio_helpers import Recorder, make_atoms, run_md
from clusterdyn import units as cu
from clusterdyn.errors import InputError
from clusterdyn.io import H5MDReader, H5MDWriter, read_checkpoint, read_h5md, write_checkpoint

TRAJ = "particles/trajectory"


def universe(path):
    mda = pytest.importorskip("MDAnalysis")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # "no reference attributes to guess types from"
        return mda.Universe(str(path))       # no topology: found via particles/trajectory


# --------------------------------------------------------------------------- MDAnalysis
def test_mdanalysis_reads_without_topology(md_file):
    path, atoms, dyn, rec = md_file
    u = universe(path)
    assert u.atoms.n_atoms == len(atoms)
    assert u.trajectory.n_frames == len(rec.frames) == 6
    for ts, ref in zip(u.trajectory, rec.frames):
        # MDAnalysis holds float32; compare at float32 precision
        # periodic box: MDAnalysis reads the wrapped positions
        L = np.diag(np.asarray(atoms.cell[:]))
        wrapped = ref["positions"] - np.floor(ref["positions"] / L) * L
        np.testing.assert_allclose(ts.positions, wrapped, rtol=1e-6, atol=1e-5)
        np.testing.assert_allclose(ts.velocities, ref["velocities"] * cu.VEL_TO_A_PER_PS,
                                   rtol=1e-5, atol=1e-4)                # Angstrom/ps
        np.testing.assert_allclose(ts.forces, ref["forces"] * cu.FORCE_TO_KJMOL_A,
                                   rtol=1e-5, atol=1e-4)                # kJ/(mol Angstrom)
        a, b, c = np.linalg.norm(ref["cell"], axis=1)
        np.testing.assert_allclose(ts.dimensions, [a, b, c, 90, 90, 90], rtol=1e-6)
        assert ts.time == pytest.approx(ref["time"] * cu.TIME_TO_PS, rel=1e-12, abs=1e-15)
        assert ts.data["step"] == ref["step"]
        assert ts.data["potential_energy"] == pytest.approx(ref["energy"] * cu.ENERGY_TO_KJMOL,
                                                            rel=1e-12)
        assert ts.data["kinetic_energy"] == pytest.approx(ref["ekin"] * cu.ENERGY_TO_KJMOL,
                                                          rel=1e-12)
    # observables/dt gives MDAnalysis the frame spacing (else it warns and assumes 1 ps)
    for ts in u.trajectory:
        assert ts.dt == pytest.approx(2 * 2 * units.fs * cu.TIME_TO_PS, rel=1e-12)   # interval 2
    assert [ts.data["step"] for ts in u.trajectory] == [0, 2, 4, 6, 8, 10]


def test_file_layout_units_and_hard_links(md_file):
    path, atoms, dyn, rec = md_file
    n = len(atoms)
    with h5py.File(path, "r") as f:
        assert list(f["h5md"].attrs["version"]) == [1, 1]
        assert f["h5md/creator"].attrs["name"] == "clusterdyn"
        assert "name" in f["h5md/author"].attrs
        assert list(f["particles"]) == ["trajectory"]       # MDAnalysis takes the first group
        t = f[TRAJ]
        assert t["box"].attrs["dimension"] == 3
        assert list(t["box"].attrs["boundary"]) == ["periodic"] * 3
        assert t["box/edges/value"].shape == (6, 3, 3)
        units_ = {"position": "Angstrom", "velocity": "Angstrom ps-1",
                  "force": "kJ mol-1 Angstrom-1", "box/edges": "Angstrom"}
        for name, unit in units_.items():
            assert t[name]["value"].attrs["unit"] == unit
        assert t["position/time"].attrs["unit"] == "ps"
        for name in ("position", "velocity", "force"):
            v = t[name]["value"]
            assert v.shape == (6, n, 3) and v.dtype == np.float64
            assert v.maxshape[0] is None and v.chunks is not None and v.compression == "gzip"
        assert t["species/value"].shape == (6, n)
        assert t["mass"].shape == (n,) and t["mass"].attrs["unit"] == "u"   # time-independent
        assert set(t) >= {"id", "material"}
        # step/time exist once and are hard-linked everywhere (same HDF5 object)
        for g in ("velocity", "force", "species", "id", "material", "box/edges"):
            assert t[g]["step"] == t["position/step"] and t[g]["time"] == t["position/time"]
        for name in ("kinetic_energy", "potential_energy", "total_energy"):
            obs = f["observables"][name]
            assert obs["value"].shape == (6,) and obs["value"].attrs["unit"] == "kJ mol-1"
            assert obs["step"] == t["position/step"]
        assert f["observables/dt/value"].attrs["unit"] == "ps"
        np.testing.assert_allclose(f["observables/dt/value"][:], 4 * units.fs * cu.TIME_TO_PS)
        assert "VelocityVerlet" in f["parameters/dynamics"][()].decode()
        assert b'"r0": 5.0' in f["parameters/scene"][()]


# --------------------------------------------------------------------------- read_h5md
def test_read_h5md_round_trip(md_file):
    path, atoms, dyn, rec = md_file
    with H5MDReader(path) as r:
        assert len(r) == 6 and r.n_particles == len(atoms)
        np.testing.assert_array_equal(r.steps, [0, 2, 4, 6, 8, 10])
        assert set(r.per_particle) == {"id", "material"}
        assert r.parameters == {"r0": 5.0, "material": "Cu"}
        frames = list(r)
    for b, ref in zip(frames, rec.frames):
        # unwrapped from wrapped position + image: equal to round-off
        np.testing.assert_allclose(b.positions, ref["positions"], rtol=0, atol=1e-12 * np.abs(
            ref["positions"]).max() + 1e-12)
        np.testing.assert_allclose(b.get_velocities(), ref["velocities"], rtol=1e-13, atol=1e-16)
        np.testing.assert_allclose(b.get_forces(), ref["forces"], rtol=1e-13, atol=1e-14)
        assert b.get_potential_energy() == pytest.approx(ref["energy"], rel=1e-13)
        np.testing.assert_array_equal(b.cell[:], ref["cell"])
        assert b.pbc.all()
        np.testing.assert_array_equal(b.numbers, ref["numbers"])
        np.testing.assert_array_equal(b.get_masses(), ref["masses"])
        np.testing.assert_array_equal(b.arrays["id"], ref["id"])
        np.testing.assert_array_equal(b.arrays["material"], ref["material"])
        assert b.info["step"] == ref["step"]
        assert b.info["time"] == pytest.approx(ref["time"], rel=1e-13)
    last = read_h5md(path)                       # default: last frame
    assert last.info["step"] == 10
    np.testing.assert_allclose(read_h5md(path, frame=0).positions, rec.frames[0]["positions"],
                               rtol=0, atol=1e-12)        # wrapped + image: equal to round-off
    with pytest.raises(InputError, match="frame"):
        read_h5md(path, frame=6)
    # slices as ase.io.read takes them: a list of frames
    assert [a.info["step"] for a in read_h5md(path, ":")] == [0, 2, 4, 6, 8, 10]
    assert [a.info["step"] for a in read_h5md(path, "-2:")] == [8, 10]
    with H5MDReader(path) as r:
        assert [a.info["step"] for a in r[::2]] == [0, 4, 8]
    with pytest.raises(InputError, match="frame"):
        read_h5md(path, "first")


def test_rows_follow_ids_when_atoms_are_reordered(tmp_path):
    atoms = make_atoms()
    path = tmp_path / "sorted.h5md"
    with H5MDWriter(path, atoms) as w:
        w.write()
        perm = np.random.default_rng(3).permutation(len(atoms))
        for name in list(atoms.arrays):
            atoms.arrays[name] = atoms.arrays[name][perm]
        w.write()
    with h5py.File(path, "r") as f:
        pos = f[TRAJ]["position/value"][:]
        ids = f[TRAJ]["id/value"][:]
        np.testing.assert_array_equal(pos[0], pos[1])
        np.testing.assert_array_equal(ids[0], np.sort(atoms.arrays["id"]))
        np.testing.assert_array_equal(f[TRAJ]["position/step"][:], [0, 1])   # counted frames


def test_per_particle_series_and_observables(tmp_path):
    mda = pytest.importorskip("MDAnalysis")
    atoms = make_atoms(shuffle_ids=False)
    n = len(atoms)
    atoms.new_array("grain", np.arange(n) % 4)
    path = tmp_path / "extra.h5md"
    stress = lambda a: np.tile(np.arange(6.0), (len(a), 1)) * a.positions[:, :1]   # (N, 6)
    with H5MDWriter(path, atoms,
                    per_particle={"stress": (stress, "eV Angstrom-3"),
                                  "links": lambda a: np.full(len(a), 12, dtype=np.int32),
                                  "material": None},
                    observables={"piston_force": (lambda a: 1.5, "kJ mol-1 Angstrom-1"),
                                 "com": lambda a: a.get_center_of_mass(),
                                 "total_energy": None}) as w:
        for k in range(3):
            atoms.positions += 0.01
            w.write(step=10 * k, time=k * units.fs)
    with h5py.File(path, "r") as f:
        t = f[TRAJ]
        assert t["stress/value"].shape == (3, n, 6)
        assert t["stress/value"].attrs["unit"] == "eV Angstrom-3"
        assert t["links/value"].dtype == np.int32
        assert t["grain/value"].shape == (3, n)
        assert "material" not in t
        assert set(f["observables"]) == {"dt", "kinetic_energy", "potential_energy",
                                         "piston_force", "com"}
        assert f["observables/com/value"].shape == (3, 3)
    u = universe(path)
    for k, ts in enumerate(u.trajectory):
        assert ts.data["piston_force"] == 1.5
        assert ts.data["com"].shape == (3,)
        assert ts.data["step"] == 10 * k
    b = read_h5md(path, 1)
    np.testing.assert_array_equal(b.arrays["stress"], stress(b))
    np.testing.assert_array_equal(b.arrays["grain"], np.arange(n) % 4)
    assert b.info["time"] == pytest.approx(units.fs)
    del mda


def test_no_calculator_open_boundaries(tmp_path):
    atoms = Atoms("Ar3", positions=[[0, 0, 0], [3, 0, 0], [0, 3, 0]])
    atoms.set_velocities(np.ones((3, 3)) * 1e-3)
    path = tmp_path / "free.h5md"
    with H5MDWriter(path, atoms) as w:
        w.write()
        atoms.positions[0, 0] -= 100.0          # flies far away: no box, nothing wrapped
        w.write()
    with h5py.File(path, "r") as f:
        t = f[TRAJ]
        assert "force" not in t and "edges" not in t["box"]
        assert list(t["box"].attrs["boundary"]) == ["none"] * 3
        assert sorted(f["observables"]) == ["dt", "kinetic_energy"]
    u = universe(path)
    assert u.trajectory.n_frames == 2 and u.trajectory.ts.dimensions is None
    u.trajectory[1]
    assert u.atoms.positions[0, 0] == pytest.approx(-100.0)
    b = read_h5md(path)
    assert not b.pbc.any() and b.cell.rank == 0 and b.calc is None
    assert b.positions[0, 0] == -100.0


def test_periodic_positions_are_wrapped_with_images(tmp_path):
    """Periodic axes: wrapped positions + integer images (H5MD); read_h5md unwraps them."""
    atoms = make_atoms()
    atoms.positions[0] += atoms.cell[0] * 1.5          # outside the box: image +1 along x
    atoms.positions[1] -= atoms.cell[1] * 2.25         # image -3 along y
    path = tmp_path / "wrapped.h5md"
    with H5MDWriter(path, atoms) as w:
        w.write()
    with h5py.File(path, "r") as f:
        pos = f[TRAJ]["position/value"][0]
        img = f[TRAJ]["image/value"][0]
        L = np.diag(f[TRAJ]["box/edges/value"][0])
    order = np.argsort(atoms.arrays["id"])
    assert np.all(pos >= -1e-9) and np.all(pos < L + 1e-9)
    np.testing.assert_allclose(pos + img * L, atoms.positions[order], rtol=0, atol=1e-9)
    r0 = int(np.flatnonzero(atoms.arrays["id"][order] == atoms.arrays["id"][0])[0])
    r1 = int(np.flatnonzero(atoms.arrays["id"][order] == atoms.arrays["id"][1])[0])
    frac = atoms.positions / np.diag(np.asarray(atoms.cell[:]))
    assert img[r0][0] == np.floor(frac[0, 0]) == 1
    assert img[r1][1] == np.floor(frac[1, 1]) <= -2
    b = read_h5md(path)
    np.testing.assert_allclose(b.positions, atoms.positions[order], rtol=0, atol=1e-9)
    assert "image" not in b.arrays


def test_unwrapped_on_request(tmp_path):
    """wrap=False writes positions exactly as ASE holds them, without images."""
    atoms = make_atoms()
    atoms.positions[0] += atoms.cell[0] * 1.5
    path = tmp_path / "unwrapped.h5md"
    with H5MDWriter(path, atoms, wrap=False) as w:
        w.write()
    b = read_h5md(path)
    row = int(np.flatnonzero(b.arrays["id"] == atoms.arrays["id"][0])[0])
    np.testing.assert_array_equal(b.positions[row], atoms.positions[0])
    with h5py.File(path, "r") as f:
        assert "image" not in f[TRAJ]


# --------------------------------------------------------------------------- append / restart
def test_restart_from_checkpoint_appends_without_duplicates(tmp_path):
    # reference: one uninterrupted run of 12 steps
    ref_path = tmp_path / "ref.h5md"
    run_md(ref_path, steps=12, interval=2)

    # interrupted run: 12 steps with a checkpoint at step 6 ("crash" after step 12 anyway)
    path, chk = tmp_path / "run.h5md", tmp_path / "run.chk"
    atoms = make_atoms()
    dyn = VelocityVerlet(atoms, timestep=2 * units.fs)
    with H5MDWriter(path, atoms, dyn=dyn) as w:
        dyn.attach(w, interval=2)
        dyn.attach(lambda: write_checkpoint(chk, atoms, {"step": dyn.nsteps}), interval=-6)
        dyn.run(10)                          # frames 0..10; frames 8, 10 must be dropped
    atoms2, state = read_checkpoint(chk)
    assert state["step"] == 6
    atoms2.calc = EMT()
    dyn2 = VelocityVerlet(atoms2, timestep=2 * units.fs)
    dyn2.nsteps = state["step"]
    with H5MDWriter(path, atoms2, dyn=dyn2, mode="a", restart_step=state["step"]) as w:
        assert w.nframes == 4                # 0, 2, 4, 6
        dyn2.attach(w, interval=2)
        dyn2.run(6)                          # steps 8, 10, 12
    with h5py.File(path, "r") as f, h5py.File(ref_path, "r") as g:
        np.testing.assert_array_equal(f[TRAJ]["position/step"][:], [0, 2, 4, 6, 8, 10, 12])
        np.testing.assert_array_equal(f[TRAJ]["position/time"][:], g[TRAJ]["position/time"][:])
        for name in ("position", "velocity", "force", "box/edges", "id"):
            new, ref = f[TRAJ][name]["value"][:], g[TRAJ][name]["value"][:]
            assert new.shape == ref.shape
            np.testing.assert_array_equal(new[:4], ref[:4])       # kept frames untouched
            # appended frames continue the same trajectory (EMT's neighbour list is rebuilt
            # on restart, so its sums may differ in the last bit: not an io matter)
            np.testing.assert_allclose(new[4:], ref[4:], rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(f["observables/potential_energy/value"][:],
                                   g["observables/potential_energy/value"][:], rtol=1e-11)
    u = universe(path)
    assert u.trajectory.n_frames == 7


def test_append_mode_rules(tmp_path):
    atoms = make_atoms()
    path = tmp_path / "a.h5md"
    with H5MDWriter(path, atoms) as w:          # counted frames: steps 0, 1, 2
        for _ in range(3):
            w.write()
    with H5MDWriter(path, atoms, mode="a") as w:
        assert w.nframes == 3
        w.write()                                # continues at step 3
        atoms.positions += 0.5
        w.write(step=3)                          # same step again: replaces, no duplicate
        with pytest.raises(InputError, match="step"):
            w.write(step=1)
        assert w.truncate_after_step(1) == 2
        w.write()                                # step 2 again
    with H5MDReader(path) as r:
        np.testing.assert_array_equal(r.steps, [0, 1, 2])
        assert r.n_frames == 3
    with H5MDWriter(path, atoms, mode="a", observables={"extra": lambda a: 0.0}) as w:
        with pytest.raises(InputError, match="observables not in the file"):
            w.write()
    atoms2 = make_atoms()[:10]
    with pytest.raises(InputError, match="10 particles"):
        H5MDWriter(path, atoms2, mode="a")
    assert read_h5md(path).info["step"] == 2     # file untouched by the refused writers
    # 'a' on a missing file, or on one created without frames, starts a new trajectory
    for fresh in (tmp_path / "new.h5md", tmp_path / "empty.h5md"):
        if fresh.name == "empty.h5md":
            H5MDWriter(fresh, atoms).close()
        with H5MDWriter(fresh, atoms, mode="a") as w:
            w.write()
            w.write()
        with H5MDReader(fresh) as r:
            np.testing.assert_array_equal(r.steps, [0, 1])


def test_invalid_arguments(tmp_path):
    atoms = make_atoms()
    with pytest.raises(InputError, match="mode='x'"):
        H5MDWriter(tmp_path / "x.h5md", atoms, mode="x")
    with pytest.raises(InputError, match="compression"):
        H5MDWriter(tmp_path / "x.h5md", atoms, compression="zstd")
    with pytest.raises(InputError, match="per_particle"):
        H5MDWriter(tmp_path / "x.h5md", atoms, per_particle={"position": "id"})
    with pytest.raises(InputError, match="nope"):
        H5MDWriter(tmp_path / "x.h5md", atoms, per_particle={"g": "nope"})
    with pytest.raises(InputError, match="restart_step"):
        H5MDWriter(tmp_path / "x.h5md", atoms, restart_step=3)
    with H5MDWriter(tmp_path / "y.h5md", atoms) as w:
        w.write()
        atoms.arrays["id"][1] = atoms.arrays["id"][0]
        with pytest.raises(InputError, match="duplicate id"):
            w.write()


def test_reader_errors(tmp_path):
    with pytest.raises(InputError, match="missing.h5md"):
        read_h5md(tmp_path / "missing.h5md")
    junk = tmp_path / "junk.h5md"
    junk.write_bytes(os.urandom(2000))
    with pytest.raises(InputError, match="junk.h5md"):
        read_h5md(junk)
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f["x"] = 1
    with pytest.raises(InputError, match="no /particles"):
        read_h5md(plain)


# --------------------------------------------------------------------------- crash safety
WRITER_SCRIPT = textwrap.dedent("""
    import sys, time
    import numpy as np
    from ase import Atoms, units
    from clusterdyn.io import H5MDWriter
    n = 50
    atoms = Atoms(numbers=np.full(n, 29), positions=np.zeros((n, 3)), cell=[20.0] * 3, pbc=True)
    base = np.random.default_rng(1).uniform(0, 20, (n, 3))
    w = H5MDWriter(sys.argv[1], atoms, observables={"k": lambda a: float(a.info["k"])})
    k = 0
    while True:
        atoms.positions = base + 0.01 * k
        atoms.set_velocities(np.full((n, 3), 1e-3 * k))
        atoms.info["k"] = k
        w.write(step=5 * k, time=5 * k * units.fs)
        k += 1
        print(k, flush=True)        # frames on disk (the writer flushed)
        time.sleep(0.15)
""")


def test_sigkill_leaves_readable_file(tmp_path):
    path = tmp_path / "killed.h5md"
    proc = subprocess.Popen([sys.executable, "-c", WRITER_SCRIPT, str(path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    written = 0
    deadline = time.monotonic() + 60
    try:
        while written < 5:
            line = proc.stdout.readline()
            if not line:
                pytest.fail(f"writer exited early: {proc.stderr.read()}")
            written = int(line)
            assert time.monotonic() < deadline
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL

    base = np.random.default_rng(1).uniform(0, 20, (50, 3))
    with h5py.File(path, "r") as f:
        t = f[TRAJ]
        nf = t["position/value"].shape[0]
        assert nf >= written
        np.testing.assert_array_equal(t["position/step"][:], 5 * np.arange(nf))
        for k in range(nf):
            np.testing.assert_array_equal(t["position/value"][k], base + 0.01 * k)
            np.testing.assert_allclose(t["velocity/value"][k], 1e-3 * k * cu.VEL_TO_A_PER_PS)
        np.testing.assert_array_equal(f["observables/k/value"][:], np.arange(nf))
        for name in ("velocity", "species", "box/edges"):
            assert t[name]["value"].shape[0] == nf
    u = universe(path)
    assert u.trajectory.n_frames == nf
    for k, ts in enumerate(u.trajectory):
        np.testing.assert_allclose(ts.positions, base + 0.01 * k, rtol=1e-6)
        assert ts.data["k"] == k
