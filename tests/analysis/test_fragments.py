"""Fragments: exact components on built configurations, scipy on random ones, MCA, observer, files."""

import math

import numpy as np
import pytest
from ase import Atoms
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from clusterdyn import units
from clusterdyn.analysis import FragmentAnalysis, FragmentObserver
from clusterdyn.analysis.fragments import fragments
from clusterdyn.errors import InputError

R0 = 1.0          # Angstrom (the rule is scale-free; CD-sized samples below use 10 um)


def _atoms(pos, cell=None, pbc=False, masses=None, vel=None, material=None):
    pos = np.asarray(pos, float)
    a = Atoms(numbers=np.ones(len(pos), int), positions=pos, cell=cell if cell is not None else np.zeros(3),
              pbc=pbc)
    if masses is not None:
        a.set_masses(masses)
    if vel is not None:
        a.set_velocities(vel)
    if material is not None:
        a.new_array("material", np.asarray(material, np.int64))
    return a


def _canonical(labels):
    """Labels renumbered in order of first appearance (a partition's canonical form)."""
    _, first, inv = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[inv]


def _scipy_labels(n, i, j):
    g = coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    return _canonical(connected_components(g, directed=False)[1])


# ------------------------------------------------------------------ built configurations, exact N(g)

def test_chain_ring_and_isolated_clusters_exact_spectrum():
    chain = [[10.0 + k, 0.0, 0.0] for k in range(5)]                     # 5 in a line, spacing r0
    nr = 8
    rad = 0.5 / math.sin(math.pi / nr)                                    # neighbours at exactly r0
    ring = [[rad * math.cos(2 * math.pi * k / nr), 20 + rad * math.sin(2 * math.pi * k / nr), 0.0]
            for k in range(nr)]
    lone = [[-20.0, 0, 0], [-20.0, 1.2, 0], [-20.0, 0, 1.2]]              # 1.2 r0 apart: not bonded at b=1.15
    a = _atoms(chain + ring + lone)
    f = fragments(a, b=1.15, r0=R0)
    gs, n = f.spectrum()
    assert dict(zip(gs.tolist(), n.tolist())) == {1: 3, 5: 1, 8: 1}
    assert f.labels.tolist() == [0] * 5 + [1] * 8 + [2, 3, 4]
    assert f.nbonds == 4 + 8                                              # a ring of 8 closes: 8 bonds
    assert not f.percolating.any()
    # b = 1.25 bonds the three lone clusters (1.2 apart) but not the ring's second neighbours (1.85)
    f2 = fragments(a, b=1.25, r0=R0)
    assert sorted(f2.g.tolist()) == [3, 5, 8]


def test_fragment_across_a_periodic_face_mass_centre_velocity_by_hand():
    L = 10.0
    x = [8.6, 9.6, 0.6, 1.6]                          # a chain of 4 through the x face (0.6 -> 9.6 is 1.0)
    pos = [[xi, 5.0, 5.0] for xi in x] + [[5.0, 5.0, 5.0]]
    m = [1.0, 2.0, 3.0, 4.0, 7.0]
    v = [[1, 0, 0], [2, 0, 0], [3, 1, 0], [4, 0, -1], [0, 0, 5]]
    per = _atoms(pos, cell=[L, L, L], pbc=True, masses=m, vel=v)
    f = fragments(per, b=1.15, r0=R0)
    assert f.g.tolist() == [4, 1] and f.labels.tolist() == [0, 0, 0, 0, 1]
    # by hand: unwrapped x = 8.6, 9.6, 10.6, 11.6; centre (8.6 + 19.2 + 31.8 + 46.4)/10 = 10.6 -> 0.6
    assert f.mass.tolist() == [10.0, 7.0]
    assert f.com[0] == pytest.approx([0.6, 5.0, 5.0], abs=1e-12)
    assert f.com[1] == pytest.approx([5.0, 5.0, 5.0])
    # momentum (1 + 4 + 9 + 16, 3, -4) / 10
    assert f.velocity[0] == pytest.approx([3.0, 0.3, -0.4])
    assert f.velocity[1] == pytest.approx([0.0, 0.0, 5.0])
    assert not f.percolating.any()
    # the same positions in an open box: the face no longer joins them
    f_open = fragments(_atoms(pos, masses=m, vel=v), b=1.15, r0=R0)
    assert sorted(f_open.g.tolist()) == [1, 2, 2]
    # unwrapped input (positions beyond the box) gives the same fragments and centre
    shifted = per.copy()
    shifted.positions[:2, 0] -= L
    shifted.positions[3, 0] += 2 * L
    f_s = fragments(shifted, b=1.15, r0=R0)
    assert f_s.labels.tolist() == f.labels.tolist()
    assert f_s.com[0] == pytest.approx(f.com[0], abs=1e-12)


