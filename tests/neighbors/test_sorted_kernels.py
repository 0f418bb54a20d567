"""The calculator's sorted neighbour list and chunked kernels: brute force, thread-count independence."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.neighbors import NeighborList
from clusterdyn.parallel import set_max_threads
from clusterdyn.scenes.shock import build_shock

from test_neighbors import brute_force, full_from_half, listed


@pytest.mark.parametrize("seed", range(16))
def test_sorted_lists_against_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 300))
    L = rng.uniform(1.0, 9.0, 3)
    pbc = rng.random(3) < 0.5
    rc = rng.uniform(0.4, 2.5)
    pos = rng.uniform(0, 1, (n, 3)) * L
    pos[: n // 4] = np.round(pos[: n // 4] / L * 3) / 3 * L
    ref = brute_force(pos, L, pbc, rc)
    skin = rng.uniform(0, 0.5)
    full = NeighborList(rc, skin, half=False, sort=True)
    full.build(pos, np.diag(L), pbc)
    assert listed(full, pos, rc) == ref
    half = NeighborList(rc, skin, half=True, sort=True, centered=True)
    half.build(pos, np.diag(L), pbc)
    s, npairs = full_from_half(half, pos, rc)
    assert s == ref and 2 * npairs == len(ref)
    # a common translation larger than the skin plus small noise: the centred test keeps the list
    shift = rng.normal(size=3)
    shift *= 3 * skin / np.linalg.norm(shift)
    pos2 = pos + shift + rng.uniform(-0.05, 0.05, pos.shape) * skin
    half.update(pos2, np.diag(L), pbc)
    w = np.where(pbc, pos2 % L, pos2)
    assert full_from_half(half, pos2, rc)[0] == brute_force(w, L, pbc, rc)


@pytest.mark.parametrize("pbc", [(True, True, True), (False, True, True)])
def test_sorted_half_stencil_on_lattices(pbc):
    for size in [(3, 3, 3), (5, 4, 3), (8, 3, 4)]:
        atoms = fcc_packing("Al", 1.0, size=size, pbc=pbc)
        L = np.diag(atoms.cell.array)
        nl = NeighborList(1.15, 0.2, half=True, sort=True, centered=True)
        nl.build(atoms.positions, atoms.cell.array, pbc)
        assert full_from_half(nl, atoms.positions, 1.15)[0] == brute_force(atoms.positions, L, pbc, 1.15)


def test_centered_rebuild_ignores_a_moving_block():
    atoms = fcc_packing("Al", 1.0, size=(4, 4, 4), pbc=(False, True, True))
    nl = NeighborList(1.15, 0.2, sort=True, centered=True)
    nl.update(atoms.positions, atoms.cell.array, atoms.pbc)
    pos = atoms.positions + [0.15, 0.0, 0.0]              # > skin/2, all together
    assert not nl.update(pos, atoms.cell.array, atoms.pbc)
    pos[0] += [0.0, 0.21, 0.0]                            # spread > skin
    assert nl.update(pos, atoms.cell.array, atoms.pbc)


def test_forces_bit_identical_on_one_and_two_threads():
    """Chunks depend on the list only: the same sums in the same order on any thread count."""
    s = build_shock(size=(32, 16, 16), u=3 * units.km_s, J=50, seed=3)    # 32768: four chunks
    a, c = s.atoms, s.calc
    rng = np.random.default_rng(0)
    a.positions = a.positions + rng.normal(0, 0.02 * 5 * units.um, a.positions.shape)
    damping = (a.arrays["momenta"], 1.0 / a.get_masses(), c.damping_matrix(50.0))
    try:
        set_max_threads(1)
        f1 = c.compute(a, damping=damping)["forces"]
        p1 = c.compute(a, per_particle=True)
        set_max_threads(2 if __import__("numba").config.NUMBA_NUM_THREADS >= 2 else 1)
        f2 = c.compute(a, damping=damping)["forces"]
        p2 = c.compute(a, per_particle=True)
    finally:
        set_max_threads(None)
    assert np.array_equal(f1, f2)
    assert np.array_equal(p1["forces"], p2["forces"]) and np.array_equal(p1["virials"], p2["virials"])
    assert p1["energy"] == p2["energy"]
    assert len(c.engine._lay["chunks"].bounds) - 1 == 4


def test_sorted_kernels_match_a_direct_pair_sum():
    s = build_shock(size=(10, 3, 3), u=3 * units.km_s, J=50, seed=7)
    s.dyn.run(120)
    a, c = s.atoms, s.calc
    out = c.compute(a, per_particle=True)
    nl = NeighborList(c.nl.cutoff, 0.0, half=True)
    nl.build(a.positions, a.cell.array, a.pbc)
    i, j, d, r = nl.pairs(a.positions)
    t = c.tables[0][0]
    k = r < t.cutoff
    i, j, d, r = i[k], j[k], d[k], r[k]
    e, f = t.evaluate(r)
    fv = (f / r)[:, None] * d
    F = np.zeros((len(a), 3))
    np.add.at(F, i, -fv)
    np.add.at(F, j, fv)
    scale = np.abs(F).max()
    assert np.abs(out["forces"] - F).max() < 1e-10 * scale
    assert np.isclose(out["energy"], e.sum(), rtol=1e-12)
    En = np.zeros(len(a))
    np.add.at(En, i, 0.5 * e)
    np.add.at(En, j, 0.5 * e)
    assert np.allclose(out["energies"], En, rtol=1e-10, atol=1e-12 * np.abs(En).max())
    assert np.allclose(out["virials"].sum(axis=0), out["virial"], rtol=1e-10)


def test_closest_pair_found_when_read_is_the_tracked_one():
    """The single-material step kernels keep only the smallest distance; the pair itself is
    found on demand and is the one the tracking kernels report; it expires with the next step."""
    from clusterdyn import units
    from clusterdyn.scenes.shock import build_shock
    s = build_shock(size=(24, 3, 3), u=3 * units.km_s, J=None)
    s.dyn.run(50)
    c, a = s.calc, s.atoms
    c.compute(a, virial=False, energy=False)
    st = c.last_stats
    assert st._rerun is not None                      # not tracked by this kernel
    lazy, x_lazy = st["closest"], st["min_r_over_r0"]
    c.compute(a)                                       # the virial kernel tracks the pair
    assert c.last_stats._rerun is None
    assert c.last_stats["closest"] == lazy and c.last_stats["min_r_over_r0"] == x_lazy < 1.0
    i, j = lazy
    assert a.get_distance(i, j, mic=True) / c.potentials[0].r0 == pytest.approx(x_lazy, rel=1e-12)
    c.compute(a, virial=False, energy=False)
    old = c.last_stats
    s.dyn.run(1)
    with pytest.raises(KeyError, match="before the next compute"):
        old["closest"]


@pytest.mark.parametrize("periodic_x", [False, True])
def test_step_kernels_write_unshared_rows_as_the_full_sum_does(periodic_x):
    """The step kernels write each row no other chunk touches themselves (with the half kick)
    and sum only the shared rows after: the same bits as summing every row afterwards."""
    s = build_shock(size=(64, 16, 16), u=3 * units.km_s, J=None, seed=5)    # 65536: four chunks
    a, c = s.atoms, s.calc
    s.dyn.run(30)
    if periodic_x:       # pairs across the x faces: the first and last chunks share rows
        a.pbc = True
        a.cell[0, 0] = a.positions[:, 0].max() + 0.9 * c.potentials[0].r0
    f_all = c.compute(a)["forces"].copy()                      # virial kernel: every row summed after
    lay = c.engine._lay["chunks"]
    assert len(lay.bounds) - 1 == 4
    shared = lay.shared_r.shape[0]
    assert 0 < shared < len(a) // 4
    p0 = a.arrays["momenta"].copy()
    p = p0.copy()
    h = 0.37
    f_fin = c.compute(a, virial=False, energy=False, kick=(p, h))["forces"]
    assert np.array_equal(f_fin, f_all)
    assert np.array_equal(p, p0 + h * f_all)
    f_fin2 = c.compute(a, virial=False, energy=False)["forces"]        # no kick: momenta untouched
    assert np.array_equal(f_fin2, f_all)


def test_chunk_count_follows_the_layers_not_the_threads():
    from clusterdyn.engine import chunks as K
    n = 40 * K.CHUNK_ROWS
    assert K.chunk_count(n, 0) == 40                               # no layers known: rows alone
    assert K.chunk_count(n, 1000) == 40                            # thin layers (a slab): rows alone
    assert K.chunk_count(n, n // 8) == K.MIN_CHUNKS                # thick layers: never fewer than this
    thick = n // (K.CHUNK_LAYERS * 20)
    assert K.chunk_count(n, thick) == 20                           # CHUNK_LAYERS layers a chunk
    assert K.chunk_count(100, 50) == 1
    # small lists: up to FEW_CHUNKS chunks of at least MIN_CHUNK_ROWS rows, for two to four threads
    m = K.MIN_CHUNK_ROWS
    assert [K.chunk_count(k * m, 0) for k in (1, 2, 3, 4, 8)] == [1, 2, 3, 4, 4]
    assert K.chunk_count(2 * K.CHUNK_ROWS, 0) == K.FEW_CHUNKS == K.chunk_count(K.FEW_CHUNKS * K.CHUNK_ROWS, 0)
    assert K.chunk_count((K.FEW_CHUNKS + 1) * K.CHUNK_ROWS, 0) == K.FEW_CHUNKS + 1


def test_chunks_of_a_compact_body_span_layers(monkeypatch):
    """In a compact body a cell layer holds more rows than a chunk: chunks of several layers share
    far fewer rows (and buffer rows) with the next, and give the same forces, on any thread count."""
    from clusterdyn.build.bodies import sphere
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.engine import chunks as K
    monkeypatch.setattr(K, "CHUNK_ROWS", 128)
    monkeypatch.setattr(K, "MIN_CHUNKS", 4)
    monkeypatch.setattr(K, "CHUNK_LAYERS", 4)
    r0 = 5 * units.um
    a = sphere("Al", r0, 20 * r0)
    rng = np.random.default_rng(1)
    a.positions = a.positions + rng.normal(0, 0.03 * r0, a.positions.shape)
    a.calc = c = ClusterDynamics()
    n = len(a)
    try:
        set_max_threads(1)
        f_new = c.compute(a)["forces"].copy()
        lay = c.engine._lay["chunks"]
        nk, shared, buf = len(lay.bounds) - 1, lay.shared_r.shape[0], int(lay.boff[-1])
        assert c.nl.layer_rows > 4 * 128 and nk == max(4, n // (4 * c.nl.layer_rows))
        set_max_threads(2 if __import__("numba").config.NUMBA_NUM_THREADS >= 2 else 1)
        assert np.array_equal(c.compute(a)["forces"], f_new)
        monkeypatch.setattr(K, "chunk_count", lambda n, layer_rows: max(1, n // K.CHUNK_ROWS))   # rows alone
        c.engine._lay["key"] = None
        f_old = c.compute(a)["forces"]
    finally:
        set_max_threads(None)
    lay = c.engine._lay["chunks"]
    assert len(lay.bounds) - 1 == n // 128
    assert shared < 0.5 * lay.shared_r.shape[0] and buf < 0.8 * lay.boff[-1]
    assert np.abs(f_new - f_old).max() <= 1e-12 * np.abs(f_old).max()


@pytest.mark.parametrize("nan_at", [None, 2, 5])
def test_chunk_stats_is_the_numpy_summary(nan_at):
    """``chunk_stats``: the closest pair's rows renamed through the permutation where tracked
    (-1 kept), the chunk of the smallest r^2 as ``np.argmin`` picks it (the first NaN if any),
    and the smallest and sum of the counts column."""
    from clusterdyn.engine.chunks import chunk_stats
    rng = np.random.default_rng(7)
    nk, n = 9, 50
    stat = np.column_stack([rng.normal(size=nk), rng.uniform(0.5, 2.0, nk), rng.integers(-1, n, nk),
                            rng.integers(-1, n, nk), rng.integers(-1, 4, nk), rng.uniform(size=nk)]).astype(float)
    stat[3, 1] = stat[6, 1] = stat[:, 1].min() / 2          # a tie: the first one wins
    if nan_at is not None:
        stat[nan_at, 1] = stat[nan_at + 1, 1] = np.nan
    perm = rng.permutation(n)
    want = stat.copy()
    for c in (2, 3):
        ok = want[:, c] >= 0
        want[ok, c] = perm[want[ok, c].astype(int)]
    k, low, tot = chunk_stats(stat, perm)
    assert np.array_equal(stat, want, equal_nan=True)
    assert k == int(np.argmin(want[:, 1])) == (3 if nan_at is None else nan_at)
    assert low == want[:, 4].min() and tot == want[:, 4].sum()
