"""Friction studies of the MCA segment method (scene ``mca-friction``), resumable.

    python benchmarks/mca_friction.py                       # every part, seeds 0 1
    python benchmarks/mca_friction.py --part mu1 --part viscous
    python benchmarks/mca_friction.py --seeds 0,1,2 --out benchmarks/results/mca_friction

Parts (each writes ``<part>.csv`` and ``<part>.png`` in ``--out``; every scene run keeps its
own folder ``runs/<name>/`` with ``result.json`` and the mu_dr CSV, and a run whose
``result.json`` exists is not run again, so an interrupted study resumes):

* ``mu1``: K_mu = 0, mu0 = 0, three mu1: steady mu_dr against mu1 (must be mu1 within 2%);
* ``viscous``: mu1 = 0, mu0 > 0, three speeds: mu_dr against V (linear, slope from the law
  ``mu0 sum(r0) V / F_N``);
* ``energy``: two free blocks sliding at 2 km/s (no drive, no damping; the upper one shorter,
  so automata of the lower block pass its corners), friction on and off: the
  mechanical energy lost against the friction work, the momenta, and the number of segment
  switches at the upper block's corners;
* ``interlock``: K_mu on, three block lengths at fixed R, ``--seeds``: the standard deviation
  of mu_dr against the number of contacts along the interface, the K_mu clips;
* ``explicit``: the same blocks with the segment method off, surfaces at the automaton scale
  (bare rows; a step pattern) meeting through the ordinary contact with Coulomb friction
  mu1: mu_dr(t) beside the segment method's.

Runs are single-threaded (``NUMBA_NUM_THREADS=1``); progress with time left (tqdm).
"""

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from clusterdyn import units  # noqa: E402
from clusterdyn.scenes.base import get_scene  # noqa: E402
from clusterdyn.scenes.common import matplotlib_agg  # noqa: E402

BASE = {"size": "24x4", "steps": 6000, "frames": 200, "h5md": "false", "checkpoint_every": 0}
INTERLOCK = {"mu1": "0.3", "K_av": "0.1", "A1": "1um", "l1": "2um", "d1": "10um", "A2": "0.25um",
             "l2": "0.5um", "d2": "2um"}


def run(out, name, **over):
    """Run the scene once into ``out/runs/name`` (or reuse it); returns (result dict, curve dict)."""
    d = out / "runs" / name
    res = d / "result.json"
    if not res.exists():
        t0 = time.perf_counter()
        get_scene("mca-friction").run({**BASE, **over}, out=d, progress=True)
        print(f"  {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    r = json.loads(res.read_text())
    with open(d / "mca-friction-mu.csv") as fh:
        rows = list(csv.DictReader(fh))
    cur = {k: np.array([float(x[k]) for x in rows]) for k in rows[0]}
    return r, cur


def q(r, key):
    return r[key]["value"]


def part_mu1(out, seeds):
    rows = []
    for mu1 in (0.1, 0.3, 0.6):
        r, _ = run(out, f"mu1-{mu1}", mu1=str(mu1))
        rows.append((mu1, q(r, "mu_dr"), q(r, "mu_dr_std"), q(r, "mu_dr") / mu1 - 1))
    _table(out / "mu1.csv", ["mu1", "mu_dr", "mu_dr_std", "rel_error"], rows)
    plt = matplotlib_agg()
    fig, ax = plt.subplots(figsize=(4.5, 3.5))
    a = np.array(rows)
    ax.errorbar(a[:, 0], a[:, 1], yerr=a[:, 2], fmt="o", label="segment method (steady mean, std)")
    ax.plot([0, 0.65], [0, 0.65], "k--", lw=0.8, label="mu_dr = mu1")
    ax.set_xlabel("mu1")
    ax.set_ylabel("mu_dr")
    ax.set_title("K_mu = 0, mu0 = 0: steady sliding")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "mu1.png", dpi=120)
    plt.close(fig)
    return rows