def test_fragment_bonded_to_its_own_image_is_flagged():
    L = 6.0
    pos = [[k + 0.5, 2.0, 2.0] for k in range(6)] + [[3.0, 5.0, 5.0]]    # a line spanning periodic x
    a = _atoms(pos, cell=[L, 8.0, 8.0], pbc=(True, False, False))
    f = fragments(a, b=1.15, r0=R0)
    assert f.g.tolist() == [6, 1]
    assert f.percolating.tolist() == [[True, False, False], [False, False, False]]
    assert f.com[0] == pytest.approx([3.0, 2.0, 2.0])                      # mean of the wrapped x
    # a box narrower than the bond distance: one cluster bonded to its own image
    one = _atoms([[0.3, 0.3, 0.3]], cell=[1.0, 5.0, 5.0], pbc=True)
    f1 = fragments(one, b=1.15, r0=R0)
    assert f1.g.tolist() == [1] and f1.percolating.tolist() == [[True, False, False]]


def test_two_materials_bond_at_b_r0ab_and_volumes():
    # r0 = 1 and 2 Angstrom: r0_ab = 1.5, bond below 1.15 * 1.5 = 1.725
    pos = [[0, 0, 0], [1.7, 0, 0], [10, 0, 0], [11.75, 0, 0], [20, 0, 0], [22.2, 0, 0]]
    mid = [0, 1, 0, 1, 1, 1]                      # last pair: r0 = 2, bonded below 2.3
    a = _atoms(pos, material=mid)
    f = fragments(a, b=1.15, r0=[1.0, 2.0])
    assert f.g.tolist() == [2, 1, 1, 2]
    v0, v1 = 1.0 / math.sqrt(2), 8.0 / math.sqrt(2)
    assert f.volume == pytest.approx([v0 + v1, v0, v1, 2 * v1])
    assert f.diameter == pytest.approx(np.cbrt(6 * f.volume / math.pi))


def test_cd_sample_equivalent_diameter_and_default_b_from_the_calculator():
    from clusterdyn.build import fcc_packing
    from clusterdyn.calculators import ClusterDynamics
    r0 = 10 * units.um
    a = fcc_packing("Al", r0, size=(3, 3, 3), pbc=(False, True, True))
    a.calc = ClusterDynamics(rc=1.1)
    f = fragments(a)                                                       # b = rc = 1.1, r0 from info
    assert f.b == 1.1 and f.g.tolist() == [108]
    # 6 layers of 18 along x; 12 neighbours each, 4 fewer in the two open surface layers
    assert f.nbonds == (108 * 12 - 2 * 18 * 4) // 2
    assert f.percolating.tolist() == [[False, True, True]]
    assert f.diameter[0] == pytest.approx((6 * 108 * r0 ** 3 / math.sqrt(2) / math.pi) ** (1 / 3))
    assert f.mass[0] == pytest.approx(a.get_masses().sum())
    with pytest.raises(InputError, match="b="):
        fragments(fcc_packing("Al", r0, size=(2, 2, 2)))                   # no calculator, no b
    with pytest.raises(InputError, match="r0="):
        fragments(_atoms([[0, 0, 0]]), b=1.1)


def test_bad_pairs_and_exclude_are_refused():
    a = _atoms([[0, 0, 0], [1, 0, 0]])
    with pytest.raises(InputError, match="pairs"):
        fragments(a, pairs=([0], [2]), volumes=np.ones(2))
    with pytest.raises(InputError, match="exclude"):
        fragments(a, b=1.1, r0=R0, exclude=[0, 1])


def test_exclude_leaves_particles_out():
    a = _atoms([[k, 0.0, 0.0] for k in range(5)])
    ex = np.array([False, False, True, False, False])
    f = fragments(a, b=1.15, r0=R0, exclude=ex)
    assert f.labels.tolist() == [0, 0, -1, 1, 1] and f.g.tolist() == [2, 2]
    fp = fragments(a, pairs=(np.arange(4), np.arange(1, 5)), volumes=np.ones(5), exclude=ex)
    assert fp.labels.tolist() == f.labels.tolist()
    none = fragments(a, b=1.15, r0=R0, exclude=np.ones(5, bool))
    assert none.labels.tolist() == [-1] * 5 and none.n_fragments == 0
    assert fragments(_atoms(np.zeros((0, 3))), b=1.15, r0=R0).n_fragments == 0


