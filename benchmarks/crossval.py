"""Cross-validation: the aluminium piston shock run by clusterdyn and by its exported LAMMPS deck.

    python benchmarks/crossval.py                 # u = 3 km/s, size 100x8x8, damping off and J = 50
    python benchmarks/crossval.py --size 60x6x6 --J none
    python benchmarks/crossval.py --u 6 --size auto --J none   # the shock scene's default sample at 6 km/s

1. Forces: the scene after ``--steps-before`` steps of clusterdyn (the front
   has formed, so pairs span compression and tension) is exported with
   ``run 0``; LAMMPS' forces are compared with clusterdyn's (with the damping
   term when J is set: dpd/ext/tstat at T = 0 must give -m Gamma (v_i - v_j)).
   The expected difference is the linear-in-r^2 interpolation of the exported
   table (``table_interpolation_error``), stated beside the measurement.
2. Shock speed: the set-up state is exported with the scene's full number of
   steps and frames; both runs go through the same ShockTracker front fit.

Writes benchmarks/results/crossval.md and .json.
"""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from clusterdyn import units
from clusterdyn.analysis.shock import shock_from_lammps
from clusterdyn.io.lammps import (DEFAULT_TABLE_POINTS, export_lammps, frame_atoms, run_lammps,
                                  table_interpolation_error)
from clusterdyn.scenes.shock import build_shock, run_shock

HERE = Path(__file__).resolve().parent


def compare_forces(size, u, J, steps_before, folder, n_points=DEFAULT_TABLE_POINTS, seed=1):
    s = build_shock(size=size, u=u, J=J, seed=seed)
    s.dyn.run(steps_before)
    a, c = s.atoms, s.calc
    if J is None:
        f_cd = c.compute(a)["forces"]
    else:
        f_cd = c.compute(a, damping=(a.arrays["momenta"], 1.0 / a.get_masses(), c.damping_matrix(J)))["forces"]
    e_cd = c.compute(a)["energy"]
    export_lammps(a, c, s.dyn, folder, nsteps=0, frames=1, n_points=n_points)
    r = run_lammps(folder, 1)
    fr = r.final
    f_l = np.empty_like(f_cd)
    f_l[fr["id"] - 1] = fr["forces"]
    err = np.abs(f_l - f_cd).max()
    fmax = np.abs(f_cd).max()
    norm = np.linalg.norm(f_cd, axis=1)
    big = norm > 1e-3 * norm.max()
    per = np.linalg.norm(f_l - f_cd, axis=1)[big] / norm[big]
    e_l = r.thermo[0][2] if r.thermo else float("nan")
    bound = table_interpolation_error(c, n_points)
    return {"N": len(a), "J": J, "steps_before": steps_before, "max_abs_diff_eV_A": float(err),
            "max_force_eV_A": float(fmax), "max_rel_to_fmax": float(err / fmax),
            "median_rel_per_particle": float(np.median(per)), "max_rel_per_particle": float(per.max()),
            "energy_cd_eV": float(e_cd), "energy_lammps_eV": float(e_l),
            "energy_rel_diff": float(abs(e_l - e_cd) / abs(e_cd)),
            "min_r_over_r0": c.last_stats["min_r_over_r0"], "table_bound": bound}


