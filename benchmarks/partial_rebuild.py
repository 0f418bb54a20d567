"""Would partial list rebuilds pay?  Renewing only the bricks that fail the local test, emulated.

    python benchmarks/partial_rebuild.py                          # debris contact and cloud (123k), bricks 8, 4, 2
    python benchmarks/partial_rebuild.py --scenes contact --sides 4 --steps 60
    python benchmarks/partial_rebuild.py --scenes slab --sides 8,4,2,1 --out benchmarks/results/partial_rebuild_slab

The list's rebuild test (:meth:`clusterdyn.neighbors.NeighborList.update`) bounds the
change of every unlisted pair by bricks: two bricks a, b pass when |centre_a - centre_b| +
R_a + R_b (their displacement boxes' centres and radii) is at most max(skin, S_ab - rc), S_ab
the distance between their reference positions' boxes.  A common motion of a neighbourhood
passes; a rebuild renews every row.  A partial rebuild would renew only the rows of failing
bricks: their particles' reference positions X become the current ones (the pairs of a
renewed particle searched against every other particle's X, the invariant "an unlisted
pair was at least cutoff + skin apart in X" kept), the others keep theirs.

This script asks what that would save before building it.  From the saved debris states
(``benchmarks/debris_cloud.py``'s 123k cloud at step 400, the contact, and 1 200, the
cloud; saved by ``benchmarks/debris_lammps.py``'s ``debris_state``), or from the race's
piston-shock state (``slab``: 31% shocked, undamped, ``benchmarks/_states.py``) the run goes on for
``--steps`` steps, one thread, with the list's own test and builds (its bricks of 8
cut-offs; the physics is not touched).  Beside it, emulated references X are kept: after each step the bricks' test is
evaluated on X with the list's own kernels (every pair of bricks compared); the failing bricks
are renewed (X = x there), and since a renewed brick's displacement restarts from zero while
its quiet neighbours' does not, the test is evaluated again and the new failures renewed,
until it passes (the closure).  A renewal of more than ``--full-at`` of the particles is
counted as a full build (X = x everywhere, bricks assigned anew).

The figure per scene and brick side: renewal events and full builds per 100 steps against
the list's own builds, the median share renewed, and the work in full builds' worth of rows
(a share f of the rows costs f builds: optimistic, a real partial search needs the full
stencil), plus the chunk layout that every change of rows needs (measured in the run) once
per event: what partial rebuilds would cost at best, against what the list's builds cost.
Results: ``benchmarks/results/partial_rebuild.md``, ``.json`` (written after each case).
"""

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
RESULTS = HERE / "results"

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from clusterdyn.neighbors.celllist import _brick_pair_safe  # noqa: E402
from _states import load_scene, scene_list, write_report  # noqa: E402


@njit(cache=True)
def failing_bricks(mid_b3, rad_b2, blo_b3, bhi_b3, box_c, periodic_c, skin, rc, out_b):
    """Every pair of bricks through the list's own pair test (:func:`_brick_pair_safe`); out_b[a]
    True when brick a fails with itself or another brick."""
    nb = mid_b3.shape[0]
    for a in range(nb):
        out_b[a] = not rad_b2[a, 0] + rad_b2[a, 1] <= skin
    for a in range(nb):
        for b in range(a + 1, nb):
            if not _brick_pair_safe(a, b, mid_b3, rad_b2, blo_b3, bhi_b3, box_c, periodic_c, skin, rc):
                out_b[a] = True
                out_b[b] = True