def test_packed_images_round_trip_and_add():
    from numba import njit
    import clusterdyn.analysis.fragment_graph as F

    @njit
    def add(a, b):
        return F._unpack(F._pack(a[0], a[1], a[2]) + F._pack(b[0], b[1], b[2]))

    rng = np.random.default_rng(0)
    h = F.IMG_LIMIT // 2
    for _ in range(200):
        a, b = rng.integers(-h, h, 3), rng.integers(-h, h, 3)
        assert add(a, b) == tuple(a + b)
    assert add(np.array([F.IMG_LIMIT - 1, -F.IMG_LIMIT, 0]), np.zeros(3, np.int64)) == \
        (F.IMG_LIMIT - 1, -F.IMG_LIMIT, 0)


# ------------------------------------------------------------------ random configurations against scipy

@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("pbc", [False, True, (True, False, True)])
def test_random_gas_equals_scipy_connected_components(seed, pbc):
    from ase.neighborlist import neighbor_list
    rng = np.random.default_rng(seed)
    n = 3000
    L = np.array([26.0, 24.0, 25.0])                  # ~1.2 bonded neighbours each: many components
    a = _atoms(rng.random((n, 3)) * L, cell=L, pbc=pbc)
    f = fragments(a, b=1.15, r0=R0)
    i, j = neighbor_list("ij", a, 1.15 * R0)
    assert f.labels.tolist() == _scipy_labels(n, i, j).tolist()
    assert f.nbonds == len(i) // 2
    assert 50 < f.n_fragments < n
    # the same graph as an explicit pair list gives the same components
    fp = fragments(a, pairs=(i, j), volumes=np.ones(n))
    assert fp.labels.tolist() == f.labels.tolist()
    if np.any(pbc):
        # centres: the explicit minimum-image route and the cell-list route agree
        assert np.allclose(fp.com, f.com, atol=1e-9)


@pytest.mark.parametrize("seed", [3, 4])
def test_random_two_phase_equals_scipy(seed):
    from ase.neighborlist import neighbor_list
    rng = np.random.default_rng(seed)
    n = 2000
    L = np.full(3, 16.0)
    mid = rng.integers(0, 2, n)
    a = _atoms(rng.random((n, 3)) * L, cell=L, pbc=True, material=mid)
    r0 = np.array([1.0, 1.6])
    b = 1.2
    f = fragments(a, b=b, r0=r0)
    i, j, d = neighbor_list("ijd", a, b * r0.max())
    keep = d < b * 0.5 * (r0[mid[i]] + r0[mid[j]])
    assert f.labels.tolist() == _scipy_labels(n, i[keep], j[keep]).tolist()


# ------------------------------------------------------------------ MCA: linked pairs

def _mca_state(size=(8, 6, 6), pbc=False, crack_at=None):
    from clusterdyn.build.mca import mca_packing, precrack
    from clusterdyn.mca.calculator import MCA
    a = mca_packing("alumina", 1.0, size, pbc=pbc)
    if crack_at is not None:
        precrack(a, point=(crack_at, 0, 0), normal=(1, 0, 0))
    a.calc = MCA()
    return a, a.calc.setup(a)


@pytest.mark.parametrize("pbc", [False, (False, True, True)])
def test_mca_sample_cut_by_unlinked_pairs(pbc):
    a, st = _mca_state(pbc=pbc, crack_at=3.3)
    f = fragments(a, pairs=st)
    left = a.positions[:, 0] < 3.3
    assert f.n_fragments == 2
    assert f.labels.tolist() == np.where(left, f.labels[0], 1 - f.labels[0]).tolist()
    assert sorted(f.g.tolist()) == sorted([int(left.sum()), int((~left).sum())])
    i_p, j_p = st.pair_rows(a)[:2]
    lk = st.linked_p == 1
    assert f.labels.tolist() == _scipy_labels(len(a), i_p[lk], j_p[lk]).tolist()
    # with periodic y and z both halves are slabs bonded to their own images across them
    assert f.percolating.tolist() == [[False, bool(pbc), bool(pbc)]] * 2
    # volumes are the automata's cells: mass / volume is the density
    rho = a.info["mca_materials"][0].rho0
    assert f.mass / f.volume == pytest.approx(np.full(2, rho))
    # cut every link of one automaton: it becomes a fragment of its own
    i_p, j_p = st.pair_rows(a)[:2]
    k = int(np.argmin(np.linalg.norm(a.positions - a.positions.mean(axis=0), axis=1)))
    st.linked_p[(i_p == k) | (j_p == k)] = 0
    f3 = fragments(a, pairs=st)
    assert f3.n_fragments == 3 and f3.g[f3.labels[k]] == 1
    lk = st.linked_p == 1
    assert f3.labels.tolist() == _scipy_labels(len(a), i_p[lk], j_p[lk]).tolist()


