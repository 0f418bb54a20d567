"""Where a step of the aluminium piston shock spends its time, on 1 and 2 threads.

    python benchmarks/profile_step.py --nx 128 --J none --rounds 8

One process, one scene (``build_shock``, cross-section 16 x 16 cells, N =
1024 x nx/4): after ``--warmup`` steps, rounds of ``--steps`` steps on one
thread and then on two alternate; timers around the force loop, the list
builds, the fused kick-drift-gather pass and the force sum give each part's
time per particle and step (median over rounds), and each part's two-thread
efficiency (median of the rounds' own).  "other" is the rest of the step:
Python, constraints and checks.  The timers add a few microseconds a call.
"""

import argparse
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nx", type=int, default=128, help="sample length in cells (N = 1024 nx / 4)")
    ap.add_argument("--J", default="none", help="damping J, or none")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=40)
    a = ap.parse_args(argv)

    from clusterdyn import units
    from clusterdyn.parallel import set_max_threads
    from clusterdyn.scenes.shock import build_shock
    import clusterdyn.calculators._cd_kernels as K
    import clusterdyn.calculators.cluster as C
    import clusterdyn.neighbors.celllist as CL

    acc = {}

    def timed(name, f):
        def g(*args, **kw):
            t0 = time.perf_counter()
            r = f(*args, **kw)
            acc[name] = acc.get(name, 0.0) + time.perf_counter() - t0
            return r
        return g

    parts = ("force loop", "list builds", "kick-drift-gather", "force sum")
    for key in list(K.KERNELS):
        K.KERNELS[key] = timed(parts[0], K.KERNELS[key])
    CL.NeighborList.build = timed(parts[1], CL.NeighborList.build)
    C.kick_drift_gather = timed(parts[2], C.kick_drift_gather)
    K.reduce_rows = timed(parts[3], K.reduce_rows)
    K.reduce_shared = timed(parts[3], K.reduce_shared)

    s = build_shock(size=(a.nx, 16, 16), u=3 * units.km_s, J=None if a.J == "none" else float(a.J))
    s.dyn.run(a.warmup)
    n = len(s.atoms)
    per = {1: {}, 2: {}}
    for _ in range(a.rounds):
        for th in (1, 2):
            set_max_threads(th)
            acc.clear()
            t0 = time.perf_counter()
            s.dyn.run(a.steps)
            acc["whole step"] = time.perf_counter() - t0
            acc["other"] = acc["whole step"] - sum(acc.get(p, 0.0) for p in parts)
            for k in parts + ("other", "whole step"):
                per[th].setdefault(k, []).append(acc.get(k, 0.0) / (a.steps * n) * 1e9)
    print(f"N = {n}, J = {a.J}: {a.rounds} rounds of {a.steps} steps on 1 then 2 threads; "
          "ns per particle and step, medians over rounds")
    print(f"| part | 1 thread | 2 threads | efficiency |\n|---|---|---|---|")
    for k in parts + ("other", "whole step"):
        t1, t2 = np.array(per[1][k]), np.array(per[2][k])
        eff = f"{np.median(t1 / t2) / 2:.0%}" if k != "other" and t2.min() > 0 else ""
        print(f"| {k} | {np.median(t1):.1f} | {np.median(t2):.1f} | {eff} |")


if __name__ == "__main__":
    main()
