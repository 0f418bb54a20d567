"""How long must a shock sample be for a steady front?  The measurement behind ``size=auto``.

    python benchmarks/shock_length.py record --u 3 --cells 300          # one long run, frames saved
    python benchmarks/shock_length.py analyse                           # every recorded run
    python benchmarks/shock_length.py rule                              # the size=auto rule against them

``record`` runs the aluminium piston shock (defaults of the ``shock`` scene:
[100], damping off, 10 m/s noise) on a long sample with many frames and
keeps the tracker's frames (``results/shock_length/u<U>_<L>x<A>x<A>.pkl``,
not committed: large).  Until the front reaches the sample's far end it does
not know how long the sample is, so the frames of one long run up to the time
a shorter run would stop are that shorter run (up to the noise realisation).
``analyse`` replays each recorded run cut to shorter lengths through the
scene's own analysis (:meth:`ShockTracker.result` with the fit window the
scene uses) and prints, per u and length, D, the steadiness verdict and its
reasons.  ``rule`` checks the scene's ``AUTO_RULE`` against the recordings
(the transient skipped, the shortest length from which every longer cut is
steady, D at the rule's length and on the longest record) and writes
``results/shock_length.md``/``.json``.
"""

import argparse
import json
import math
import pickle
import time
from pathlib import Path

import numpy as np

from clusterdyn import units
from clusterdyn.analysis.shock import ShockTracker
from clusterdyn.materials import hugoniot
from clusterdyn.scenes.shock import build_shock, run_shock

HERE = Path(__file__).resolve().parent
STORE = HERE / "results" / "shock_length"


