"""Sorting the Atoms into the neighbour list's cell order (DampedVerlet(sort_interval=...)), and the
local rebuild test's walk over nearby bricks only."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError
from clusterdyn.io import H5MDWriter
from clusterdyn.io.checkpoint import load_run, save_run
from clusterdyn.md import DampedVerlet, Piston, default_timestep
from clusterdyn.neighbors import NeighborList
from clusterdyn.neighbors.rebuild import (MAX_BRICK_REACH, _brick_centres, _brick_pair_safe, _brick_radii,
                                          _bricks_safe)

R0 = 5 * units.um


def _sample(sort_interval=None, seed=0):
    """A shuffled open block driven by a piston at 2 km/s, a face of clusters thrown off at
    6-8 km/s, damping on."""
    atoms = fcc_packing("Al", R0, size=(8, 4, 4), pbc=False)
    rng = np.random.default_rng(seed)
    v = rng.normal(0, 20 * units.m_s, (len(atoms), 3))
    x = atoms.positions[:, 0]
    v[x > x.max() - 0.2 * R0, 0] += rng.uniform(6, 8, (x > x.max() - 0.2 * R0).sum()) * units.km_s
    atoms.set_velocities(v)
    atoms = atoms[rng.permutation(len(atoms))]            # rows in no spatial order
    atoms.set_constraint(Piston(np.flatnonzero(atoms.positions[:, 0] < x.min() + 0.2 * R0), 2 * units.km_s))
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    dt = default_timestep(atoms.calc, 8 * units.km_s)
    return atoms, DampedVerlet(atoms, timestep=dt, J=50, sort_interval=sort_interval)


def _by_id(atoms, name="positions"):
    return atoms.arrays[name][np.argsort(atoms.arrays["id"])]


def test_sorted_atoms_run_the_same_trajectory(tmp_path):
    """Sorting every 5 steps: the ids, the piston's particles and its force follow; between a sort
    and the next build the steps are the same bit for bit as without sorting; after builds the
    sums add in another order (rounding only); H5MD rows stay in id order."""
    a, da = _sample()
    b, db = _sample(sort_interval=5)
    pist_a, pist_b = a.constraints[0], b.constraints[0]
    assert np.array_equal(a.arrays["id"], b.arrays["id"])      # the builder's ids, shuffled alike
    ids_piston = set(a.arrays["id"][pist_a.index].tolist())
    w = H5MDWriter(tmp_path / "b.h5md", b, dyn=db)
    db.attach(w, interval=10)
    exact = 0
    builds_at_sort = None
    sorts, built = 0, -1
    for step in range(40):
        da.run(1)
        db.run(1)
        if (step + 1) % 5 == 0:                           # sorted at the end of this step
            if builds_at_sort is None:
                builds_at_sort = b.calc.nl.nbuilds        # the first sort: exact until the next build
            # (a sort only when a build since the last one left something to move)
            sorts, built = (sorts + 1, b.calc.nl.nbuilds) if b.calc.nl.nbuilds != built else (sorts, built)
            assert np.array_equal(b.calc.nl.perm_n, np.arange(len(b)))     # the list's rows are the Atoms'
        if builds_at_sort is not None and b.calc.nl.nbuilds == builds_at_sort:
            assert np.array_equal(_by_id(a), _by_id(b)) and np.array_equal(_by_id(a, "momenta"), _by_id(b, "momenta"))
            exact += 1
        if step == 9:
            pos10 = _by_id(a).copy()
        scale = np.abs(a.positions).max()
        assert np.abs(_by_id(a) - _by_id(b)).max() < 1e-12 * scale
        assert np.allclose(pist_b.force, pist_a.force, rtol=1e-9, atol=1e-9 * np.abs(pist_a.force).max())
    w.close()
    assert db.nsorts == sorts and 2 < sorts < 8 and exact >= 4 and b.calc.nl.nbuilds > 2
    assert not np.array_equal(a.arrays["id"], b.arrays["id"])                 # the sort did reorder
    assert set(b.arrays["id"][pist_b.index].tolist()) == ids_piston
    import h5py
    with h5py.File(tmp_path / "b.h5md", "r") as f:
        ids = f["particles/trajectory/id/value"][()]
        pos = f["particles/trajectory/position/value"][()]
    assert np.array_equal(ids[1], np.sort(a.arrays["id"]))
    assert np.allclose(pos[1], pos10, rtol=1e-6, atol=0)


def test_sorted_periodic_run_keeps_the_wrap_offsets_and_rows():
    """In a periodic box with particles outside it, sorting the Atoms carries the list's wrap
    offsets (held in the Atoms' order) and its inverse permutation with them: after the first
    sort the run is the unsorted run's bit for bit until the next build, and close to it after
    (the sums add in another order)."""
    def sample(sort_interval):
        atoms = fcc_packing("Al", R0, size=(6, 4, 4), pbc=True)
        rng = np.random.default_rng(3)
        atoms.positions += [0.0, 0.37 * atoms.cell[1, 1], -0.21 * atoms.cell[2, 2]]   # not wrapped
        atoms.set_velocities(rng.normal(0, 1.5 * units.km_s, (len(atoms), 3)))
        atoms = atoms[rng.permutation(len(atoms))]
        atoms.calc = ClusterDynamics()
        atoms.calc.setup(atoms)
        return atoms, DampedVerlet(atoms, timestep=default_timestep(atoms.calc, 4 * units.km_s), J=None,
                                   sort_interval=sort_interval)
    a, da = sample(None)
    b, db = sample(4)
    exact = 0
    sorted_at = None
    sorts, built = 0, -1
    for step in range(24):
        da.run(1)
        db.run(1)
        nl = b.calc.nl
        assert np.array_equal(nl.row_n[nl.perm_n], np.arange(len(b)))
        box = np.diag(b.cell)
        ref = nl.ref_nc
        assert np.abs(nl.offset_nc - (np.mod(ref, box) - ref)).max() < 1e-9 * box.max()
        assert np.count_nonzero(nl.offset_nc) > len(b) // 4
        if (step + 1) % 4 == 0:
            if sorted_at is None:
                sorted_at = nl.nbuilds            # the first sort: exact until the next build
            sorts, built = (sorts + 1, nl.nbuilds) if nl.nbuilds != built else (sorts, built)
            assert np.array_equal(nl.perm_n, np.arange(len(b)))
        if sorted_at is not None and nl.nbuilds == sorted_at:
            assert np.array_equal(_by_id(a), _by_id(b)) and np.array_equal(_by_id(a, "momenta"), _by_id(b, "momenta"))
            exact += 1
        assert np.abs(_by_id(a) - _by_id(b)).max() < 1e-12 * np.abs(a.positions).max()
    assert db.nsorts == sorts and 1 < sorts <= 6 and exact >= 3 and b.calc.nl.nbuilds > 2


def test_sorted_run_restarts_bit_for_bit(tmp_path):
    b, db = _sample(sort_interval=7)
    db.run(30)
    save_run(tmp_path / "c.h5", db)
    n30 = db.nsorts
    db.run(30)
    b2, d2, _ = load_run(tmp_path / "c.h5")
    assert d2.sort_interval == 7
    d2.run(30)
    # the restart's list, built from the sorted Atoms' reference positions, is in their order
    # too: the two runs sort at the same steps
    assert n30 >= 2 and db.nsorts - n30 == d2.nsorts >= 1
    for name in ("positions", "momenta", "id"):
        assert np.array_equal(b2.arrays[name], b.arrays[name])


def test_sort_interval_refused_when_it_cannot_follow():
    atoms = fcc_packing("Al", R0, size=(3, 3, 3), pbc=False)
    atoms.calc = ClusterDynamics()
    for bad in (0, -3, 2.5, "often"):
        with pytest.raises(InputError, match="sort_interval"):
            DampedVerlet(atoms, J=None, timestep=1.0, sort_interval=bad)
    from ase.calculators.emt import EMT
    other = atoms.copy()
    other.calc = EMT()
    with pytest.raises(InputError, match="ClusterDynamics"):
        DampedVerlet(other, J=None, timestep=1.0, sort_interval=10)


def test_sort_holds_no_scratch_and_masses_follow_the_atoms():
    """A sort borrows the list's key scratch (the dynamics keeps no array of its own for it), and
    ``dyn.masses`` (ASE's attribute) is the sorted Atoms' masses; another array is refused."""
    atoms, dyn = _sample(sort_interval=7)
    atoms.arrays["masses"] = atoms.get_masses() * (1 + 0.01 * np.arange(len(atoms)) / len(atoms))
    dyn.run(7)
    assert dyn.nsorts == 1
    held = [k for k, v in vars(dyn).items() if isinstance(v, np.ndarray) and v.ndim and v.shape[0] >= len(atoms)]
    assert sorted(held) == ["_fbuf", "_invm_n", "forces"]
    assert np.array_equal(dyn.masses[:, 0], atoms.get_masses()) and dyn.masses.shape == (len(atoms), 1)
    dyn.masses = atoms.get_masses()
    with pytest.raises(InputError, match="masses"):
        dyn.masses = 2 * atoms.get_masses()


def _brute(mid, rad, blo, bhi, box, periodic, skin, rc):
    for a in range(mid.shape[0]):
        if not rad[a, 0] + rad[a, 1] <= skin:
            return False
        for b in range(a + 1, mid.shape[0]):
            if not _brick_pair_safe(a, b, mid, rad, blo, bhi, box, periodic, skin, rc):
                return False
    return True


@pytest.mark.parametrize("pbc", [False, (True, False, True)])
def test_brick_walk_decides_as_every_pair_of_bricks(pbc, monkeypatch):
    """The local test walks only the bricks within reach of each other: over smooth strains and
    random motions of a block (periodic or open; bricks of 2 cut-offs, so that there are many),
    its answer is that of testing every pair of bricks, and both answers come out."""
    import clusterdyn.neighbors.celllist as CL
    monkeypatch.setattr(CL, "BRICK_SIDE", 2.0)
    atoms = fcc_packing("Al", 1.0, size=(24, 16, 12), pbc=pbc)
    pos0 = atoms.positions
    cell = atoms.cell.array if np.any(pbc) else np.zeros((3, 3))
    nl = NeighborList(1.15, 0.3, half=True, sort=True, centered=True)
    nl.build(pos0, cell, pbc)
    brick_n, blo, bhi, box, periodic, acc, mid, hi, acc2, rad, skey, sid, nb_c, csz = nl._bricks
    assert mid.shape[0] >= 100 and nb_c.min() >= 3
    rng = np.random.default_rng(5)
    seen = set()
    compared = 0
    for trial in range(40):
        grad = rng.normal(0, 10 ** rng.uniform(-3.5, -1.5), (3, 3))
        d = (pos0 - pos0.mean(0)) @ grad.T + rng.normal(0, 10 ** rng.uniform(-3, -1.3), pos0.shape)
        d += rng.normal(0, 2.0, 3)                                   # a common drift changes nothing
        pos = pos0 + d
        _brick_centres(pos, nl.ref_nc, brick_n, acc, hi, mid)
        _brick_radii(pos, nl.ref_nc, brick_n, mid, acc2, rad)
        want = _brute(mid, rad, blo, bhi, box, periodic, nl.skin, nl.cutoff)
        got = _bricks_safe(mid, rad, blo, bhi, skey, sid, nb_c, csz, box, periodic, nl.skin, nl.cutoff,
                           MAX_BRICK_REACH)
        reach = nl.cutoff + 2 * (np.linalg.norm(mid - 0.5 * (mid.max(0) + mid.min(0)), axis=1) + rad[:, 0]).max()
        if reach <= MAX_BRICK_REACH * csz.min():
            assert got == want
            compared += 1
        else:
            assert not got                                           # beyond its reach: a rebuild
        seen.add(want)
    assert seen == {True, False} and compared >= 20
