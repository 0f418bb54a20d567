"""Particles leaving a region of interest: removed, their energy and momentum booked, H5MD frames
of fixed size with fill values that MDAnalysis and clusterdyn read."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError
from clusterdyn.io import H5MDWriter, read_h5md
from clusterdyn.io.checkpoint import load_run, save_run
from clusterdyn.md import DampedVerlet, RegionOfInterest, default_timestep

R0 = 5 * units.um


def _block(seed=0):
    """An open aluminium block with eight clusters thrown out along +x at 7-9 km/s."""
    atoms = fcc_packing("Al", R0, size=(5, 4, 4), pbc=False)
    atoms.calc = ClusterDynamics()
    rng = np.random.default_rng(seed)
    v = rng.normal(0, 20 * units.m_s, (len(atoms), 3))
    x = atoms.positions[:, 0]
    out = np.argsort(x)[-8:]                         # the last layer flies off
    v[out, 0] += rng.uniform(7, 9, out.size) * units.km_s
    atoms.set_velocities(v)
    return atoms, out


def _run(tmp_path, steps=400, remove=True):
    atoms, out = _block()
    hi = atoms.positions[:, 0].max() + 3 * R0
    region = RegionOfInterest(hi=[hi, np.inf, np.inf]) if remove else None
    atoms.calc.setup(atoms)
    dt = default_timestep(atoms.calc, 9 * units.km_s)
    dyn = DampedVerlet(atoms, timestep=dt, J=None, region=region, remove_interval=5)
    p0 = atoms.get_momenta().sum(axis=0)
    tmp_path.mkdir(exist_ok=True)
    path = tmp_path / "run.h5md"
    w = H5MDWriter(path, atoms, dyn=dyn)
    dyn.attach(w, interval=40)
    dyn.start_ledger()
    dyn.run(steps)
    w.close()
    return atoms, dyn, out, p0, path


def test_removed_particles_carry_their_energy_and_momentum(tmp_path):
    atoms, dyn, out, p0, path = _run(tmp_path)
    n0 = 4 * 5 * 4 * 4
    r = dyn.removed
    assert r["count"] > 0 and len(atoms) == n0 - r["count"]
    assert set(out.tolist()) >= set(np.setdiff1d(np.arange(n0), atoms.arrays["id"]).tolist())
    L = dyn.energy_ledger()
    assert L["removed_kinetic"] > 0.5 * L["energy_in"] and L["removed_potential"] != 0
    # no drives, no damping: the residual is velocity Verlet's error alone, the same as in the run
    # that keeps every particle (whose energy is all still there)
    L_keep = _run(tmp_path / "keep", remove=False)[1].energy_ledger()
    assert abs(L_keep["residual"]) < 1e-3 * L_keep["energy_in"]
    assert abs(L["residual"] - L_keep["residual"]) < 1e-7 * L["energy_in"]
    # momentum: what is left plus what was removed is what there was
    p_now = atoms.get_momenta().sum(axis=0)
    scale = out.size * atoms.get_masses()[0] * 9 * units.km_s
    assert np.abs(p_now + L["removed_momentum"] - p0).max() < 1e-9 * scale


def test_h5md_keeps_fixed_frames_with_fill_values(tmp_path):
    atoms, dyn, out, p0, path = _run(tmp_path)
    import h5py
    n0 = 4 * 5 * 4 * 4
    with h5py.File(path, "r") as f:
        ids = f["particles/trajectory/id/value"][()]
        pos = f["particles/trajectory/position/value"][()]
        assert ids.shape == (11, n0) and pos.shape == (11, n0, 3)
        gone = ids[-1] == -1
        assert gone.sum() == dyn.removed["count"]
        assert np.all(np.isnan(pos[-1][gone])) and not np.any(np.isnan(pos[-1][~gone]))
        assert np.all(ids[0] >= 0)
        assert f["particles/trajectory/position/value"].fillvalue != f["particles/trajectory/position/value"].fillvalue
    last = read_h5md(path, -1)
    assert len(last) == len(atoms)
    assert np.array_equal(last.arrays["id"], np.sort(atoms.arrays["id"]))
    order = np.argsort(atoms.arrays["id"])
    assert np.allclose(last.positions, atoms.positions[order])
    # MDAnalysis reads every frame: the run's particles, NaN rows for the removed ones
    pytest.importorskip("MDAnalysis")
    import MDAnalysis
    from clusterdyn.io.mda import universe
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)     # plain MDAnalysis: no topology to guess masses from
        plain = MDAnalysis.Universe(str(path))
    for u in (universe(path), plain):
        assert u.atoms.n_atoms == n0 and len(u.trajectory) == 11
        u.trajectory[-1]
        nan = np.isnan(u.atoms.positions).any(axis=1)
        assert nan.sum() == dyn.removed["count"]
        assert np.allclose(u.atoms.positions[~nan], atoms.positions[order], atol=1e-3)


def test_removal_restarts_bit_for_bit_and_keeps_the_region(tmp_path):
    atoms, _ = _block(1)
    region = RegionOfInterest(hi=[atoms.positions[:, 0].max() + 2 * R0, np.inf, np.inf])
    dyn = DampedVerlet(atoms, J=50, region=region, remove_interval=3)
    n0 = len(atoms)
    w = H5MDWriter(tmp_path / "r.h5md", atoms, dyn=dyn)
    dyn.attach(w, interval=30)
    dyn.run(60)
    save_run(tmp_path / "c.h5", dyn)
    w.close()
    dyn.observers.clear()
    dyn.run(60)
    a2, d2, _ = load_run(tmp_path / "c.h5")
    assert d2.region is not None and d2.remove_interval == 3
    # the restarted run (fewer particles) appends to its file: same rows, fill values
    w2 = H5MDWriter(tmp_path / "r.h5md", a2, dyn=d2, mode="a", restart_step=60)
    d2.attach(w2, interval=30)
    d2.run(60)
    w2.close()
    import h5py
    with h5py.File(tmp_path / "r.h5md", "r") as f:
        ids = f["particles/trajectory/id/value"][()]
    assert ids.shape == (5, n0) and (ids[-1] < 0).sum() == n0 - len(a2)
    assert dyn.removed["count"] > 0 and d2.removed["count"] == dyn.removed["count"]
    assert np.array_equal(a2.positions, atoms.positions)
    assert np.array_equal(a2.arrays["momenta"], atoms.arrays["momenta"])


def test_region_refused_along_periodic_axes():
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=(False, True, True))
    atoms.calc = ClusterDynamics()
    with pytest.raises(InputError, match="periodic"):
        DampedVerlet(atoms, J=None, region=RegionOfInterest(hi=[np.inf, 1e6, np.inf]))
    with pytest.raises(InputError, match="hi"):
        RegionOfInterest(lo=[0, 0, 0], hi=[1, -1, 1])


def test_removal_moves_rows_in_place_and_allocates_no_new_arrays():
    """A removal keeps the Atoms' arrays, the list's buffers and the force buffers (the kept rows
    moved to the front of the same memory: nothing of N's size is allocated, so removing does not
    raise the peak memory) and gives the same particles and forces as the kept rows themselves."""
    from clusterdyn.md.damped import COMPACT_ROWS, _compact
    atoms, out = _block()
    region = RegionOfInterest(hi=[atoms.positions[:, 0].max() + 3 * R0, np.inf, np.inf])
    atoms.calc.setup(atoms)
    dyn = DampedVerlet(atoms, timestep=default_timestep(atoms.calc, 9 * units.km_s), J=None, region=region,
                       remove_interval=1000)
    dyn.run(400)                                 # the thrown layer is outside now
    before = {k: v for k, v in atoms.arrays.items()}
    copies = {k: v.copy() for k, v in atoms.arrays.items()}
    nl = atoms.calc.nl
    stores = [nl._store[0], nl._ref_store, dyn._fbuf]
    inside = region.inside(atoms.positions)
    assert 0 < (~inside).sum() <= len(out)
    assert dyn.remove_outside() == (~inside).sum()
    keep = np.flatnonzero(inside)
    for k, v in atoms.arrays.items():
        assert np.shares_memory(v, before[k]) and np.array_equal(v, copies[k][keep]), k
    assert all(np.shares_memory(a, b) for a, b in zip(stores, [nl.xs_nc, nl.ref_nc, dyn.forces]))
    assert nl.xs_nc.shape[0] == len(atoms) == keep.size
    ref = atoms.copy()
    ref.calc = ClusterDynamics()
    assert np.allclose(dyn.forces, ref.get_forces(), rtol=1e-12, atol=1e-12 * np.abs(dyn.forces).max())
    # blocks of rows: the same rows as one fancy index, across block edges
    a = np.arange(3 * COMPACT_ROWS + 7, dtype=float).reshape(-1, 1) * [1.0, 2.0, 3.0]
    k = np.flatnonzero(np.random.default_rng(1).random(a.shape[0]) < 0.6)
    want = a[k].copy()
    got = _compact(a, k)
    assert np.shares_memory(got, a) and np.array_equal(got, want)
