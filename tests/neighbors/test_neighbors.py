"""The Verlet list against a brute-force O(N^2) search (open and periodic orthorhombic boxes)."""

import itertools

import numpy as np
import pytest

from clusterdyn.build import fcc_packing
from clusterdyn.errors import InputError
from clusterdyn.neighbors import NeighborList


def brute_force(pos, L, pbc, rc):
    """All (i, j, image) with |x_j + image*L - x_i| < rc, i != j or image != 0."""
    out = set()
    n = len(pos)
    ranges = [range(-int(np.ceil(rc / L[d])) - 1, int(np.ceil(rc / L[d])) + 2) if pbc[d] else [0]
              for d in range(3)]
    for img in itertools.product(*ranges):
        s = np.array(img) * L
        d = pos[None, :, :] + s[None, None, :] - pos[:, None, :]
        r = np.sqrt((d ** 2).sum(-1))
        ii, jj = np.nonzero(r < rc)
        for i, j in zip(ii, jj):
            if i == j and img == (0, 0, 0):
                continue
            out.add((int(i), int(j)) + tuple(np.round(d[i, j], 7)))
    return out


def listed(nl, pos, rc):
    i, j, d, r = nl.pairs(pos)
    k = r < rc
    return {(int(a), int(b)) + tuple(np.round(c, 7)) for a, b, c in zip(i[k], j[k], d[k])}


def full_from_half(nl, pos, rc):
    i, j, d, r = nl.pairs(pos)
    k = r < rc
    s = set()
    for a, b, c in zip(i[k], j[k], d[k]):
        s.add((int(a), int(b)) + tuple(np.round(c, 7)))
        s.add((int(b), int(a)) + tuple(np.round(-c, 7)))
    return s, int(k.sum())