def part_viscous(out, seeds):
    mu0 = 0.1            # MPa per m/s
    stress = 0.05 * units.GPa
    rows = []
    for V in (10.0, 20.0, 40.0):
        r, _ = run(out, f"visc-{V:g}", mu1="0", mu0=str(mu0), V=f"{V}m/s")
        rows.append((V, q(r, "mu_dr"), q(r, "mu_dr_std")))
    a = np.array(rows)
    # the law: every contact slides at V; each interface length is covered twice (both bodies' segments)
    law = mu0 * units.MPa / units.m_s * 2.0 * a[:, 0] * units.m_s / stress
    slope = np.polyfit(a[:, 0], a[:, 1], 1)
    _table(out / "viscous.csv", ["V_m_s", "mu_dr", "mu_dr_std", "law_2mu0V_over_sigma"],
           [tuple(x) + (y,) for x, y in zip(rows, law)])
    plt = matplotlib_agg()
    fig, ax = plt.subplots(figsize=(4.5, 3.5))
    ax.errorbar(a[:, 0], a[:, 1], yerr=a[:, 2], fmt="o", label="segment method")
    ax.plot(a[:, 0], law, "k--", lw=0.8, label="2 mu0 V / sigma_N")
    ax.set_xlabel("V (m/s)")
    ax.set_ylabel("mu_dr")
    ax.set_title(f"mu1 = 0, mu0 = {mu0} MPa/(m/s): fit {slope[0]:.4g} V + {slope[1]:.2g}", fontsize=9)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "viscous.png", dpi=120)
    plt.close(fig)
    return rows, slope


def part_energy(out, seeds):
    """Free sliding: energy lost vs friction work, momenta, segment switches."""
    from clusterdyn.build.mca import mca_packing
    from clusterdyn.materials import get_material
    from clusterdyn.mca.contact import SegmentContact, stack_blocks
    from clusterdyn.mca.dynamics import MCADynamics
    D = 10 * units.um
    rows = []
    for label, kw in (("friction", dict(mu1=0.3, mu0=0.02 * units.MPa / units.m_s, v_reg=0.05 * units.m_s)),
                      ("interlock", dict(mu1=0.3, K_av=0.1, A1=1 * units.um, l1=0.2 * units.um, d1=1 * units.um,
                                         v_reg=0.05 * units.m_s, seed=1)),
                      ("no-friction", dict(mu1=0.0, friction=False))):
        mat = get_material("alumina")
        lo = mca_packing(mat, D, (20 * D, 4 * D), packing="hex")
        up = mca_packing(mat, D, (8 * D, 4 * D), packing="hex")
        atoms = stack_blocks([lo, up])
        body = atoms.arrays["body"]
        v = np.zeros((len(atoms), 3))
        v[body == 1, 0] = 2000 * units.m_s        # fast enough to cross segment joints and corners
        v[body == 1, 1] = -2 * units.m_s
        atoms.set_velocities(v)
        c = SegmentContact(**kw)
        dyn = MCADynamics(atoms, contact=c)
        E0 = dyn.total_energy()
        p0 = atoms.get_momenta().sum(axis=0)
        prev = {}
        switches = 0
        steps = 0
        while steps < 2000:
            dyn.run(1)
            steps += 1
            g = c.geo
            now = dict(zip(zip(g["k"].tolist(), g["body"].tolist()), g["p"].tolist()))
            switches += sum(1 for key, p in now.items() if key in prev and prev[key] != p)
            prev = now
            if g["nc"] == 0 or (g["fn"].max() == 0 and steps > 20):
                break
        lost = E0 - dyn.total_energy()
        dp = np.abs(atoms.get_momenta().sum(axis=0) - p0).max() / np.abs(atoms.get_momenta()).sum()
        rows.append((label, steps, E0 / units.J * units.m, lost / units.J * units.m,
                     c.friction_work / units.J * units.m,
                     (lost - c.friction_work) / max(c.friction_work, 1e-300) if c.friction_on else float("nan"),
                     (lost - c.friction_work) / E0, switches, dp, int(c.clips[0])))
    _table(out / "energy.csv", ["case", "steps_in_contact", "E0_J_per_m", "lost_J_per_m", "friction_work_J_per_m",
                                "rel_mismatch_vs_friction_work", "mismatch_over_E0", "segment_switches",
                                "rel_momentum_change", "K_clips"], rows)
    return rows


