"""Debris cloud: a sphere through a plate, until the cloud's bounding box has grown tenfold.

    python benchmarks/debris_cloud.py                        # ~1.1M clusters, two runs, hours
    python benchmarks/debris_cloud.py --sphere 20 --plate-radius 14 --plate-thickness 4 --growth 3
    python benchmarks/debris_cloud.py --resume               # continue both runs from their checkpoints

An aluminium sphere (``clusterdyn.build.bodies.sphere``, diameter ``--sphere`` r0)
hits a round aluminium plate (``plate``, ``--plate-thickness`` x ``--plate-radius`` r0)
at ``--v`` (6.7 km/s) along -x; ``place`` puts it half a cluster above the
plate, ``combine_bodies`` makes one sample.  Open boundaries, pair damping J =
``--J``, time step ``--dt-factor`` r0/(c0 + v).  The run continues until the
largest side of the particles' bounding box is ``--growth`` (10) times its initial
value, in chunks of ``--chunk`` steps, each ending with a checkpoint
(``clusterdyn.io.checkpoint.save_run``), so a run can be resumed (``--resume``).

Two runs: ``keep`` (every particle stays) and ``remove`` (particles leaving a box
``--region`` times the initial bounding box, about its centre, are removed:
``DampedVerlet(region=RegionOfInterest)``; the energy they take away is in the
ledger), run for as many steps as the ``keep`` run took (its bounding box stays
within the region).

After every chunk: particle-steps per second of the chunk (wall clock and the
process' CPU time, one thread), list builds and the builds the local test saved,
the cell structure (dense or sparse), pairs per particle, particles left, the
bounding box, and the process' peak memory per particle (VmHWM minus the
process' size before the sample was built; the peak counter is reset once the
sample is built, so the figure is the run's, not the builder's), over the steps and,
apart, while the chunk's checkpoint is written (HDF5's buffers and the dynamics'
state copies add about 200 bytes per particle there).  The reference: the piston-shock
slab of the same N (``build_shock``, 16 x 16 cells across, from the saved state
of ``benchmarks/_common.py``) timed in its own process right after each chunk
for ``--slab-steps`` steps, so that the two rates are measured under the same
machine load; the ratio debris/slab is per chunk.  Results:
``benchmarks/results/debris_cloud_{keep,remove}.csv`` and ``debris_cloud.md``.
"""

import argparse
import csv
import gc
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _common import RESULTS, load_state, reset_peak, state_path, status, trim, warm_kernels  # noqa: E402
FIELDS = ["run", "chunk", "step", "time_ns", "N", "removed", "wall_s", "cpu_s", "rate_wall", "rate_cpu",
          "builds", "saved_by_local_test", "cells", "pairs_per_particle", "ext_x_r0", "ext_y_r0", "ext_z_r0",
          "largest_side_growth", "volume_growth", "peak_bytes_per_particle",
          "checkpoint_peak_bytes_per_particle", "slab_N", "slab_rate_wall",
          "slab_rate_cpu", "ratio_wall", "ratio_cpu", "load"]


def _warm(J):
    """Compile (or load from the cache) the kernels on a small shock, then return the process size."""
    warm_kernels(J, sort=True)         # the sort's kernels too: code, not the sample's memory
    gc.collect()
    return status("VmRSS")


def build(a, region):
    from clusterdyn import units
    from clusterdyn.build.bodies import combine_bodies, place, plate, sphere
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.md import DampedVerlet, RegionOfInterest
    r0 = a.r0 * units.um
    pl = plate("Al", r0, a.plate_thickness * r0, radius=a.plate_radius * r0, axis=0)
    sp = sphere("Al", r0, a.sphere * r0, velocity=(-a.v * units.km_s, 0.0, 0.0))
    sp = place(sp, pl, axis=0, gap=0.5 * r0, side=1)
    atoms = combine_bodies([pl, sp])
    atoms.calc = ClusterDynamics()
    atoms.calc.setup(atoms)
    pot = atoms.calc.potentials[0]
    dt = a.dt_factor * r0 / (pot.c0 + a.v * units.km_s)
    roi = None
    if region:
        lo, hi = atoms.positions.min(axis=0), atoms.positions.max(axis=0)
        c, h = 0.5 * (lo + hi), 0.5 * (hi - lo) * a.region
        roi = RegionOfInterest(c - h, c + h)
    J = None if a.J == "none" else float(a.J)
    dyn = DampedVerlet(atoms, timestep=dt, J=J, region=roi, remove_interval=a.remove_interval,
                       sort_interval=a.sort_interval or None)
    return atoms, dyn


