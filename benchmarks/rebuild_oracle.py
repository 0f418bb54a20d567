"""How many list builds could a better rebuild test save?  The list's own test against an oracle.

    python benchmarks/rebuild_oracle.py                       # slab 128k, debris contact and cloud (123k)
    python benchmarks/rebuild_oracle.py --scenes slab --steps 100 --nx 128

From each saved state (the piston-shock slab of ``benchmarks/_states.py`` at 30%
shocked; the debris cloud of ``benchmarks/debris_cloud.py`` at steps 400 and
1 200, saved by ``benchmarks/debris_lammps.py``'s ``debris_state``) the run goes on
twice for ``--steps`` steps, one thread:

- with the list's own rigorous test (:meth:`clusterdyn.neighbors.NeighborList.update`:
  the global displacement test, then the local test over bricks), timing the
  list builds and the whole step with the process clock;
- with an oracle in its place: at every step the list is kept unless a pair within
  the cut-off is missing from it (every pair within the cut-off found by ASE's
  ``neighbor_list``, the list's pairs within the cut-off counted).  No rigorous test can
  rebuild less often than that.

The figure: builds per 100 steps with the test and with the oracle, and the most a
perfect test could save, ``build time x (1 - oracle/test)``, in ns per particle and step
and as a share of the step.  Results (written after each scene):
``benchmarks/results/rebuild_oracle.md``, ``.json``.  The oracle's search is ASE's, about
5 s a step at 131k clusters on the slab, far longer on the spread debris: ``--steps``
keeps it short.
"""

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _states import load_scene, scene_list, write_report  # noqa: E402
RESULTS = HERE / "results"


def oracle_moved(atoms):
    """A replacement of ``NeighborList._moved``: True only when a pair within the cut-off is missing."""
    import numpy as np
    from ase.neighborlist import neighbor_list

    def moved(self, pos, displacement=None):
        i, j = neighbor_list("ij", atoms, self.cutoff)
        need = int(np.count_nonzero(i < j))
        have = int(np.count_nonzero(self.pairs(pos)[3] < self.cutoff))
        return have < need
    return moved


def run(scene, a, oracle):
    import clusterdyn.neighbors.celllist as CL
    atoms, dyn = load_scene(scene, a)
    dyn.run(2)
    nl = atoms.calc.nl
    spent = [0.0]
    build = CL.NeighborList.build

    def timed_build(self, *args, **kw):
        t0 = time.process_time()
        r = build(self, *args, **kw)
        spent[0] += time.process_time() - t0
        return r
    moved = CL.NeighborList._moved
    CL.NeighborList.build = timed_build
    if oracle:
        CL.NeighborList._moved = oracle_moved(atoms)
    try:
        nb0 = nl.nbuilds
        t0 = time.process_time()
        for k in range(a.steps):
            dyn.run(1)
            if (k + 1) % max(1, a.steps // 10) == 0:
                print(f"  {scene} {'oracle' if oracle else 'test'}: step {k + 1}/{a.steps}, "
                      f"builds {nl.nbuilds - nb0}", flush=True)
        t = time.process_time() - t0
    finally:
        CL.NeighborList.build = build
        CL.NeighborList._moved = moved
    n = len(atoms)
    return {"N": n, "builds_per_100": 100.0 * (nl.nbuilds - nb0) / a.steps,
            "build_ns_ps": spent[0] / (a.steps * n) * 1e9, "step_ns_ps": t / (a.steps * n) * 1e9}


def write(rows, out):
    """The table and the JSON of the scenes done so far (written after each scene)."""
    lines = ["| scene | N | steps | builds / 100 steps, test | oracle | builds, ns/ps (test) | step, ns/ps (test) "
             "| most a perfect test saves |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['N']} | {r['steps']} | {r['test']['builds_per_100']:.1f} | "
                     f"{r['oracle']['builds_per_100']:.1f} | {r['test']['build_ns_ps']:.1f} | "
                     f"{r['test']['step_ns_ps']:.1f} | {r['most_saved_ns_ps']:.1f} ({r['most_saved_share']:.0%}) |")
    write_report(out, rows, lines)
    return lines


def main(argv=None):
    from debris_cloud import add_scene_args
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="slab,contact,cloud")
    ap.add_argument("--nx", type=int, default=128, help="slab length in cells (N = 1024 nx)")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--out", default=str(RESULTS / "rebuild_oracle"))
    add_scene_args(ap, 50.0, 6.0, 35.0)
    a = ap.parse_args(argv)
    scenes = scene_list(ap, a.scenes)
    from clusterdyn.parallel import set_max_threads
    set_max_threads(1)
    rows = []
    for s in scenes:
        test = run(s, a, False)
        orc = run(s, a, True)
        save = test["build_ns_ps"] * (1.0 - orc["builds_per_100"] / max(test["builds_per_100"], 1e-300))
        rows.append({"scene": s, "N": test["N"], "steps": a.steps, "test": test, "oracle": orc,
                     "most_saved_ns_ps": save, "most_saved_share": save / test["step_ns_ps"]})
        print(f"{s}: N {test['N']}, builds per 100 steps {test['builds_per_100']:.1f} (test) / "
              f"{orc['builds_per_100']:.1f} (oracle); builds {test['build_ns_ps']:.1f} of {test['step_ns_ps']:.1f} "
              f"ns per particle-step; a perfect test saves at most {save:.1f} ({save / test['step_ns_ps']:.0%})",
              flush=True)
        lines = write(rows, a.out)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