def part_interlock(out, seeds):
    rows = []
    curves = {}
    for L in (6, 12, 24):
        for s in seeds:
            r, cur = run(out, f"inter-L{L}-s{s}", size=f"{L}x4", seed=str(s), **INTERLOCK)
            n = q(r, "contacts")
            steps = float(BASE["steps"]) * (1 - 0.2)     # contact-steps while sliding (after the ramps)
            rows.append((L, s, n, q(r, "mu_dr"), q(r, "mu_dr_std"), q(r, "K_mu_clips"),
                         q(r, "K_mu_clips") / (n * steps)))
            curves[(L, s)] = cur
    _table(out / "interlock.csv", ["length_d", "seed", "contacts", "mu_dr_mean", "mu_dr_std", "K_mu_clips",
                                       "clip_fraction_approx"], rows)
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 2, figsize=(10, 3.6))
    for (L, s), cur in curves.items():
        if s == seeds[0]:
            sel = cur["time_ns"] > cur["time_ns"][-1] * 0.2
            axs[0].plot(cur["sliding_um"][sel], cur["mu_dr"][sel], lw=0.8, label=f"L = {L} d")
    axs[0].axhline(0.4, color="k", ls="--", lw=0.8, label="mu1 + K_av")
    axs[0].set_xlabel("sliding distance (um)")
    axs[0].set_ylabel("mu_dr")
    axs[0].legend(fontsize=8)
    a = np.array([(r[2], r[4]) for r in rows])
    axs[1].loglog(a[:, 0], a[:, 1], "o", label="runs (seeds)")
    nn = np.unique(a[:, 0])
    m = np.array([a[a[:, 0] == x, 1].mean() for x in nn])
    axs[1].loglog(nn, m[0] * np.sqrt(nn[0] / nn), "k--", lw=0.8, label="~ 1/sqrt(N)")
    axs[1].set_xlabel("contacts along the interface")
    axs[1].set_ylabel("std of mu_dr (steady)")
    axs[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "interlock.png", dpi=120)
    plt.close(fig)
    return rows


def part_explicit(out, seeds):
    cases = [("segment", {"method": "segment", "mu1": "0.3"}),
             ("explicit, bare rows", {"method": "explicit", "mu1": "0.3", "steps_w": "0"}),
             ("explicit, steps of 2", {"method": "explicit", "mu1": "0.3", "steps_w": "2"})]
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, len(cases), figsize=(12, 3.4), sharey=True)
    rows = []
    for ax, (label, over) in zip(axs, cases):
        r, cur = run(out, "cmp-" + label.replace(",", "").replace(" ", "-"), **over)
        ax.plot(cur["sliding_um"], cur["mu_dr"], lw=0.8)
        ax.axhline(0.3, color="k", ls="--", lw=0.8)
        ax.set_title(f"{label}: mean {q(r, 'mu_dr'):.3g} +- {q(r, 'mu_dr_std'):.2g}", fontsize=9)
        ax.set_xlabel("sliding distance (um)")
        rows.append((label, q(r, "mu_dr"), q(r, "mu_dr_std"), q(r, "damping_work"), q(r, "drive_work")))
    axs[0].set_ylabel("mu_dr = F_dr / F_N")
    fig.tight_layout()
    fig.savefig(out / "explicit.png", dpi=120)
    plt.close(fig)
    _table(out / "explicit.csv", ["case", "mu_dr_mean", "mu_dr_std", "damping_work_J_per_m", "drive_work_J_per_m"],
           rows)
    return rows


def _table(path, header, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    print(f"\n{path}")
    for r in [header] + [list(x) for x in rows]:
        print("  " + "  ".join(f"{x:.5g}" if isinstance(x, float) else str(x) for x in r))


PARTS = {"mu1": part_mu1, "viscous": part_viscous, "energy": part_energy, "interlock": part_interlock,
         "explicit": part_explicit}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="benchmarks/results/mca_friction")
    ap.add_argument("--part", action="append", choices=sorted(PARTS))
    ap.add_argument("--seeds", default="0,1")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = [int(s) for s in a.seeds.split(",")]
    for p in a.part or list(PARTS):
        print(f"== {p}", flush=True)
        PARTS[p](out, seeds)


if __name__ == "__main__":
    main()