class Emulated:
    """Reference positions X and bricks of an emulated partially rebuilt list."""

    def __init__(self, atoms, template, full_at, side):
        import clusterdyn.neighbors.celllist as CL
        self.CL = CL
        self.side = side
        self.atoms = atoms
        self.nl = CL.NeighborList(template.cutoff, template.skin, half=True, sort=True, centered=True)
        self.full_at = full_at
        self.full(atoms.positions)

    def full(self, x):
        keep, self.CL.BRICK_SIDE = self.CL.BRICK_SIDE, self.side     # the emulated list's bricks only
        try:
            self.nl.build(x, self.atoms.cell.array, self.atoms.pbc)
        finally:
            self.CL.BRICK_SIDE = keep
        if self.nl._bricks is None:
            raise SystemExit("the scene has fewer than two bricks: nothing to emulate")
        b = self.nl._bricks
        self.brick_n = b[0][:x.shape[0]]
        self.m = b[1].shape[0]
        self.X = x.copy()
        self.count = np.bincount(self.brick_n, minlength=self.m)
        self.box, self.periodic = b[3], b[4]
        self.acc = np.empty((b[5].shape[0], self.m, 6))
        self.acc2 = np.empty((b[5].shape[0], self.m, 2))
        self.blo = np.empty((self.m, 3))
        self.bhi = np.empty((self.m, 3))
        self.mid = np.empty((self.m, 3))
        self.hi = np.empty((self.m, 3))
        self.rad = np.empty((self.m, 2))
        self.bad = np.empty(self.m, np.bool_)
        self._boxes()

    def _boxes(self):
        self.CL._brick_boxes(self.X, self.box, self.periodic, self.brick_n, self.acc, self.blo, self.bhi)

    def _fails(self, x):
        CL = self.CL
        CL._brick_centres(x, self.X, self.brick_n, self.acc, self.hi, self.mid)
        CL._brick_radii(x, self.X, self.brick_n, self.mid, self.acc2, self.rad)
        failing_bricks(self.mid, self.rad, self.blo, self.bhi, self.box, self.periodic, self.nl.skin,
                       self.nl.cutoff, self.bad)
        return self.bad

    def step(self, x):
        """After a step: None when the test passes, else (share renewed, rounds, full)."""
        bad = self._fails(x)
        if not bad.any():
            return None
        renewed = np.zeros(self.m, bool)
        rounds = 0
        n = x.shape[0]
        while bad.any():
            rounds += 1
            renewed |= bad
            if self.count[renewed].sum() > self.full_at * n:
                self.full(x)
                return 1.0, rounds, True
            sel = bad[self.brick_n]
            self.X[sel] = x[sel]
            self._boxes()
            bad = self._fails(x)
        return float(self.count[renewed].sum() / n), rounds, False


