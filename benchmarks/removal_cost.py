"""What a removal of particles costs, part by part, on the 123k debris cloud.

    python benchmarks/removal_cost.py
    PYTHONPATH=/path/to/other/tree python benchmarks/removal_cost.py      # another version

The debris cloud of ``debris_cloud.py`` at 123k clusters (sphere 50 r0, plate 6 x 35 r0,
6.7 km/s, J = 50, time step 0.03 r0/(c0 + v), Atoms sorted every 100 steps), one thread,
with a region of interest ``--region`` (1.15) times the initial bounding box, so that
particles leave it from about step 300 on; removal every ``--remove-interval`` (20) steps.
After ``--warmup`` (600) steps, ``--steps`` (600) more are timed (process CPU time):
each part of :meth:`clusterdyn.md.DampedVerlet.remove_outside` that the imported version has
(the region test, the pair pass over the removed particles' pairs, the moves of the Atoms'
rows, the list's compaction or the builds, the force passes), in ns per particle (at the
start of the window) per removal check, beside the same run without a region (whose force
passes and builds are the steps' own), and each run's ns per particle-step.  Timers wrap the functions (a few microseconds a call).
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def run(a, region):
    from debris_cloud import build
    import clusterdyn.md.damped as D
    a.region = region
    atoms, dyn = build(a, region > 0)
    calc = atoms.calc
    nl = calc.nl
    dyn.run(a.warmup)
    T = {}

    def wrap(obj, name, key):
        f = getattr(obj, name, None)
        if f is None:
            return

        def g(*x, **k):
            t = time.process_time()
            r = f(*x, **k)
            T[key] = T.get(key, 0.0) + time.process_time() - t
            return r
        setattr(obj, name, g)
    parts = [(dyn, "remove_outside", "removal check, all of it"), (dyn.region, "outside", "region test"),
             (dyn.region, "inside", "region test"), (calc, "pairs_touching", "pass over the removed pairs"),
             (calc, "pair_energy_touching", "pass over the removed pairs"), (D, "_compact", "moving the Atoms' rows"),
             (calc, "removed", "list compaction"), (nl, "build", "list builds (all)"),
             (dyn, "_compute_forces", "force passes (all)")]
    for obj, name, key in parts:
        if obj is not None:
            wrap(obj, name, key)
    n0, b0, r0 = len(atoms), nl.nbuilds, dyn.removed["count"]
    t0 = time.process_time()
    dyn.run(a.steps)
    tot = time.process_time() - t0
    nmean = 0.5 * (n0 + len(atoms))
    checks = a.steps // a.remove_interval
    return {"n0": n0, "n1": len(atoms), "removed": dyn.removed["count"] - r0, "builds": nl.nbuilds - b0,
            "step": tot / (nmean * a.steps) * 1e9, "parts": {k: v / (n0 * checks) * 1e9 for k, v in T.items()}}


def main(argv=None):
    from debris_cloud import add_scene_args
    from clusterdyn.parallel import set_max_threads
    import clusterdyn
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_scene_args(ap, 50.0, 6.0, 35.0)
    ap.add_argument("--region", type=float, default=1.15)
    ap.add_argument("--remove-interval", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=600)
    ap.add_argument("--steps", type=int, default=600)
    a = ap.parse_args(argv)
    a.dt_factor = 0.03
    set_max_threads(1)
    rm = run(a, a.region)
    keep = run(a, 0.0)
    print(f"clusterdyn {Path(clusterdyn.__file__).parent.parent}: N {rm['n0']} -> {rm['n1']} over steps "
          f"{a.warmup}-{a.warmup + a.steps} ({rm['removed']} removed, {a.steps // a.remove_interval} checks); "
          f"list builds {rm['builds']} with removal, {keep['builds']} without")
    print("| part (ns per particle per removal check) | with removal | without |\n|---|---:|---:|")
    for k, v in rm["parts"].items():
        w = keep["parts"].get(k)
        print(f"| {k} | {v:.1f} | {'-' if w is None else f'{w:.1f}'} |")
    print(f"\nwhole step: {rm['step']:.1f} ns per particle-step with removal, {keep['step']:.1f} without")


if __name__ == "__main__":
    main()
