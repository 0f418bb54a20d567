"""A step's fixed cost: microseconds a step against N on small scenes, for one or two checkouts.

    python benchmarks/step_overhead.py                         # this checkout
    python benchmarks/step_overhead.py --against /path/to/older/checkout --rounds 5

The scene is a periodic fcc box of aluminium clusters (r0 = 5 um, ``fcc_packing``,
4 n^3 clusters for ``--sizes n``), 30 m/s thermal noise (seed 1), NVE
(``DampedVerlet`` without damping, no drives), one thread: the engine's own per-step
cost, with nothing a scene adds.  Each worker is a fresh process that steps 100
steps, then times ``--repeat`` windows of ``--steps`` steps and keeps the fastest
(the process' CPU time: on a shared machine it leaves out the time the process waited for a
core; one thread, so it is the step's own time).  With ``--against``, workers of the two
checkouts alternate (each import of ``clusterdyn`` from its own tree through ``PYTHONPATH``)
and each N's
line gives the median of the rounds for both, their ratio and whether the final
positions agree to the bit.  A straight line t = a + b N fitted to each checkout's
medians gives the fixed cost a (us a step) and the cost b a particle (ns a
particle-step).  Writes ``--out``.md, .json, .csv and .png.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def worker(n, steps, repeat):
    import hashlib

    import numba
    from clusterdyn import units
    from clusterdyn.build import fcc_packing
    from clusterdyn.calculators.cluster import ClusterDynamics
    from clusterdyn.md.damped import DampedVerlet
    from clusterdyn.parallel import set_max_threads
    set_max_threads(1)
    a = fcc_packing("Al", 5 * units.um, size=(n, n, n), pbc=True)
    a.calc = ClusterDynamics()
    rng = np.random.default_rng(1)
    a.set_momenta(a.get_masses()[:, None] * rng.normal(0.0, 30 * units.m_s, (len(a), 3)))
    dyn = DampedVerlet(a, J=None)
    dyn.run(100)
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        dyn.run(steps)
        best = min(best, (time.process_time() - t0) / steps)
    print(json.dumps({"N": len(a), "us": best * 1e6, "builds": dyn.calc.nl.nbuilds,
                      "positions": hashlib.sha1(np.ascontiguousarray(a.positions).tobytes()).hexdigest(),
                      "numba": numba.__version__}))


def _label(tree):
    """The checkout's commit (with "+ changes" when its tracked files differ from it)."""
    try:
        rev = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
        return rev + (" + changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "not a git checkout"


def _run(tree, n, steps, repeat):
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", str(n), "--steps", str(steps),
                          "--repeat", str(repeat)], env=env, capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"worker ({tree}, n={n}) failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--sizes", default="2,3,4,6,8", help="box sides n in fcc cells (N = 4 n^3)")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--against", default=None, help="another checkout to time in alternation")
    ap.add_argument("--out", default=str(HERE / "results" / "step_overhead"))
    a = ap.parse_args(argv)
    if a.worker is not None:
        return worker(a.worker, a.steps, a.repeat)
    for name, v, lo in (("steps", a.steps, 1), ("repeat", a.repeat, 1), ("rounds", a.rounds, 1)):
        if v < lo:
            raise SystemExit(f"--{name} = {v}: at least {lo}")
    sizes = [int(s) for s in a.sizes.split(",")]
    if any(s < 2 for s in sizes):
        raise SystemExit(f"--sizes = {a.sizes}: box sides of at least 2 cells")
    here = HERE.parent
    trees = {"this": here}
    if a.against:
        other = Path(a.against).resolve()
        if not (other / "clusterdyn" / "__init__.py").exists():
            raise SystemExit(f"--against = {a.against}: not a clusterdyn checkout (no clusterdyn/__init__.py)")
        trees["against"] = other
    rows = []
    t_start = time.perf_counter()
    total = len(sizes) * a.rounds * len(trees)
    done = 0
    for n in sizes:
        got = {k: [] for k in trees}
        for _ in range(a.rounds):
            for k, tree in trees.items():
                got[k].append(_run(tree, n, a.steps, a.repeat))
                done += 1
                el = time.perf_counter() - t_start
                print(f"  {done}/{total} runs, {el:.0f} s, about {el / done * (total - done):.0f} s left", flush=True)
        row = {"N": got["this"][0]["N"]}
        for k in trees:
            row[f"{k}_us"] = statistics.median(r["us"] for r in got[k])
            row[f"{k}_rounds"] = [r["us"] for r in got[k]]
        if "against" in trees:
            row["ratio"] = row["against_us"] / row["this_us"]
            row["same_positions"] = len({r["positions"] for k in trees for r in got[k]}) == 1
        rows.append(row)
        line = f"N = {row['N']}: this {row['this_us']:.1f} us a step"
        if "against" in trees:
            line += (f", against {row['against_us']:.1f}, against/this {row['ratio']:.2f}, "
                     f"same positions: {row['same_positions']}")
        print(line, flush=True)
    labels = {k: _label(t) for k, t in trees.items()}
    fits = {}
    N = np.array([r["N"] for r in rows], float)
    for k in trees:
        t = np.array([r[f"{k}_us"] for r in rows])
        b, c = np.polyfit(N, t, 1) if len(rows) > 1 else (np.nan, np.nan)
        fits[k] = {"fixed_us": float(c), "ns_per_particle": float(b * 1e3)}
    from _common import write_report
    cmd = (f"python benchmarks/step_overhead.py --sizes {a.sizes} --steps {a.steps} --repeat {a.repeat} "
           f"--rounds {a.rounds}" + (f" --against <a checkout of {labels['against']}>" if a.against else ""))
    lines = ["# A step's fixed cost (periodic fcc box, NVE, one thread)", "", f"    {cmd}", ""]
    head = "| N | this: us a step | particle-steps/s |"
    sep = "|---:|---:|---:|"
    if a.against:
        head += " against: us a step | against / this | same positions |"
        sep += "---:|---:|---|"
    lines += [head, sep]
    for r in rows:
        s = f"| {r['N']} | {r['this_us']:.1f} | {r['N'] / r['this_us'] * 1e6:.3g} |"
        if a.against:
            s += f" {r['against_us']:.1f} | {r['ratio']:.2f} | {r['same_positions']} |"
        lines.append(s)
    lines += ["", "Straight line t = a + b N through the medians:", ""]
    for k, f in fits.items():
        lines.append(f"- {k} ({labels[k]}): fixed cost a = {f['fixed_us']:.1f} us a step, "
                     f"b = {f['ns_per_particle']:.1f} ns a particle-step")
    lines += ["", "Each N's rounds (us a step, in the order run):", ""]
    for r in rows:
        lines.append(f"- N = {r['N']}: " + "; ".join(
            f"{k} " + ", ".join(f"{x:.0f}" for x in r[f"{k}_rounds"]) for k in trees))
    md = write_report(a.out, {"command": cmd, "rows": rows, "fits": fits, "trees": labels}, lines)
    import csv
    with open(Path(a.out).with_suffix(".csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["N"] + [f"{k}_us_per_step" for k in trees])
        for r in rows:
            w.writerow([r["N"]] + [f"{r[f'{k}_us']:.3f}" for k in trees])
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for k in trees:
        ax.plot(N, [r[f"{k}_us"] for r in rows], "o-", label=f"{k} ({labels[k]}): a = {fits[k]['fixed_us']:.0f} us")
    ax.set_xlabel("clusters N")
    ax.set_ylabel("us a step (one thread)")
    ax.set_title("A step's cost on a small periodic box")
    ax.legend()
    fig.tight_layout()
    fig.savefig(Path(a.out).with_suffix(".png"), dpi=120)
    print(md.read_text())


if __name__ == "__main__":
    main()