def add_scene_args(ap, sphere, thickness, radius):
    """The scene's options, with the given sizes as defaults."""
    ap.add_argument("--sphere", type=float, default=sphere, help="sphere diameter, r0")
    ap.add_argument("--plate-thickness", type=float, default=thickness, help="r0")
    ap.add_argument("--plate-radius", type=float, default=radius, help="r0")
    ap.add_argument("--r0", type=float, default=5.0, help="um")
    ap.add_argument("--v", type=float, default=6.7, help="km/s")
    ap.add_argument("--J", default="50")
    ap.add_argument("--dt-factor", type=float, default=0.1)
    ap.add_argument("--sort-interval", type=int, default=100,
                    help="steps between sorts of the Atoms into the list's cell order (0: never)")


def worker_slab(a):
    """The slab reference: ``--slab-steps`` steps of the saved shock state of the same N, one thread."""
    from clusterdyn.parallel import set_max_threads
    set_max_threads(1)
    J = None if a.J == "none" else float(a.J)
    atoms, dyn, _ = load_state(a.state, J=J)
    dyn.run(2)
    n = len(atoms)
    t0, c0 = time.perf_counter(), time.process_time()
    dyn.run(a.slab_steps)
    t, c = time.perf_counter() - t0, time.process_time() - c0
    print(json.dumps({"N": n, "rate_wall": n * a.slab_steps / t, "rate_cpu": n * a.slab_steps / c}))


def slab_rate(a, state):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "slab", "--state", str(state),
           "--J", a.J, "--slab-steps", str(a.slab_steps)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=7200)
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-3000:])
    return json.loads(p.stdout.strip().split("\n")[-1])


class MemoryTrace:
    """Where in a chunk its peak memory was reached: read after every step (an observer; about 20 us
    a step), each rise of the peak by more than ``RISE`` bytes a particle is kept with what the step
    did (a list build, a sort of the Atoms, a removal), and the chunk's largest ones go to
    ``debris_cloud_<run>_memory.csv`` (chunk, step, peak B/particle, rise, events)."""

    RISE = 2.0
    KEEP = 5

    def __init__(self, path, dyn, nl, base, n0, resume):
        self.path, self.dyn, self.nl, self.base, self.n0 = path, dyn, nl, base, n0
        if not (resume and path.exists()):
            with open(path, "w", newline="") as fh:
                csv.writer(fh).writerow(["chunk", "step", "peak_bytes_per_particle", "rise", "events"])

    def start_chunk(self):
        self.last = (status("VmHWM") - self.base) / self.n0
        self.builds, self.n = self.nl.nbuilds, len(self.dyn.atoms)
        self.rises = []

    def __call__(self):
        peak = (status("VmHWM") - self.base) / self.n0
        ev = []
        if self.nl.nbuilds != self.builds:
            ev.append("build")
        if len(self.dyn.atoms) != self.n:
            ev.append("removal")
        si = self.dyn.sort_interval
        if si and self.dyn.nsteps % si == 0:
            ev.append("sort")
        if peak > self.last + self.RISE:
            self.rises.append((self.dyn.nsteps, peak, peak - self.last, "+".join(ev) or "-"))
        self.last = max(self.last, peak)
        self.builds, self.n = self.nl.nbuilds, len(self.dyn.atoms)

    def end_chunk(self, chunk):
        top = sorted(self.rises, key=lambda r: -r[1])[:self.KEEP]
        with open(self.path, "a", newline="") as fh:
            w = csv.writer(fh)
            for step, peak, rise, ev in sorted(top):
                w.writerow([chunk, step, f"{peak:.1f}", f"{rise:.1f}", ev])


