"""The debris cloud in LAMMPS: does a tuned LAMMPS keep its slab speed where clusterdyn does not?

    python benchmarks/debris_lammps.py                      # 123k clusters, two windows, ~15 min
    python benchmarks/debris_lammps.py --sphere 20 --plate-radius 14 --plate-thickness 4 --at 100 --steps 40

The scene of ``benchmarks/debris_cloud.py`` (an aluminium sphere through an
aluminium plate at 6.7 km/s, J = 50, dt = 0.1 r0/(c0 + v), open boundaries),
run by clusterdyn to each step of ``--at`` and saved
(:func:`clusterdyn.io.checkpoint.save_run`); from each saved state, timed
windows of ``--steps`` steps in clusterdyn (one thread) and in LAMMPS (one
rank, the state exported with :func:`clusterdyn.io.lammps.export_lammps`),
damped (J as run) and with the damping off from the same state (LAMMPS'
damping, ``dpd/ext/tstat``, costs it several times its undamped step, which
hides its list builds; undamped they show).
LAMMPS is tuned on the debris state itself: the tables ``--tables``, each
with its force error against clusterdyn's (damping off; eligible within
``--tol``, 1e-4 of the largest force: the debris' compression reaches far
up the repulsive branch, where a coarse table is off), then with the
fastest eligible table skins ``--skins`` (multiples of r0) and
``neigh_modify every 1|2 delay 0 check yes``, and the three fastest of those again
with LAMMPS' OPENMP styles on one thread (``package omp 1``, ``suffix omp``, as
``lammps_tune.py`` tries them on the slab); configurations with
dangerous builds are not eligible, the fastest eligible one races.  The reference of each
engine: its own rate on the piston-shock slab of the same N (``build_shock``,
16 x 16 cells across, from the state of ``benchmarks/_states.py`` after its
first 100 steps, as ``debris_cloud.py`` uses), LAMMPS with the slab race's
winner (``--slab-table``, ``--slab-skin``, ``--slab-neigh``, ``--slab-suffix``).  Repeats interleaved; the figure
is each engine's debris/slab ratio.  Results:
``benchmarks/results/debris_lammps.md`` and ``.json``.
"""

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
RESULTS = HERE / "results"

import lammps_tune as lt  # noqa: E402  (benchmarks/ on the path)
from _states import STATES, shock_state  # noqa: E402
from debris_cloud import add_scene_args, build  # noqa: E402


def debris_state(a, step):
    """Paths of the debris run saved at ``step`` (made on first use): as run (damped) and the same
    state with the damping off (the undamped windows' start)."""
    from clusterdyn.io.checkpoint import load_run, save_run
    from clusterdyn.md import DampedVerlet
    path = STATES / (f"debris_al_s{a.sphere:g}_p{a.plate_thickness:g}x{a.plate_radius:g}_J{a.J}"
                     f"_dt{a.dt_factor:g}_step{step}.h5")
    off = path.with_name(path.stem + "_off.h5")
    if not path.exists():
        STATES.mkdir(parents=True, exist_ok=True)
        atoms, dyn = build(a, False)
        dyn.run(step)
        tmp = path.with_suffix(".tmp")
        save_run(tmp, dyn, extra={"step": step})
        os.replace(tmp, path)
    if not off.exists():
        atoms, dyn, _ = load_run(path)
        und = DampedVerlet(atoms, timestep=dyn.dt, J=None)
        und.set_state(dict(dyn.get_state(), J=None))
        tmp = off.with_suffix(".tmp")
        save_run(tmp, und, extra={"step": step})
        os.replace(tmp, off)
    return path, off


