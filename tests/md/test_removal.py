"""Particles leaving a region of interest: removed, their energy and momentum booked, H5MD frames
of fixed size with fill values that MDAnalysis and clusterdyn read."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics, mark_initial_bonds
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
    from clusterdyn.md.region import COMPACT_ROWS, _compact
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


def _compaction_case(case, seed=3):
    """A jiggled aluminium block (open, or periodic and thin along z: the full-stencil list),
    with two materials or attraction='initial' as ``case`` says."""
    periodic = case == "periodic, two materials"
    atoms = fcc_packing("Al", R0, size=(7, 6, 2 if periodic else 5), pbc=periodic)
    rng = np.random.default_rng(seed)
    kw = {}
    if periodic:
        atoms.arrays["material"] = rng.integers(0, 2, len(atoms))
        kw = {"materials": ["Al", "Pb"], "r0": [R0, R0]}
    if case == "initial bonds":
        mark_initial_bonds(atoms)
        kw = {"attraction": "initial"}
    atoms.positions += rng.normal(0, 0.04 * R0, atoms.positions.shape)
    return atoms, kw, rng


@pytest.mark.parametrize("case", ["open", "periodic, two materials", "initial bonds"])
def test_compacted_list_gives_a_fresh_builds_forces_and_the_energy_lost(case):
    """Taking particles out compacts the list (no build); its forces on the rest are a fresh
    calculator's to 1e-12, and the energy of the pairs touching them is the energy lost."""
    atoms, kw, rng = _compaction_case(case)
    calc = ClusterDynamics(**kw)
    atoms.calc = calc
    e_before = calc.compute(atoms)["energy"]
    atoms.positions += rng.normal(0, 0.02 * R0, atoms.positions.shape)   # within the skin: no build
    e_before = calc.compute(atoms)["energy"]
    nl = calc.nl
    nb, ver = nl.nbuilds, nl.version
    gone = rng.random(len(atoms)) < 0.3
    lost = calc.pairs_touching(atoms, gone)[0]
    kept = atoms[~gone]
    assert calc.removed(~gone)
    kept.calc = calc
    res = calc.compute(kept)
    assert (nl.nbuilds, nl.version, nl.compacted) == (nb, ver + 1, True)
    assert np.array_equal(nl.perm_n[nl.row_n], np.arange(len(kept)))
    assert np.array_equal(nl.sorted_positions(kept.positions), nl.xs_nc)
    fresh = kept.copy()
    fresh.calc = ClusterDynamics(**kw)
    ref = fresh.calc.compute(fresh)
    scale = np.abs(ref["forces"]).max()
    assert np.abs(res["forces"] - ref["forces"]).max() <= 1e-12 * scale
    assert res["energy"] == pytest.approx(ref["energy"], rel=1e-12, abs=1e-12 * abs(e_before))
    assert lost == pytest.approx(e_before - ref["energy"], rel=1e-11)
    assert abs(lost) > 0.1 * abs(e_before - lost) * gone.mean()
    # the pairs within the cut-off are the fresh list's
    def close(c, a):
        i, j, _, r = c.nl.pairs(a.positions)
        ok = r < c.nl.cutoff
        return {(min(p, q), max(p, q)) for p, q in zip(i[ok], j[ok])}
    assert close(calc, kept) == close(fresh.calc, fresh)


def test_removal_keeps_the_list_and_the_local_test():
    """Three quiet blocks far apart, two flying off in opposite directions; one is taken out
    at once.  The removal builds nothing: its emptied bricks are dropped, and the local rebuild
    test keeps the list of the other two as it keeps the list of all three without removal."""
    blocks = []
    for k, v in ((0, 0.0), (1, 2.0), (-1, -2.0)):
        b = fcc_packing("Al", R0, size=(4, 4, 4), pbc=False)
        b.positions += (20 * R0 * k, 0.0, 0.0)
        b.set_velocities(np.tile([v * units.km_s, 0.0, 0.0], (len(b), 1)))
        blocks.append(b)
    atoms = blocks[0] + blocks[1] + blocks[2]
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    dt = default_timestep(atoms.calc, 2 * units.km_s)
    lo = np.full(3, -np.inf)
    lo[0] = blocks[2].positions[:, 0].max() + 0.05 * R0         # the third block is outside
    runs = []
    for region in (None, RegionOfInterest(lo=lo)):
        a = atoms.copy()
        a.calc = ClusterDynamics()
        dyn = DampedVerlet(a, timestep=dt, J=None, region=region, remove_interval=10)
        dyn.run(80)
        runs.append((a.calc.nl, dyn))
    (nl0, _), (nl1, d1) = runs
    assert d1.removed["count"] == len(blocks[2]) and nl1.nremovals == 1
    # (the removal run's global test fails later: the displacements left span half as much)
    assert nl0.nbuilds == nl1.nbuilds == 1 and nl0.nlocal > 0 and nl1.nlocal > 0
    assert nl1._bricks[1].shape[0] == np.unique(nl1._bricks[0]).size < nl0._bricks[1].shape[0]


@pytest.mark.parametrize("J", [None, 50.0])
def test_removal_takes_the_removed_pairs_out_of_the_steps_forces(J):
    """Without constraints a removal runs no force pass: the step's forces less the removed
    particles' pairs (and their damping, at the step's velocities) are the forces the step's
    pass gives over the particles left, to 1e-12."""
    atoms = fcc_packing("Al", R0, size=(6, 5, 5), pbc=False)
    rng = np.random.default_rng(11)
    atoms.set_velocities(rng.normal(0, 50 * units.m_s, (len(atoms), 3)))
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    dt = default_timestep(atoms.calc, 1 * units.km_s)
    hi = [atoms.positions[:, 0].max() - 1.5 * R0, np.inf, np.inf]       # the last two layers go
    twin = atoms.copy()
    twin.calc = ClusterDynamics()
    dyn = DampedVerlet(atoms, timestep=dt, J=J, region=RegionOfInterest(hi=hi), remove_interval=5)
    ref = DampedVerlet(twin, timestep=dt, J=J)
    dyn.run(4)
    ref.run(5)
    passes = []
    own = dyn._compute_forces
    dyn._compute_forces = lambda *a, **k: passes.append(1) or own(*a, **k)
    nb = atoms.calc.nl.nbuilds
    dyn.run(1)
    keep = twin.positions[:, 0] <= hi[0]
    assert len(passes) == 1 and atoms.calc.nl.nbuilds == nb and 0 < len(atoms) == keep.sum() < len(twin)
    assert np.array_equal(atoms.positions, twin.positions[keep])
    # the step's pass over the particles left: its positions, and velocities half a step back
    kept = twin[keep]
    kept.calc = ClusterDynamics()
    damping = None
    if J is not None:
        p_half = twin.arrays["momenta"] - 0.5 * dt * ref.forces
        damping = (np.ascontiguousarray(p_half[keep]), 1.0 / kept.get_masses(), ref._eta)
    want = kept.calc.compute(kept, damping=damping)["forces"]
    assert np.abs(dyn.forces - want).max() <= 1e-12 * np.abs(want).max()
    assert np.abs(ref.forces[keep] - want).max() > 1e-6 * np.abs(want).max()    # the pairs mattered
