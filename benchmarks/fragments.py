"""Fragment analysis of one million clusters on one core, against scipy's connected_components.

    python benchmarks/fragments.py                     # 1M clusters, 3 repeats per sample
    python benchmarks/fragments.py --n 100000 --repeats 1

Samples (N ~ 1e6 each, aluminium, r0 = 10 um, b = rc = 1.15):

* ``fcc-125-pieces``: an fcc block (open box) cut into 5 x 5 x 5 blocks moved
  apart by 2 r0, with 1% r0 noise: 125 fragments, checked;
* ``fcc-slab-periodic``: the same block, periodic across y and z, intact
  (a shock sample: one fragment, percolating across y and z);
* ``gas-zX``: particles placed uniformly at random in a periodic cube at the
  density giving X bonded neighbours per particle on average (0.8: dust;
  2.7: near the continuum percolation threshold; 6: one big cluster).

For each sample: the wall time of :func:`clusterdyn.analysis.fragments`
(cell-list pair search + union-find + per-fragment properties) on one thread
(``NUMBA_NUM_THREADS=1`` and ``set_max_threads(1)``), best and worst of
``--repeats`` after a warm-up call, clusters per second, and the 2 s target.
The peer: ``scipy.sparse.csgraph.connected_components`` on the same pair list
(the bonded pairs, taken from the same cell list), timed with and without
building its CSR matrix; beside it our union-find on that explicit pair list
(``pairs=``).  The components are checked equal.  The machine is shared:
the load average is printed; run the script several times.  Results go to
``benchmarks/results/fragments.md`` and ``.json`` (``--out`` to rename).
"""

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from clusterdyn import units  # noqa: E402
from clusterdyn.analysis.fragments import FragmentFinder  # noqa: E402
from clusterdyn.build import fcc_packing  # noqa: E402
from clusterdyn.build.lattice import make_cluster_atoms  # noqa: E402
from clusterdyn.parallel import set_max_threads  # noqa: E402

R0 = 10 * units.um
B = 1.15
TARGET_S = 2.0


def fcc_block(n, pbc, pieces=0, seed=0):
    """An fcc block of about n clusters; ``pieces`` > 0 cuts it into pieces^3 blocks moved apart."""
    k = max(1, round((n / 4) ** (1 / 3)))
    a = fcc_packing("Al", R0, size=(k, k, k), pbc=pbc)
    rng = np.random.default_rng(seed)
    a.positions += rng.normal(0.0, 0.01 * R0, a.positions.shape)
    if pieces:
        L = a.cell.diagonal()
        idx = np.minimum((a.positions / L * pieces).astype(int), pieces - 1)
        a.positions += idx * 2.0 * R0              # 2 r0 gaps: no bond across a cut
        a.cell = L + pieces * 2.0 * R0
    return a


def gas(n, z, seed=0):
    """n clusters uniform in a periodic cube, density giving z neighbours within b r0 on average."""
    rho = z / (4.0 / 3.0 * math.pi * (B * R0) ** 3)
    L = (n / rho) ** (1 / 3)
    rng = np.random.default_rng(seed)
    return make_cluster_atoms(rng.random((n, 3)) * L, ["Al"], [R0], cell=np.diag([L] * 3), pbc=True)


def canonical(labels):
    _, first, inv = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[inv]