def compare_shock(size, u, J, folder, frames=60, nprocs=1, seed=1):
    s = build_shock(size=size, u=u, J=J, seed=seed)
    template = s.atoms.copy()
    export_lammps(s.atoms, s.calc, s.dyn, folder, nsteps=s.nsteps, frames=frames)
    t0 = time.perf_counter()
    tracker, st, t_run = run_shock(s, frames=frames, progress=False)
    t_cd = time.perf_counter() - t0
    r = run_lammps(folder, nprocs)
    x_lo = template.positions[~s.piston_mask, 0].min()
    tr_l, st_l = shock_from_lammps(r, template, s.piston_mask, s.material.rho0, s.u, s.slab, s.length, x_lo,
                                   fit_from=s.fit_from)
    kms = units.km_s
    return {"N": len(template), "J": J, "u_km_s": u / kms, "steps": s.nsteps, "size": "x".join(map(str, s.size)),
            "steady_cd": st.steady, "steady_lammps": st_l.steady,
            "D_cd_km_s": st.D_fit / kms, "D_cd_err": st.D_fit_err / kms,
            "D_lammps_km_s": st_l.D_fit / kms, "D_lammps_err": st_l.D_fit_err / kms,
            "D_rel_diff": float(abs(st_l.D_fit - st.D_fit) / st.D_fit),
            "P_cd_GPa": st.P / units.GPa, "P_lammps_GPa": st_l.P / units.GPa,
            "u_cd_km_s": st.u / kms, "u_lammps_km_s": st_l.u / kms,
            "wall_cd_s": t_cd, "wall_lammps_s": r.wall_time_s, "lammps_loop_s": r.loop_time_s}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="100x8x8")
    ap.add_argument("--u", type=float, default=3.0, help="km/s")
    ap.add_argument("--J", default="none,50")
    ap.add_argument("--steps-before", type=int, default=600)
    ap.add_argument("--out", default=str(HERE / "results" / "crossval"))
    a = ap.parse_args(argv)
    size = a.size if a.size.startswith("auto") else tuple(int(x) for x in a.size.split("x"))
    u = a.u * units.km_s
    out = {"size": a.size, "u_km_s": a.u, "forces": [], "shock": []}
    with tempfile.TemporaryDirectory() as d:
        for Jt in a.J.split(","):
            J = None if Jt == "none" else float(Jt)
            f = compare_forces(size, u, J, a.steps_before, Path(d) / f"forces_{Jt}")
            out["forces"].append(f)
            print(json.dumps(f, default=float), flush=True)
            sh = compare_shock(size, u, J, Path(d) / f"shock_{Jt}")
            out["shock"].append(sh)
            print(json.dumps(sh, default=float), flush=True)
    p = Path(a.out)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.with_suffix(".json").write_text(json.dumps(out, indent=1, default=float))
    p.with_suffix(".md").write_text(markdown(out))
    print(markdown(out))


def markdown(out):
    L = [f"# Cross-validation clusterdyn vs LAMMPS: Al piston shock, u = {out['u_km_s']:g} km/s, "
         f"size {out['size']}", "",
         "## Forces (exported deck, `run 0`)", "",
         "| N | damping | steps before | max abs diff (eV/A) | max force (eV/A) | max diff / max force | "
         "median per-particle rel | table bound (rel to max f, r >= 0.75 r0) | energy rel diff |",
         "|---|---|---|---|---|---|---|---|---|"]
    for f in out["forces"]:
        b = list(f["table_bound"].values())[0]
        L.append(f"| {f['N']} | {'off' if f['J'] is None else 'J = %g' % f['J']} | {f['steps_before']} | "
                 f"{f['max_abs_diff_eV_A']:.3g} | {f['max_force_eV_A']:.3g} | {f['max_rel_to_fmax']:.2e} | "
                 f"{f['median_rel_per_particle']:.2e} | {b['max_rel_to_fmax_r_ge_0.75r0']:.2e} | "
                 f"{f['energy_rel_diff']:.2e} |")
    L += ["", "## Shock speed (same set-up, full run, same front fit)", "",
          "| size | N | damping | steps | D clusterdyn (km/s) | D LAMMPS (km/s) | rel diff | P cd / LAMMPS (GPa) "
          "| steady cd / LAMMPS |",
          "|---|---|---|---|---|---|---|---|---|"]
    yn = {True: "yes", False: "no", None: "-"}
    for s in out["shock"]:
        L.append(f"| {s.get('size', out['size'])} | {s['N']} | {'off' if s['J'] is None else 'J = %g' % s['J']} | "
                 f"{s['steps']} | {s['D_cd_km_s']:.3f} +- {s['D_cd_err']:.3f} | "
                 f"{s['D_lammps_km_s']:.3f} +- {s['D_lammps_err']:.3f} | {s['D_rel_diff']:.2%} | "
                 f"{s['P_cd_GPa']:.2f} / {s['P_lammps_GPa']:.2f} | {yn[s.get('steady_cd')]} / "
                 f"{yn[s.get('steady_lammps')]} |")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    main()