def record(u, cells, across=6, frames=None, seed=1, material="Al", run_fraction=0.9, tag=""):
    """One long run; returns the path of the pickled tracker state."""
    frames = frames or max(120, cells // 2)
    s = build_shock(material, u * units.km_s, size=(cells, across, across), seed=seed,
                    run_fraction=run_fraction)
    t0 = time.perf_counter()
    tracker, st, t_run = run_shock(s, frames=frames, progress=True, desc=f"u={u:g} {cells}x{across}x{across}")
    wall = time.perf_counter() - t0
    STORE.mkdir(parents=True, exist_ok=True)
    path = STORE / f"{material}_u{u:g}_{cells}x{across}x{across}{tag}.pkl"
    with open(path, "wb") as fh:
        pickle.dump({"u": u, "cells": cells, "across": across, "seed": seed, "material": material,
                     "repeat": float(s.slab), "length": float(s.length), "nsteps": s.nsteps,
                     "n": len(s.atoms), "wall_s": wall, "t_run": t_run, "dt": s.dyn.dt,
                     "state": tracker.get_state()}, fh)
    print(f"u = {u:g} km/s, {cells}x{across}x{across}: D = {st.D_fit / units.km_s:.4f} km/s, steady "
          f"{st.steady} {st.steady_reasons}, {wall:.0f} s -> {path}", flush=True)
    return path


def cut(rec, cells, skip=None, **kw):
    """The ShockState of the recorded run cut to ``cells`` repeat cells, fitted from the front at ``skip``
    cells on (None: the scene's window alone), and the number of frames a run of that length records."""
    st = rec["state"]
    tr = ShockTracker.from_state(st)
    tr.fit_from = None if skip is None else skip * rec["repeat"]
    L = rec["length"] * cells / rec["cells"]
    lo = tr.frames[0]["profile"]["edges"][0]
    # the scene's run time for this length: run_fraction * L / D_guess (build_shock)
    D_guess = hugoniot(rec["material"]).D(rec["u"] * units.km_s)
    t_end = kw.pop("run_fraction", 0.8) * L / D_guess
    frames = []
    for f in tr.frames:
        if f["t"] > t_end * (1 + 1e-9):
            break
        p = dict(f["profile"])
        e = np.array(p["edges"], float)
        p["edges"] = np.array([lo, lo + L + rec["repeat"]])
        g = dict(f)
        g["profile"] = p
        frames.append(g)
    tr.frames = frames
    return tr.result(**kw), len(frames)


def analyse(lengths=None, skip=None, **kw):
    rows = []
    for path in sorted(STORE.glob("*.pkl")):
        rec = pickle.loads(path.read_bytes())
        ref = hugoniot(rec["material"]).D(rec["u"] * units.km_s) / units.km_s
        cand = lengths or sorted({c for c in (40, 60, 80, 100, 120, 140, 160, 200, 250, 300, 350, 400, 500, 600)
                                  if c <= rec["cells"]} | {rec["cells"]})
        for c in cand:
            st, nf = cut(rec, c, skip, **kw)
            rows.append({"u": rec["u"], "across": rec["across"], "record": rec["cells"], "cells": c,
                         "frames": nf, "D": st.D_fit / units.km_s, "err": st.D_fit / units.km_s / ref - 1,
                         "halves": [h / units.km_s for h in st.D_halves], "rms_slabs": st.fit_rms / st.width,
                         "u_ratio": st.u / st.u_piston, "steady": st.steady, "reasons": st.steady_reasons})
    return rows


def rule_table(lengths=(40, 60, 80, 100, 120, 140, 160, 180, 200, 250, 300, 350, 400, 500, 600)):
    """The scene's AUTO_RULE against every recording (one row per recorded u, the longest record)."""
    from clusterdyn.scenes.shock import AUTO_RULE, shock_size
    recs = {}
    for path in sorted(STORE.glob("Al_*.pkl")):
        rec = pickle.loads(path.read_bytes())
        if rec["u"] not in recs or rec["cells"] > recs[rec["u"]]["cells"]:
            recs[rec["u"]] = rec
    rows = []
    for u, rec in sorted(recs.items()):
        (L, _, _), fit_r0 = shock_size(u * units.km_s)
        skip = fit_r0 / math.sqrt(2.0)
        ref = hugoniot(rec["material"]).D(u * units.km_s) / units.km_s
        cuts = sorted({c for c in lengths if c <= rec["cells"]} | {rec["cells"], L} - {c for c in () })
        cuts = [c for c in cuts if c <= rec["cells"]]
        res = {c: cut(rec, c, skip)[0] for c in cuts}
        steady_from = None
        for c in reversed(cuts):
            if not res[c].steady:
                break
            steady_from = c
        at = res.get(L)
        longest = res[rec["cells"]]
        rows.append({"u": u, "skip_cells": skip, "length_cells": L, "recorded_cells": rec["cells"],
                     "steady_from_cells": steady_from, "margin": L / steady_from if steady_from else None,
                     "D_rule": at.D_fit / units.km_s if at else None, "steady_rule": at.steady if at else None,
                     "reasons_rule": at.steady_reasons if at else None,
                     "D_longest": longest.D_fit / units.km_s, "steady_longest": longest.steady,
                     "D_ref": ref, "err_rule": (at.D_fit / units.km_s / ref - 1) if at else None,
                     "err_longest": longest.D_fit / units.km_s / ref - 1,
                     "u_ratio_rule": at.u / at.u_piston if at else None})
    lines = ["| u km/s | transient skipped (cells) | auto length (cells) | recorded (cells) | steady from (cells) "
             "| margin | D at auto length | steady | err vs Al-1100 | D longest | err longest |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['u']:g} | {r['skip_cells']:.0f} | {r['length_cells']} | {r['recorded_cells']} | "
                     f"{r['steady_from_cells'] or '-'} | {r['margin'] or 0:.2f} | "
                     f"{r['D_rule'] if r['D_rule'] is None else format(r['D_rule'], '.3f')} | "
                     f"{'yes' if r['steady_rule'] else 'NO'} | "
                     f"{r['err_rule'] if r['err_rule'] is None else format(r['err_rule'], '+.2%')} | "
                     f"{r['D_longest']:.3f} | {r['err_longest']:+.2%} |")
    md = "\n".join(lines) + "\n"
    (HERE / "results" / "shock_length.md").write_text(md)
    (HERE / "results" / "shock_length.json").write_text(json.dumps(rows, indent=1, default=float))
    return rows, md


def main(argv=None):
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("--u", type=float, nargs="+", required=True)
    r.add_argument("--cells", type=int, nargs="+", required=True)
    r.add_argument("--across", type=int, default=6)
    r.add_argument("--frames", type=int, default=None)
    r.add_argument("--seed", type=int, default=1)
    a_ = sub.add_parser("analyse")
    a_.add_argument("--xmin", type=float, default=None)
    a_.add_argument("--xmax", type=float, default=None)
    a_.add_argument("--run-fraction", type=float, default=None)
    a_.add_argument("--skip", type=float, default=None, help="fit from the front at this many cells on")
    a_.add_argument("--u", type=float, default=None, help="only this piston speed")
    sub.add_parser("rule")
    a = ap.parse_args(argv)
    if a.cmd == "rule":
        print(rule_table()[1])
        return
    if a.cmd == "record":
        for u, c in zip(a.u, a.cells):
            record(u, c, a.across, a.frames, a.seed)
        return
    kw = {}
    if a.xmin is not None:
        kw["x_min_frac"] = a.xmin
    if a.xmax is not None:
        kw["x_max_frac"] = a.xmax
    if a.run_fraction is not None:
        kw["run_fraction"] = a.run_fraction
    rows = analyse(skip=a.skip, **kw)
    for r in rows:
        if a.u is not None and r["u"] != a.u:
            continue
        print(f"u {r['u']:4g} {r['cells']:4d}x{r['across']} (of {r['record']}) frames {r['frames']:4d}  "
              f"D {r['D']:8.4f} err {r['err']:+7.2%}  halves {r['halves'][0]:7.3f} {r['halves'][1]:7.3f}  "
              f"rms {r['rms_slabs']:5.2f}  u/up {r['u_ratio']:.3f}  {'steady' if r['steady'] else 'NO: ' + '; '.join(r['reasons'])}")


if __name__ == "__main__":
    main()