def bench_sample(name, atoms, repeats, expect=None):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n = len(atoms)
    finder = FragmentFinder(B)
    f = finder.find(atoms)                        # warm-up (kernels from the on-disk cache)
    walls, phases = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        f = finder.find(atoms)
        walls.append(time.perf_counter() - t)
        phases.append(f.meta["timings_s"])
    if expect is not None and f.n_fragments != expect:
        raise SystemExit(f"{name}: {f.n_fragments} fragments, expected {expect}")
    # the same bonded pairs for the peer, from the same cell list
    i_p, j_p, _, r_p = finder._nl.pairs(atoms.positions)
    keep = r_p < B * R0
    i_p, j_p = i_p[keep], j_p[keep]
    assert len(i_p) == f.nbonds
    t_sp, t_cc, t_ours = [], [], []
    finder.find(atoms, pairs=(i_p, j_p))          # warm-up of the explicit-pairs route
    for _ in range(repeats):
        t = time.perf_counter()
        g = coo_matrix((np.ones(len(i_p), np.int8), (i_p, j_p)), shape=(n, n)).tocsr()
        t1 = time.perf_counter()
        nc, lab = connected_components(g, directed=False)
        t2 = time.perf_counter()
        t_sp.append(t2 - t)
        t_cc.append(t2 - t1)
        fp = finder.find(atoms, pairs=(i_p, j_p))
        t_ours.append(fp.meta["timings_s"]["union_find"])
    same = nc == f.n_fragments and np.array_equal(canonical(lab), f.labels)
    best = int(np.argmin(walls))
    row = {
        "sample": name, "N": n, "fragments": f.n_fragments, "largest_g": int(f.g.max()),
        "bonds": f.nbonds, "wall_best_s": min(walls), "wall_worst_s": max(walls),
        "clusters_per_s": n / min(walls), "target_s": TARGET_S, "within_target": min(walls) <= TARGET_S,
        "phases_s": phases[best],
        "scipy_cc_s": min(t_cc), "scipy_with_csr_s": min(t_sp), "ours_union_on_pairs_s": min(t_ours),
        "same_components": bool(same),
    }
    print(f"{name:20s} N={n:8d} F={f.n_fragments:7d} bonds={f.nbonds:8d} | clusterdyn "
          f"{row['wall_best_s']:.3f} s (worst {row['wall_worst_s']:.3f}) = "
          f"{row['clusters_per_s'] / 1e6:.2f} M clusters/s "
          f"[search {phases[best]['pair_search']:.3f}, union {phases[best]['union_find']:.3f}, "
          f"props {phases[best]['properties']:.3f}] {'<=' if row['within_target'] else '>'} {TARGET_S:g} s | "
          f"scipy cc {row['scipy_cc_s']:.3f} s (+CSR {row['scipy_with_csr_s']:.3f}), our union on the "
          f"pair list {row['ours_union_on_pairs_s']:.3f} s | same components: {same}", flush=True)
    return row


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1_000_000, help="clusters per sample (default 1e6)")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per sample (default 3)")
    p.add_argument("--out", default="fragments", help="results/<out>.md and .json")
    a = p.parse_args(argv)
    set_max_threads(1)
    import numba
    print(f"numba threads: {numba.config.NUMBA_NUM_THREADS}; load average {os.getloadavg()}", flush=True)
    rows = []
    t0 = time.perf_counter()
    rows.append(bench_sample("fcc-125-pieces", fcc_block(a.n, False, pieces=5), a.repeats, expect=125))
    rows.append(bench_sample("fcc-slab-periodic", fcc_block(a.n, (False, True, True)), a.repeats, expect=1))
    for z in (0.8, 2.7, 6.0):
        rows.append(bench_sample(f"gas-z{z:g}", gas(a.n, z), a.repeats))
    info = {"machine": platform.platform(), "python": sys.version.split()[0], "numba": numba.__version__,
            "load_average_end": os.getloadavg(), "threads": 1, "b": B, "r0_um": R0 / units.um,
            "total_s": time.perf_counter() - t0}
    res = HERE / "results"
    res.mkdir(exist_ok=True)
    (res / f"{a.out}.json").write_text(json.dumps({"info": info, "rows": rows}, indent=1, default=float))
    lines = ["# Fragment analysis, one thread", "",
             f"{info['machine']}, load average at the end {info['load_average_end']}; b = {B}, "
             f"r0 = {R0 / units.um:g} um; best (worst) of {a.repeats} calls after a warm-up.", "",
             "| sample | N | fragments | bonds | wall s | M clusters/s | search / union / props s | "
             "scipy cc s (+CSR) | our union on pairs s | same |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ph = r["phases_s"]
        lines.append(f"| {r['sample']} | {r['N']} | {r['fragments']} | {r['bonds']} "
                     f"| {r['wall_best_s']:.3f} ({r['wall_worst_s']:.3f}) | {r['clusters_per_s'] / 1e6:.2f} "
                     f"| {ph['pair_search']:.3f} / {ph['union_find']:.3f} / {ph['properties']:.3f} "
                     f"| {r['scipy_cc_s']:.3f} ({r['scipy_with_csr_s']:.3f}) "
                     f"| {r['ours_union_on_pairs_s']:.3f} | {r['same_components']} |")
    (res / f"{a.out}.md").write_text("\n".join(lines) + "\n")
    worst = max(r["wall_best_s"] for r in rows)
    print(f"slowest sample {worst:.3f} s against the {TARGET_S:g} s target: "
          f"{'met' if worst <= TARGET_S else 'MISSED'}; total {info['total_s']:.0f} s")
    return 0 if all(r["same_components"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