def tune_debris(state, state_off, a, tmp, log):
    """LAMMPS on the debris state: each table's force error against clusterdyn's (damping off) and
    rate; then skins x neigh_modify at J = 50 with the fastest table within ``--tol``; the
    winner's deck damped and undamped."""
    base, f_cd, r0, calc = lt.export_base(state_off, None, tmp / "base_off", a.steps)
    base_j, _, _, calc_j = lt.export_base(state, float(a.J), tmp / "base_j", a.steps)
    tables, trows = {}, []
    for style, npts in a.tables:
        err = lt.force_error(lt.variant(base, tmp / f"force_{style}_{npts}", calc, style, npts, 0.25 * r0,
                                        lt.DEFAULT_NEIGH, force_run=True, tables=tables), f_cd)
        row = {"style": style, "points": npts, "force_error": err}
        if err <= a.tol:
            d = lt.variant(base_j, tmp / f"t_{style}_{npts}", calc_j, style, npts, 0.3 * r0, lt.DEFAULT_NEIGH,
                           tables=tables)
            row.update(lt.lammps_rate(d, 1))
        trows.append(row)
        log(f"    LAMMPS table {style} {npts}: force error {err:.1e}"
            + (f", {row['rate']:.3g} particle-steps/s (skin 0.3 r0, every 1)" if "rate" in row else ""))
    ok = [r for r in trows if "rate" in r and r["dangerous"] == 0]
    if not ok:
        return {"tables": trows, "configs": [], "winner": None, "r0": r0}
    best = max(ok, key=lambda r: r["rate"])
    rows = []

    def try_config(skin, neigh, suffix=""):
        tag = f"v_{skin:g}_{neigh.split()[1]}" + (f"_{suffix}" if suffix else "")
        d = lt.variant(base_j, tmp / tag, calc_j, best["style"], best["points"], skin * r0, neigh, tables=tables,
                       suffix=suffix)
        r = lt.lammps_rate(d, 1)
        r.update({"style": best["style"], "points": best["points"], "force_error": best["force_error"],
                  "skin_r0": skin, "neigh_modify": neigh, "suffix": suffix, "deck": str(d)})
        rows.append(r)
        log(f"    LAMMPS table {best['style']} {best['points']}{'/' + suffix if suffix else ''}, skin {skin:g} r0, "
            f"{neigh}: {r['rate']:.3g} particle-steps/s, {r['builds']} builds, dangerous {r['dangerous']}")

    for skin in a.skins:
        for neigh in ("every 1 delay 0 check yes", "every 2 delay 0 check yes"):
            try_config(skin, neigh)
    # the three fastest eligible configurations again with LAMMPS' CPU accelerator styles, as the slab race
    top = lt.fastest(rows, lambda r: r["dangerous"] == 0)
    for suffix in lt.SUFFIXES:
        for t in top:
            try_config(t["skin_r0"], t["neigh_modify"], suffix)
    ok = [r for r in rows if r["dangerous"] == 0]
    win = max(ok, key=lambda r: r["rate"]) if ok else None
    decks = {}
    if win is not None:
        decks = {a.J: win["deck"], "none": str(lt.variant(base, tmp / "win_off", calc, win["style"], win["points"],
                                                         win["skin_r0"] * r0, win["neigh_modify"], tables=tables,
                                                         suffix=win["suffix"]))}
    return {"tables": trows, "configs": rows, "winner": win, "r0": r0, "decks": decks}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_scene_args(ap, 50.0, 6.0, 35.0)
    ap.add_argument("--at", default="400,1200", help="debris steps at which the timed windows start")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--tables", default="linear:1000,linear:5000,linear:20000,linear:100000,spline:1000,spline:5000",
                    help="LAMMPS tables tried, style:points")
    ap.add_argument("--tol", type=float, default=1e-4, help="largest force error of an eligible table")
    ap.add_argument("--skins", default="0.2,0.3,0.4")
    ap.add_argument("--slab-table", default="linear:10000", help="style:points (the slab race's winner at 128k)")
    ap.add_argument("--slab-skin", type=float, default=0.2, help="r0 (the slab race's winner at 128k)")
    ap.add_argument("--slab-neigh", default="every 2 delay 0 check yes")
    ap.add_argument("--slab-suffix", default="omp", choices=["", *lt.SUFFIXES],
                    help="LAMMPS accelerator suffix of the slab race's winner ('' = the plain styles)")
    ap.add_argument("--out", default=str(RESULTS / "debris_lammps"))
    a = ap.parse_args(argv)
    if a.J == "none":
        raise SystemExit("--J: 'none' is not allowed here: the debris scene is damped (a number, e.g. 50)")
    a.tables = [(t.split(":")[0], int(t.split(":")[1])) for t in a.tables.split(",")]
    a.slab_table = (a.slab_table.split(":")[0], int(a.slab_table.split(":")[1]))
    a.skins = [float(s) for s in a.skins.split(",")]
    a.region, a.remove_interval = 3.0, 20
    log = lambda s: print(s, flush=True)  # noqa: E731
    tmp = Path(tempfile.mkdtemp(prefix="cd_debris_lmp_"))
    meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_start": os.getloadavg(), "steps": a.steps}
    windows = []
    for step in [int(s) for s in a.at.split(",")]:
        log(f"debris state at step {step}")
        st, st_off = debris_state(a, step)
        tun = tune_debris(st, st_off, a, tmp / f"w{step}", log)
        if tun["winner"] is None:
            raise RuntimeError(f"no LAMMPS configuration without dangerous builds at step {step}")
        windows.append({"step": step, "states": {a.J: st, "none": st_off}, **tun})
    from clusterdyn.io.checkpoint import load_run
    n = len(load_run(windows[0]["states"][a.J])[0])
    slab = shock_state(max(1, round(n / 1024)), 0.0)
    slab_w = {"step": "slab", "states": {a.J: slab, "none": slab}, "decks": {}}
    for J in (a.J, "none"):
        base, _, r0s, calc = lt.export_base(slab, None if J == "none" else float(J), tmp / f"slab_{J}", a.steps)
        slab_w["decks"][J] = str(lt.variant(base, tmp / f"slab_win_{J}", calc, a.slab_table[0], a.slab_table[1],
                                            a.slab_skin * r0s, a.slab_neigh, suffix=a.slab_suffix))
    runs = []
    for rep in range(a.repeat):
        for J in (a.J, "none"):
            for w in [*windows, slab_w]:
                cd = lt._run_cd(w["states"][J], "none" if J == "none" else J, 1, a.steps, a.sort_interval)
                lm = lt.lammps_rate(Path(w["decks"][J]), 1)
                runs.append({"repeat": rep, "J": J, "window": w["step"], "clusterdyn": cd["rate"],
                             "cd_cpu_rate": cd["N"] * a.steps / cd["cpu_s"], "cd_builds": cd["builds"],
                             "lammps": lm["rate"], "lammps_builds": lm["builds"], "dangerous": lm["dangerous"],
                             "N_cd": cd["N"], "N_lammps": lm["N"], "load": lm["load"]})
                log(f"  [{rep}] J={J} {w['step']}: clusterdyn {cd['rate']:.3g} ({cd['builds']} builds), LAMMPS "
                    f"{lm['rate']:.3g} ({lm['builds']} builds, dangerous {lm['dangerous']}), load {lm['load']:.1f}")
    meta["load_end"] = os.getloadavg()
    rep = {"meta": meta, "args": {k: v for k, v in vars(a).items()}, "runs": runs,
           "windows": [{k: ({j: os.path.relpath(p, HERE.parent) for j, p in v.items()} if k == "states" else v)
                        for k, v in w.items()}
                       for w in windows]}
    md = markdown(rep)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(rep, indent=1, default=str))
    out.with_suffix(".md").write_text(md)
    print(md)
    shutil.rmtree(tmp, ignore_errors=True)