def run(scene, side, a):
    import clusterdyn.calculators._cd_kernels as K
    import clusterdyn.neighbors.celllist as CL
    atoms, dyn = load_scene(scene, a)
    dyn.run(2)
    nl = atoms.calc.nl
    spent = {"build": 0.0, "layout": 0.0}
    build, layout = CL.NeighborList.build, K.chunk_layout

    def timed(name, f, only=None):
        def g(*args, **kw):
            if only is not None and args[0] is not only:      # the emulation's own list: not timed
                return f(*args, **kw)
            t0 = time.process_time()
            r = f(*args, **kw)
            spent[name] += time.process_time() - t0
            return r
        return g
    em = Emulated(atoms, nl, a.full_at, side)
    CL.NeighborList.build, K.chunk_layout = timed("build", build, nl), timed("layout", layout)
    events, shares, fulls, rounds = 0, [], 0, []
    try:
        nb0 = nl.nbuilds
        for k in range(a.steps):
            dyn.run(1)
            r = em.step(atoms.positions)
            if r is not None:
                events += 1
                shares.append(r[0])
                rounds.append(r[1])
                fulls += r[2]
            if (k + 1) % max(1, a.steps // 5) == 0:
                print(f"  {scene}, bricks {side:g}: step {k + 1}/{a.steps}, own builds {nl.nbuilds - nb0}, "
                      f"emulated events {events} ({fulls} full)", flush=True)
        own = nl.nbuilds - nb0
    finally:
        CL.NeighborList.build, K.chunk_layout = build, layout
    n = len(atoms)
    per_build = spent["build"] / max(own, 1) / n * 1e9
    per_layout = spent["layout"] / max(own, 1) / n * 1e9
    own_cost = own * (per_build + per_layout) / a.steps
    work = float(sum(shares))
    best = (work * per_build + events * per_layout) / a.steps
    return {"scene": scene, "N": n, "side": side, "steps": a.steps,
            "own_per_100": 100.0 * own / a.steps, "events_per_100": 100.0 * events / a.steps,
            "full_per_100": 100.0 * fulls / a.steps, "median_share": float(np.median(shares)) if shares else 0.0,
            "median_rounds": float(np.median(rounds)) if rounds else 0.0,
            "work_per_100": 100.0 * work / a.steps, "build_ns": per_build, "layout_ns": per_layout,
            "own_ns_ps": own_cost, "partial_ns_ps": best}


#: the table's columns: title, and the cell of a result row
COLUMNS = [("scene", lambda r: r["scene"]), ("N", lambda r: r["N"]),
           ("brick side (cut-offs)", lambda r: f"{r['side']:g}"),
           ("own builds / 100 steps", lambda r: f"{r['own_per_100']:.0f}"),
           ("renewals / 100", lambda r: f"{r['events_per_100']:.0f}"),
           ("of them full", lambda r: f"{r['full_per_100']:.0f}"),
           ("median share renewed", lambda r: f"{r['median_share']:.2f}"),
           ("median rounds", lambda r: f"{r['median_rounds']:.0f}"),
           ("work, builds / 100", lambda r: f"{r['work_per_100']:.1f}"),
           ("own builds, ns/ps", lambda r: f"{r['own_ns_ps']:.1f}"),
           ("partial at best, ns/ps", lambda r: f"{r['partial_ns_ps']:.1f}")]


def write(rows, out):
    """The table and the JSON of the cases done so far (written after each)."""
    lines = ["| " + " | ".join(t for t, _ in COLUMNS) + " |", "|---|" + "---:|" * (len(COLUMNS) - 1)]
    lines += ["| " + " | ".join(str(cell(r)) for _, cell in COLUMNS) + " |" for r in rows]
    write_report(out, rows, lines)
    return lines


def main(argv=None):
    from debris_cloud import add_scene_args
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="contact,cloud",
                    help="contact, cloud (the 123k debris), slab (the race's state)")
    ap.add_argument("--nx", type=int, default=128, help="the slab's length in cells (N = 1024 nx)")
    ap.add_argument("--sides", default="8,4,2", help="brick sides in cut-offs (cutoff + skin)")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--full-at", type=float, default=0.5,
                    help="a renewal of more than this share of the particles counts as a full build")
    ap.add_argument("--out", default=str(RESULTS / "partial_rebuild"))
    add_scene_args(ap, 50.0, 6.0, 35.0)
    a = ap.parse_args(argv)
    scenes = scene_list(ap, a.scenes)
    try:
        sides = [float(s) for s in a.sides.split(",")]
    except ValueError:
        ap.error(f"--sides: {a.sides!r} is not a comma-separated list of numbers")
    if not all(s >= 1 for s in sides):
        ap.error(f"--sides: {a.sides!r}: each side must be at least 1 cut-off")
    if not 0 < a.full_at <= 1:
        ap.error(f"--full-at: {a.full_at} is not in (0, 1]")
    if a.steps < 1:
        ap.error(f"--steps: {a.steps} is not >= 1")
    from clusterdyn.parallel import set_max_threads
    set_max_threads(1)
    rows = []
    for s in scenes:
        for side in sides:
            r = run(s, side, a)
            rows.append(r)
            print(f"{s}, bricks of {side:g} cut-offs: own builds {r['own_per_100']:.0f} per 100 steps "
                  f"({r['own_ns_ps']:.1f} ns/ps with their chunk layouts); renewals {r['events_per_100']:.0f} "
                  f"({r['full_per_100']:.0f} full), median share {r['median_share']:.2f}, work "
                  f"{r['work_per_100']:.1f} builds: at best {r['partial_ns_ps']:.1f} ns/ps", flush=True)
            lines = write(rows, a.out)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