@pytest.mark.parametrize("seed", range(12))
def test_random_configurations(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 120))
    L = rng.uniform(1.0, 6.0, 3)
    pbc = rng.random(3) < 0.5
    rc = rng.uniform(0.4, 2.5)
    pos = rng.uniform(0, 1, (n, 3)) * L
    pos[: n // 4] = np.round(pos[: n // 4] / L * 3) / 3 * L        # particles on cell faces
    pos[n // 8: n // 4, 0] = 0.0
    ref = brute_force(pos, L, pbc, rc)
    skin = rng.uniform(0, 0.5)
    full = NeighborList(rc, skin, half=False)
    full.build(pos, np.diag(L), pbc)
    assert listed(full, pos, rc) == ref
    for sort in (False, True):      # sorted: the one-pass fill over 14 cells where the grid allows it
        half = NeighborList(rc, skin, half=True, sort=sort)
        half.build(pos, np.diag(L), pbc)
        s, npairs = full_from_half(half, pos, rc)
        assert s == ref and 2 * npairs == len(ref)


@pytest.mark.parametrize("pbc", [(True, True, True), (False, True, True), (False, False, False)])
@pytest.mark.parametrize("size", [(1, 1, 1), (2, 1, 2), (3, 2, 4)])
def test_lattice_thin_boxes(pbc, size):
    atoms = fcc_packing("Al", 1.0, size=size, pbc=pbc)
    L = np.diag(atoms.cell.array)
    rc = 1.15
    ref = brute_force(atoms.positions, L, pbc, rc)
    for sort in (False, True):
        nl = NeighborList(rc, 0.2, half=True, sort=sort)
        nl.build(atoms.positions, atoms.cell.array, pbc)
        s, _ = full_from_half(nl, atoms.positions, rc)
        assert s == ref
    if all(pbc):
        assert all(len([p for p in ref if p[0] == i]) == 12 for i in range(len(atoms)))


def test_rebuild_by_displacement():
    atoms = fcc_packing("Al", 1.0, size=(3, 3, 3), pbc=True)
    nl = NeighborList(1.15, 0.2)
    assert nl.update(atoms.positions, atoms.cell.array, atoms.pbc)
    pos = atoms.positions.copy()
    pos[5] += [0.09, 0, 0]
    assert not nl.update(pos, atoms.cell.array, atoms.pbc)
    pos[5] += [0.02, 0, 0]
    assert nl.update(pos, atoms.cell.array, atoms.pbc)
    assert nl.nbuilds == 2
    # particles that left the periodic box are wrapped by the list, not by us
    pos[7] += [3 * atoms.cell[0, 0], 0, 0]
    nl.update(pos, atoms.cell.array, atoms.pbc)
    s, _ = full_from_half(nl, pos, 1.15)
    L = np.diag(atoms.cell.array)
    assert s == brute_force(pos % L, L, atoms.pbc, 1.15)     # separations do not depend on wrapping


def test_non_orthorhombic_periodic_cell_refused():
    nl = NeighborList(1.0)
    cell = [[3, 0, 0], [1, 3, 0], [0, 0, 3]]
    with pytest.raises(InputError, match="orthorhombic"):
        nl.build(np.zeros((2, 3)), cell, True)
    nl.build(np.array([[0, 0, 0], [0.5, 0, 0]]), cell, False)        # open: the cell does not matter
    assert nl.npairs == 1


def _debris_cloud(seed, n=600):
    """A compact lump, a cloud spread over a box 20 times wider, and a few far particles."""
    rng = np.random.default_rng(seed)
    lump = rng.uniform(0, 4.0, (n // 2, 3))
    cloud = rng.normal(0, 20.0, (n // 2 - 3, 3))
    cloud[: 60] = cloud[:60] * 0.02 + cloud[60:120] * 0.5          # small clumps inside the cloud
    far = np.array([[3.0e3, 0, 0], [3.0e3 + 0.5, 0.3, 0], [-2.0e2, 5e2, 1e3]])
    return np.vstack([lump, cloud, far])


@pytest.mark.parametrize("seed", range(4))
def test_sparse_cells_give_ase_pairs_on_a_debris_cloud(seed):
    """Sparse (occupied) cells and the dense grid give ASE's pairs, in the same order."""
    from ase import Atoms
    from ase.neighborlist import neighbor_list
    pos = _debris_cloud(seed)
    rc = 1.1
    atoms = Atoms("H%d" % len(pos), positions=pos, pbc=False)
    i, j, d = neighbor_list("ijd", atoms, rc)
    ref = {(int(a), int(b)) for a, b in zip(i, j)}
    lists = {}
    for cells in ("auto", "sparse", "dense"):
        # (the dense grid of the cloud with its far particles would have 1e9 cells: without them)
        p = pos if cells != "dense" else pos[:-3]
        nl = NeighborList(rc, 0.3, half=True, sort=True, centered=True, cells=cells)
        nl.build(p, np.zeros((3, 3)), False)
        ii, jj, dd, rr = nl.pairs(p)
        k = rr < rc
        got = {(int(a), int(b)) for a, b in zip(ii[k], jj[k])} | {(int(b), int(a)) for a, b in zip(ii[k], jj[k])}
        want = ref if cells != "dense" else {q for q in ref if max(q) < len(p)}
        assert got == want and 2 * k.sum() == len(want)
        lists[cells] = (nl.last_cells, nl.perm_n.copy(), nl.first_n.copy(), nl.jp_p.copy())
    assert lists["auto"][0] == "sparse" and lists["dense"][0] == "dense"
    assert all(np.array_equal(a, b) for a, b in zip(lists["auto"][1:], lists["sparse"][1:]))
    nl = NeighborList(rc, 0.3, half=True, sort=True, centered=True, cells="sparse")
    nl.build(pos[:-3], np.zeros((3, 3)), False)        # the same cloud: the same list in the same order
    assert all(np.array_equal(a, b) for a, b in zip((nl.perm_n, nl.first_n, nl.jp_p), lists["dense"][1:]))


def test_list_memory_does_not_grow_with_the_bounding_box():
    """One particle 1e7 cut-offs away: the list keeps the memory (and pairs) of the compact sample."""
    atoms = fcc_packing("Al", 1.0, size=(10, 10, 10), pbc=False)
    pos = atoms.positions
    nl = NeighborList(1.15, 0.25, half=True, sort=True, centered=True)
    nl.build(pos, atoms.cell.array, False)
    compact, pairs = nl.memory_bytes(), nl.npairs
    far = np.vstack([pos, [[1.4e7, -3.0e6, 2.0e6]]])
    nl2 = NeighborList(1.15, 0.25, half=True, sort=True, centered=True)
    nl2.build(far, atoms.cell.array, False)
    assert nl2.last_cells == "sparse" and nl2.npairs == pairs
    assert nl2.memory_bytes() < 1.05 * compact + 4096
    assert nl2.memory_bytes() < 250 * len(far)
    # the unsorted list coarsens its grid instead: bounded too
    nl3 = NeighborList(1.15, 0.25)
    nl3.build(far, atoms.cell.array, False)
    assert nl3.npairs == pairs


def test_a_growing_pair_pool_is_never_held_twice():
    """A build that needs a larger pair pool lets the old one go before it allocates the new one:
    the traced peak of that build stays below (memory before) + (new pool) - (old pool) / 2, where
    holding both would reach (memory before) + (new pool); and the list is that of a fresh list."""
    import tracemalloc
    atoms = fcc_packing("Al", 1.0, size=(14, 14, 14), pbc=False)
    pos = atoms.positions * 1.25            # dilute: few pairs, a small pool
    NeighborList(1.15, 0.25, half=True, sort=True, centered=True).build(pos, atoms.cell.array, False)  # code
    nl = NeighborList(1.15, 0.25, half=True, sort=True, centered=True)
    tracemalloc.start()
    try:
        nl.build(pos, atoms.cell.array, False)
        old = nl._pool.nbytes
        dense = atoms.positions * 0.8       # every cluster gains neighbours: the pool must grow
        tracemalloc.reset_peak()
        before = tracemalloc.get_traced_memory()[0]
        nl.build(dense, atoms.cell.array, False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    new = nl._pool.nbytes
    assert new > 1.5 * old
    assert peak < before + new - 0.5 * old
    fresh = NeighborList(1.15, 0.25, half=True, sort=True, centered=True)
    fresh.build(dense, atoms.cell.array, False)       # the list of a list that never had a pool
    assert all(np.array_equal(a, b) for a, b in zip((nl.perm_n, nl.first_n, nl.jp_p),
                                                    (fresh.perm_n, fresh.first_n, fresh.jp_p)))


def _listed_pairs(nl, pos, rc):
    ii, jj, dd, rr = nl.pairs(pos)
    k = rr < rc
    return {(min(a, b), max(a, b)) for a, b in zip(ii[k].tolist(), jj[k].tolist())}


def test_local_rebuild_test_bounds_by_the_farthest_displacements_and_misses_no_pair():
    """Thermal-like displacements on top of a common drift: the bounding box of the displacements
    (half-diagonal sqrt 3 times the extremes along each axis) would call for a rebuild, the two
    farthest displacements from its centre do not; and over a run of random moves with a
    block sliding past the rest, every pair within the cut-off is listed whenever the list
    is kept."""
    from scipy.spatial import cKDTree
    rc, skin = 1.15, 0.25
    atoms = fcc_packing("Al", 1.0, size=(10, 10, 10), pbc=False)
    pos0 = atoms.positions
    nl = NeighborList(rc, skin, half=True, sort=True, centered=True)
    nl.update(pos0, np.zeros((3, 3)), False)
    rng = np.random.default_rng(1)
    d = rng.normal(0.0, 0.025, pos0.shape)
    half_diag = 0.5 * np.linalg.norm(np.ptp(d, axis=0))
    far = np.sort(np.linalg.norm(d - 0.5 * (d.max(0) + d.min(0)), axis=1))[-2:].sum()
    assert 2 * half_diag > skin >= far                # the old bound fails, the new one holds
    assert not nl.update(pos0 + d + [0.3, 0.0, 0.0], np.zeros((3, 3)), False)
    assert nl.nlocal == 1 and nl.nbuilds == 1
    # a block sliding past the rest, with random motion: never a pair missed
    pos = pos0.copy()
    upper = pos0[:, 2] > pos0[:, 2].mean()
    kept = 0
    for step in range(60):
        pos = pos + rng.normal(0.0, 0.01, pos.shape)
        pos[upper, 0] += 0.02
        if not nl.update(pos, np.zeros((3, 3)), False):
            kept += 1
            want = {tuple(q) for q in cKDTree(pos).query_pairs(rc - 1e-9)}
            assert want <= _listed_pairs(nl, pos, rc)
    assert kept > 30 and nl.nbuilds > 2


@pytest.mark.parametrize("cells", ["dense", "sparse"])
def test_parallel_sort_and_bricks_are_the_serial_ones(cells):
    """The cell sort and the bricks (keys, gather and brick boxes in parallel) on 1 and 2 threads:
    the same rows, list and bricks; rows stable within a cell (a cell's particles in their
    original order); each brick's box the bounding box of its particles, bricks numbered in
    order of first appearance."""
    from clusterdyn.parallel import MIN_PARTICLES_PER_THREAD, set_max_threads
    rng = np.random.default_rng(3)
    n = max(4 * MIN_PARTICLES_PER_THREAD, 65536)
    pos = np.vstack([rng.uniform(0, 30.0, (n // 2, 3)), rng.normal(15.0, 60.0, (n // 2, 3))])
    pos = pos[rng.permutation(len(pos))]
    got = []
    try:
        for threads in (1, 2):
            set_max_threads(min(threads, __import__("numba").config.NUMBA_NUM_THREADS))
            nl = NeighborList(1.1, 0.3, half=True, sort=True, centered=True, cells=cells)
            nl.build(pos, np.zeros((3, 3)), False)
            brick_n, blo, bhi = nl._bricks[:3]
            got.append([nl.perm_n.copy(), nl.first_n.copy(), nl.jp_p.copy(), nl.xs_nc.copy(), brick_n.copy(),
                        blo.copy(), bhi.copy()])
    finally:
        set_max_threads(None)
    assert nl.last_cells == cells
    assert all(np.array_equal(a, b) for a, b in zip(*got))
    perm, xs, brick_n, blo, bhi = got[0][0], got[0][3], got[0][4], got[0][5], got[0][6]
    assert np.array_equal(np.sort(perm), np.arange(len(pos))) and np.array_equal(xs, pos[perm])
    # rows of one cell in the particles' order (the list's grid over an open box: floor(extent /
    # (cutoff + skin)) cells a side)
    ext = np.ptp(pos, axis=0)
    ncell = np.floor(ext / (nl.cutoff + nl.skin))
    cell = np.minimum(np.floor((xs - pos.min(axis=0)) * (1.0 / (ext / ncell))), ncell - 1).astype(np.int64)
    new = np.r_[True, np.any(cell[1:] != cell[:-1], axis=1)]
    run = np.cumsum(new)
    same = run[1:] == run[:-1]
    assert same.sum() > len(pos) // 4 and np.all(perm[1:][same] > perm[:-1][same])
    first = np.unique(brick_n, return_index=True)[1]
    assert np.array_equal(np.sort(first), first)           # numbered in order of first appearance
    for b in range(blo.shape[0]):
        p = pos[brick_n == b]
        assert np.array_equal(blo[b], p.min(axis=0)) and np.array_equal(bhi[b], p.max(axis=0))