def _keep_steps(out, growth):
    """Steps of the finished ``keep`` run (the ``remove`` run covers the same time; the two may run
    at the same time, in two processes), or a huge number while it runs."""
    p = Path(out).parent / "debris_cloud_keep.csv"
    rows = list(csv.DictReader(open(p))) if p.exists() else []
    done = bool(rows) and float(rows[-1]["largest_side_growth"]) >= growth
    return int(rows[-1]["step"]) if done else 10 ** 12


def worker_run(a):
    """One run (``--run keep`` or ``remove``) in chunks, resumable, one thread."""
    from clusterdyn import units
    from clusterdyn.io.checkpoint import load_run, save_run
    from clusterdyn.parallel import set_max_threads
    import h5py  # noqa: F401  (the checkpoints' library: part of the base size, not of the sample)
    set_max_threads(1)
    J = None if a.J == "none" else float(a.J)
    base = _warm(J)
    out = Path(a.out)
    ck = out.parent / f"debris_cloud_{a.run}.ckpt.h5"
    rows_csv = out.parent / f"debris_cloud_{a.run}.csv"
    if a.resume and ck.exists():
        atoms, dyn, extra = load_run(ck)
        ext0, chunk = np.array(extra["ext0"]), int(extra["chunk"])
    else:
        atoms, dyn = build(a, a.run == "remove")
        ext0, chunk = np.ptp(atoms.positions, axis=0), 0
        with open(rows_csv, "w", newline="") as fh:
            csv.writer(fh).writerow(FIELDS)
    r0 = atoms.calc.potentials[0].r0
    nl = atoms.calc.nl
    n0 = len(atoms)
    nx = max(2, round(n0 / 1024))           # (one cell along x would be all piston)
    slab_state = state_path(nx, a.slab_fraction)
    if not slab_state.exists():
        # the slab reference's state is made on first use in a process of its own: its build and
        # steps (a million clusters) are not this run's memory
        code = f"import sys; sys.path.insert(0, {str(HERE)!r}); from _common import shock_state; " \
               f"shock_state({nx}, {a.slab_fraction!r})"
        subprocess.run([sys.executable, "-c", code], check=True)
    # the peak from here on: building the sample (lattices, overlap checks) is not the run
    gc.collect()
    trim()
    base = max(base, 0)
    reset_peak()
    print(f"[{a.run}] N = {n0}, dt = {dyn.dt / units.fs:.4g} fs, initial box {np.round(ext0 / r0, 1)} r0",
          flush=True)
    trace = MemoryTrace(out.parent / f"debris_cloud_{a.run}_memory.csv", dyn, nl, base, n0, a.resume)
    dyn.attach(trace, interval=1)
    while True:
        nb0, ns0 = nl.nbuilds, nl.nlocal
        n_start = len(atoms)
        trace.start_chunk()
        t0, c0 = time.perf_counter(), time.process_time()
        dyn.run(a.chunk)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        chunk += 1
        n = len(atoms)
        nmean = 0.5 * (n + n_start)
        ext = np.ptp(atoms.positions, axis=0)
        grow = float(ext.max() / ext0.max())
        vol = float(np.prod(ext) / np.prod(ext0))
        peak_run = (status("VmHWM") - base) / n0
        trace.end_chunk(chunk)
        reset_peak()
        save_run(ck, dyn, extra={"ext0": ext0.tolist(), "chunk": chunk})
        peak_ck = (status("VmHWM") - base) / n0
        # hand the checkpoint's freed buffers back before the next chunk's peak starts from the
        # resident size (else the writer's leftovers count as the run's)
        gc.collect()
        trim()
        reset_peak()
        s = slab_rate(a, slab_state)
        row = {"run": a.run, "chunk": chunk, "step": dyn.nsteps, "time_ns": dyn.get_time() / (1e6 * units.fs),
               "N": n, "removed": dyn.removed["count"], "wall_s": wall, "cpu_s": cpu,
               "rate_wall": nmean * a.chunk / wall, "rate_cpu": nmean * a.chunk / cpu,
               "builds": nl.nbuilds - nb0, "saved_by_local_test": nl.nlocal - ns0, "cells": nl.last_cells,
               "pairs_per_particle": nl.npairs / n, "ext_x_r0": ext[0] / r0, "ext_y_r0": ext[1] / r0,
               "ext_z_r0": ext[2] / r0, "largest_side_growth": grow, "volume_growth": vol,
               "peak_bytes_per_particle": peak_run,
               "checkpoint_peak_bytes_per_particle": peak_ck, "slab_N": s["N"],
               "slab_rate_wall": s["rate_wall"], "slab_rate_cpu": s["rate_cpu"],
               "ratio_wall": nmean * a.chunk / wall / s["rate_wall"], "ratio_cpu": nmean * a.chunk / cpu / s["rate_cpu"],
               "load": os.getloadavg()[0]}
        with open(rows_csv, "a", newline="") as fh:
            csv.writer(fh).writerow([row[k] for k in FIELDS])
        print(f"[{a.run}] chunk {chunk}, step {dyn.nsteps}: N {n}, box x{grow:.2f} (volume x{vol:.0f}), "
              f"{row['rate_cpu']:.3g} particle-steps/s CPU ({row['rate_wall']:.3g} wall), slab {s['rate_cpu']:.3g} "
              f"CPU, ratio {row['ratio_cpu']:.2f} CPU / {row['ratio_wall']:.2f} wall, builds {row['builds']} "
              f"(local test saved {row['saved_by_local_test']}), {nl.last_cells} cells, "
              f"{row['peak_bytes_per_particle']:.0f} B/particle peak ({row['checkpoint_peak_bytes_per_particle']:.0f} "
              f"while writing the checkpoint), load {row['load']:.1f}", flush=True)
        if a.run == "keep" and grow >= a.growth or dyn.nsteps >= a.max_steps:
            break
        if a.run == "remove" and dyn.nsteps >= _keep_steps(out, a.growth):
            break