# ------------------------------------------------------------------ observer, H5MD observables, files

def test_observer_records_counts_during_a_run_and_feeds_h5md(tmp_path):
    from clusterdyn.build import fcc_packing
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.io import H5MDWriter, H5MDReader
    from clusterdyn.md.damped import DampedVerlet
    r0 = 10 * units.um
    a = fcc_packing("Al", r0, size=(4, 2, 2))
    x = a.positions[:, 0]
    a.set_velocities(np.outer(np.where(x > x.mean(), 1.0, -1.0), [1.0, 0, 0]) * units.km_s)
    a.calc = ClusterDynamics(rc=1.15)
    dyn = DampedVerlet(a, J=None)
    obs = FragmentObserver(a, dyn=dyn, keep=True)
    online = FragmentAnalysis(None, b=1.15, r0=r0).attach(dyn, interval=20)     # the same analysis, online
    path = tmp_path / "pull.h5md"
    writer = H5MDWriter(str(path), a, dyn=dyn, observables=obs.observables())
    dyn.attach(obs, interval=20)
    dyn.attach(writer, interval=20)
    dyn.run(160)
    writer.close()
    rec = obs.arrays()
    assert rec["steps"].tolist() == list(range(0, 161, 20))
    assert rec["n_fragments"][0] == 1 and rec["n_fragments"][-1] == 2      # the pulled block parts
    assert rec["largest"][0] == 64 and rec["largest"][-1] == 32
    assert rec["times"] == pytest.approx(rec["steps"] * dyn.dt)
    # each record is the analysis of that frame
    assert [f.n_fragments for f in obs.results.fragments] == rec["n_fragments"].tolist()
    with H5MDReader(path) as rd:
        steps, _, nf = rd.get_observable("fragments_n_fragments")
        assert steps.tolist() == rec["steps"].tolist()
        assert nf.tolist() == rec["n_fragments"].tolist()
    # the file alone, every frame (b given: the file keeps no calculator)
    fa = FragmentAnalysis(path, b=1.15, r0=r0).run()
    assert fa.results.n_fragments.tolist() == rec["n_fragments"].tolist()
    assert fa.results.steps.tolist() == rec["steps"].tolist()
    assert fa.results.fragments[-1].velocity[:, 0] == pytest.approx(
        obs.results.fragments[-1].velocity[:, 0], rel=1e-5)
    online.conclude()
    assert online.results.steps.tolist() == rec["steps"].tolist() == online.frames
    assert online.results.n_fragments.tolist() == fa.results.n_fragments.tolist()
    assert online.results.largest.tolist() == fa.results.largest.tolist()
    fa2 = FragmentAnalysis(path, b=1.15, r0=r0, keep=False).run(start=2, step=3)
    assert fa2.results.frames.tolist() == [2, 5, 8] and "fragments" not in fa2.results


def test_plots_and_csv(tmp_path):
    a = _atoms([[k, 0.0, 0.0] for k in range(3)] + [[10.0, 0, 0], [20.0, 0, 0]], masses=[1, 1, 1, 2, 2])
    f = fragments(a, b=1.15, r0=R0)
    png, csvp = f.plot_spectrum(tmp_path / "spectrum")
    assert png.stat().st_size > 1000
    assert csvp.read_text().splitlines() == ["g,N", "1,2", "3,1"]
    png, csvp = f.plot_mass_distribution(tmp_path / "mass.png")
    rows = csvp.read_text().splitlines()[1:]
    assert [float(r.split(",")[1]) for r in rows] == pytest.approx([2 / 7, 4 / 7, 1.0])
    table = f.write_csv(tmp_path / "fragments.csv").read_text().splitlines()
    assert table[0].startswith("fragment,g,mass_kg,com_x_um") and len(table) == 4


def test_fragments_module_is_not_shadowed_by_its_function():
    import types

    import clusterdyn.analysis.fragments as F
    assert isinstance(F, types.ModuleType) and F.fragments is fragments
