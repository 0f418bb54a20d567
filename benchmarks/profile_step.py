"""Where a step of the aluminium piston shock spends its time, on 1 and 2 threads.

    python benchmarks/profile_step.py --nx 128 --J none --rounds 8
    python benchmarks/profile_step.py --nx 128 --fraction 0.3 --threads 1 --clock process

One process, one scene (``build_shock``, cross-section 16 x 16 cells, N =
1024 nx): after ``--warmup`` steps, or from the saved state at ``--fraction``
of the sample shocked (``benchmarks/_states.py``), rounds of ``--steps`` steps
on each thread count alternate; timers around the force loop, the list
builds, the fused kick-drift-gather pass and the force sum give each part's
time per particle and step (median over rounds), and each part's two-thread
efficiency (median of the rounds' own).  "other" is the rest of the step:
Python, constraints and checks.  The timers add a few microseconds a call.
``--clock process`` times with the process' CPU time instead of the wall
clock (one thread only: on a loaded machine it leaves out the time the
process waited for a core).  ``--sort-every-build`` sorts the Atoms into
the list's row order after every step that rebuilt the list
(:meth:`clusterdyn.md.DampedVerlet.sort_atoms`, timed as "sorts"), so that
the list's permutation is the identity between builds.  The first line gives
the listed pairs per particle (the pair loop's work) beside the builds.
``--detail`` adds rows for the parts of the builds and of "other" (indented:
they are inside the rows above them): the cell sort (keys, sort, gather of
the sorted rows), the pair fill, the slabs' compaction, the local test's
bricks, the chunk layout of a new list (in "other") and the rebuild test (in
"other": the local test over bricks when the global one fails).  The
script profiles whatever ``clusterdyn`` is imported, so
``PYTHONPATH=/path/to/other/tree`` profiles another version.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nx", type=int, default=128, help="sample length in cells (N = 1024 nx)")
    ap.add_argument("--J", default="none", help="damping J, or none")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=40)
    ap.add_argument("--fraction", type=float, default=None,
                    help="start from the saved state with this fraction shocked (instead of --warmup steps)")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--clock", choices=("wall", "process"), default="wall")
    ap.add_argument("--detail", action="store_true",
                    help="also time the builds' parts, the chunk layout and the rebuild test")
    ap.add_argument("--sort-every-build", action="store_true",
                    help="sort the Atoms into the list's row order after every step that rebuilt the list")
    a = ap.parse_args(argv)

    import clusterdyn
    from clusterdyn import units
    from clusterdyn.parallel import set_max_threads
    import clusterdyn.calculators._cd_kernels as K
    import clusterdyn.calculators.cluster as C
    import clusterdyn.neighbors.celllist as CL

    clock = time.perf_counter if a.clock == "wall" else time.process_time
    acc = {}

    def timed(name, f):
        def g(*args, **kw):
            t0 = clock()
            r = f(*args, **kw)
            acc[name] = acc.get(name, 0.0) + clock() - t0
            return r
        return g

    parts = ("force loop", "list builds", "kick-drift-gather", "force sum") + (("sorts",) if a.sort_every_build else ())
    for key in list(K.KERNELS):
        K.KERNELS[key] = timed(parts[0], K.KERNELS[key])
    CL.NeighborList.build = timed(parts[1], CL.NeighborList.build)
    C.kick_drift_gather = timed(parts[2], C.kick_drift_gather)
    K.reduce_rows = timed(parts[3], K.reduce_rows)
    K.reduce_shared = timed(parts[3], K.reduce_shared)
    sub = ()
    if a.detail:
        # (row, where it is timed): module-level functions looked up when called, so wrapping
        # the module attribute times every call
        sub = (("  build: cell sort", CL, ("_cell_keys", "_count_sort", "_radix_sort", "_gather_sorted")),
               ("  build: pair fill", CL, ("_fill_slabs",)),
               ("  build: slab compaction", CL, ("_close_slabs",)),
               ("  build: bricks", CL.NeighborList, ("_set_bricks",)),
               ("  other: chunk layout", K, ("chunk_layout",)),
               ("  other: rebuild test", CL.NeighborList, ("_moved",)))
        for row, owner, names in sub:
            for name in names:
                setattr(owner, name, timed(row, getattr(owner, name)))
        sub = tuple(row for row, _, _ in sub)

    J = None if a.J == "none" else float(a.J)
    if a.fraction is None:
        from clusterdyn.scenes.shock import build_shock
        s = build_shock(size=(a.nx, 16, 16), u=3 * units.km_s, J=J)
        dyn, atoms = s.dyn, s.atoms
        dyn.run(a.warmup)
        where = f"after {a.warmup} steps"
    else:
        from _states import load_state, shock_state
        atoms, dyn, extra = load_state(shock_state(a.nx, a.fraction), J=J)
        dyn.run(2)
        where = f"from step {dyn.nsteps - 2}, {extra['shocked_fraction']:.0%} shocked"
    if a.sort_every_build:
        dyn.set_sort_interval(10 ** 9)      # readies the Atoms for sorts; the observer below sorts
        sort = timed("sorts", dyn.sort_atoms)
        last = [atoms.calc.nl.nbuilds]

        def sort_after_build():
            if atoms.calc.nl.nbuilds != last[0]:
                sort()
                last[0] = atoms.calc.nl.nbuilds
        dyn.attach(sort_after_build, interval=1)
        sort()
    n = len(atoms)
    threads = [int(t) for t in a.threads.split(",")]
    pairs = []
    per = {t: {} for t in threads}
    builds = {t: 0 for t in threads}
    for _ in range(a.rounds):
        for th in threads:
            set_max_threads(th)
            acc.clear()
            nb0 = atoms.calc.nl.nbuilds
            t0 = clock()
            dyn.run(a.steps)
            acc["whole step"] = clock() - t0
            builds[th] += atoms.calc.nl.nbuilds - nb0
            pairs.append(atoms.calc.nl.npairs / n)
            acc["other"] = acc["whole step"] - sum(acc.get(p, 0.0) for p in parts)
            for k in parts + ("other", "whole step") + sub:
                per[th].setdefault(k, []).append(acc.get(k, 0.0) / (a.steps * n) * 1e9)
    import os
    print(f"clusterdyn {Path(clusterdyn.__file__).parent.parent}: N = {n}, J = {a.J}, {where}: {a.rounds} rounds "
          f"of {a.steps} steps on {', '.join(map(str, threads))} thread(s), {a.clock} clock; ns per particle and "
          f"step, medians over rounds; list builds per 100 steps: "
          + ", ".join(f"{100 * builds[t] / (a.rounds * a.steps):.1f}" for t in threads)
          + f"; listed pairs per particle {np.median(pairs):.2f}"
          + ("; Atoms sorted after every build" if a.sort_every_build else "")
          + f"; load average {os.getloadavg()[0]:.1f}")
    head = "| part | " + " | ".join(f"{t} thread(s)" for t in threads) + (" | efficiency |" if len(threads) == 2 else " |")
    print(head + "\n|" + "---|" * (len(threads) + 1 + (len(threads) == 2)))
    for k in parts + ("other", "whole step") + sub:
        row = [f"{np.median(per[t][k]):.1f}" for t in threads]
        if len(threads) == 2:
            t1, t2 = np.array(per[threads[0]][k]), np.array(per[threads[1]][k])
            row.append(f"{np.median(t1 / t2) / 2:.0%}" if k != "other" and t2.min() > 0 else "")
        print(f"| {k} | " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