def _rows(a, run):
    """The rows of a run's CSV in ``--out``'s folder ([] if there is none)."""
    p = Path(a.out).parent / f"debris_cloud_{run}.csv"
    return list(csv.DictReader(open(p))) if p.exists() else []


def markdown(a):
    L = ["# Debris cloud: sphere through a plate", "",
         f"Al sphere {a.sphere:g} r0 at {a.v:g} km/s through an Al plate {a.plate_thickness:g} x "
         f"{a.plate_radius:g} r0 (radius), r0 = {a.r0:g} um, J = {a.J}, dt = {a.dt_factor:g} r0/(c0 + v); "
         f"run until the bounding box's largest side grew {a.growth:g}-fold; one thread; the slab reference "
         f"(piston shock of the same N) timed in its own process after every chunk.  Rates in particle-steps "
         "per second from the process' CPU time (the wall-clock figures, which include time spent waiting for "
         "a core on the shared machine, are in the CSV).", ""]
    for run in ("keep", "remove"):
        rows = _rows(a, run)
        if not rows:
            continue
        L += [f"## {run}", "", "| step | t (ns) | N | box growth (largest side / volume) | cells | pairs per particle | "
              "builds | saved by the local test | debris CPU rate | slab CPU rate | ratio | ratio (wall) | "
              "peak B/particle | load |", "|" + "---|" * 14]
        for r in rows:
            L.append(f"| {r['step']} | {float(r['time_ns']):.2f} | {r['N']} | {float(r['largest_side_growth']):.2f} / "
                     f"{float(r['volume_growth']):.0f} | {r['cells']} | {float(r['pairs_per_particle']):.2f} | "
                     f"{r['builds']} | {r['saved_by_local_test']} | {float(r['rate_cpu']):.3g} | "
                     f"{float(r['slab_rate_cpu']):.3g} | {float(r['ratio_cpu']):.2f} | {float(r['ratio_wall']):.2f} | "
                     f"{float(r['peak_bytes_per_particle']):.0f} | {float(r['load']):.1f} |")
        rc = np.array([float(r["ratio_cpu"]) for r in rows])
        L += ["", f"- ratio debris/slab (CPU): median {np.median(rc):.2f}, min {rc.min():.2f}, max {rc.max():.2f}; "
              f"peak memory {max(float(r['peak_bytes_per_particle']) for r in rows):.0f} B/particle", ""]
    return "\n".join(L) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", choices=["run", "slab"])
    ap.add_argument("--run", choices=["keep", "remove"], default="keep")
    ap.add_argument("--state")
    add_scene_args(ap, 104.0, 12.0, 70.0)
    ap.add_argument("--growth", type=float, default=10.0)
    ap.add_argument("--chunk", type=int, default=1000)
    ap.add_argument("--max-steps", type=int, default=200000)
    ap.add_argument("--region", type=float, default=3.0, help="region of interest / initial bounding box")
    ap.add_argument("--remove-interval", type=int, default=20)
    ap.add_argument("--slab-steps", type=int, default=40)
    ap.add_argument("--slab-fraction", type=float, default=0.0,
                    help="shocked fraction of the slab reference state (0: after its first 100 steps)")
    ap.add_argument("--runs", default="keep,remove")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--report", action="store_true", help="only write the table and plot of the CSVs in --out's folder")
    ap.add_argument("--out", default=str(RESULTS / "debris_cloud"))
    a = ap.parse_args(argv)
    if a.worker == "slab":
        return worker_slab(a)
    if a.worker == "run":
        return worker_run(a)
    if a.report:
        return report(a)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    procs = []
    for run in a.runs.split(","):          # the two runs side by side, each on one thread
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "run", "--run", run]
        for k in ("sphere", "plate_thickness", "plate_radius", "r0", "v", "J", "dt_factor", "growth", "chunk",
                  "max_steps", "region", "remove_interval", "slab_steps", "slab_fraction", "sort_interval", "out"):
            cmd += [f"--{k.replace('_', '-')}", str(getattr(a, k))]
        if a.resume:
            cmd.append("--resume")
        procs.append(subprocess.Popen(cmd))
    if any(p.wait() != 0 for p in procs):
        raise RuntimeError("a debris run failed")
    report(a)


def plot(a):
    """Rates over the run (debris and slab, CPU time) and the box's growth: ``<out>.png``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for run, c in (("keep", "C0"), ("remove", "C1")):
        rows = _rows(a, run)
        if not rows:
            continue
        t = [float(r["time_ns"]) for r in rows]
        ax.plot(t, [float(r["rate_cpu"]) for r in rows], "o-", color=c, label=f"debris cloud ({run})")
        ax.plot(t, [float(r["slab_rate_cpu"]) for r in rows], "s--", color=c, alpha=0.6,
                label=f"slab of the initial N (after each {run} chunk)")
        ax2.plot(t, [float(r["largest_side_growth"]) for r in rows], "o-", color=c, label=f"box growth ({run})")
    ax.set_ylabel("particle-steps / s (CPU)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax2.set_ylabel("largest side / initial")
    ax2.set_xlabel("time (ns)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(Path(a.out).with_suffix(".png"), dpi=110)
    plt.close(fig)


def report(a):
    """The markdown table and the plot of both runs' CSVs (also on their own: ``--report``)."""
    md = markdown(a)
    Path(a.out).with_suffix(".md").write_text(md)
    plot(a)
    print(md)


if __name__ == "__main__":
    main()