def markdown(rep):
    a, m = rep["args"], rep["meta"]
    L = ["# The debris cloud in LAMMPS and in clusterdyn", "",
         f"{m['date']}; Al sphere {a['sphere']:g} r0 at {a['v']:g} km/s through an Al plate "
         f"{a['plate_thickness']:g} x {a['plate_radius']:g} r0, J = {a['J']}, dt = {a['dt_factor']:g} r0/(c0 + v); "
         f"windows of {a['steps']} steps from the states at the steps below; one thread / one rank; load average "
         f"{m['load_start'][0]:.1f} at start, {m['load_end'][0]:.1f} at end.", "",
         "## LAMMPS tuned on each debris state (J = 50)", ""]
    for w in rep["windows"]:
        L += [f"Step {w['step']}: tables (force error; rate at skin 0.3 r0, every 1, where eligible)", "",
              "| table | points | force error | particle-steps/s |", "|---|---|---|---|"]
        for r in w["tables"]:
            L.append(f"| {r['style']} | {r['points']} | {r['force_error']:.1e} | "
                     + (f"{r['rate']:.3g} |" if "rate" in r else "not eligible |"))
        L += ["", f"Step {w['step']}: skin and neigh_modify with the fastest eligible table", "",
              "| table | skin / r0 | neigh_modify | suffix | particle-steps/s | builds | dangerous |",
              "|---|---|---|---|---|---|---|"]
        for r in w["configs"]:
            L.append(f"| {r['style']} {r['points']} | {r['skin_r0']:g} | {r['neigh_modify']} | "
                     f"{r.get('suffix') or '-'} | {r['rate']:.3g} | {r['builds']} | {r['dangerous']} |")
        win = w.get("winner")
        if win is not None:
            L.append(f"\nWinner: table {win['style']} {win['points']}, skin {win['skin_r0']:g} r0, "
                     f"{win['neigh_modify']}, {'suffix ' + win['suffix'] if win.get('suffix') else 'plain styles'}.")
        L.append("")
    L += ["## Rates and each engine's debris/slab ratio", "",
          "Particle-steps per second of the wall clock (LAMMPS' loop time; clusterdyn's run).", "",
          "| J | window | repeat | clusterdyn | builds | LAMMPS | builds | clusterdyn/LAMMPS | load |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rep["runs"]:
        L.append(f"| {r['J']} | {r['window']} | {r['repeat']} | {r['clusterdyn']:.3g} | {r['cd_builds']} | "
                 f"{r['lammps']:.3g} | {r['lammps_builds']} | {r['clusterdyn'] / r['lammps']:.2f} | {r['load']:.1f} |")
    L.append("")
    for J in (a["J"], "none"):
        for w in rep["windows"]:
            for eng in ("clusterdyn", "lammps"):
                rr = [r[eng] / s[eng] for r in rep["runs"] if r["window"] == w["step"] and r["J"] == J
                      for s in rep["runs"] if s["window"] == "slab" and s["repeat"] == r["repeat"] and s["J"] == J]
                L.append(f"- J = {J}, step {w['step']}, {eng}: debris/slab {min(rr):.2f}-{max(rr):.2f} "
                         f"(per repeat: {', '.join(f'{x:.2f}' for x in rr)})")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
