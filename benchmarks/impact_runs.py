"""The impact scenes' reported runs: their commands, and the tables of docs/impact.md from their results.

    python benchmarks/impact_runs.py commands [--runs DIR]    # print the runs, one command a line
    python benchmarks/impact_runs.py tables --runs DIR        # markdown tables from DIR/*/result.json

Runs (each ``clusterdyn run ... --out DIR/NAME``; run them one at a time on a
shared machine):

* Taylor, r0 = D0/25, the paper's packing: the four room-temperature tests
  with outlines (Wilkins-Guinan 275 m/s L0 46.94 mm and 373 m/s L0 23.47 mm,
  Gust 200 and 358 m/s) and the L0 = 46.94 mm series at 207, 275, 367 and
  434 m/s; on the 373 m/s test also full-density masses, a sticking wall and
  repulsive grain boundaries; on the 373 m/s (L0 23.47 mm) and Gust 200 m/s
  tests the packing the flow-stress study picks for 6061-T6 and r0 = D0/20
  and D0/30 (three resolutions with D0/25);
* hypervelocity at r0 = 0.4 mm (seeds 1, 2, 3), 0.2667 mm and 0.2 mm;
* multilayer at its default.
"""

import argparse
import json
import math
from pathlib import Path

PY = "python -m clusterdyn.cli run"

#: the flow-stress study's closest packing to 6061-T6's flow stress, at r0 = D0/25 (grain size g in mm)
FLOW_STRESS_PICK = "--set grain_size={g:.4g}mm --set porosity=0.2 --set rc=1.10 --set boundaries=repulsive"

TAYLOR = [
    # name, L0 mm, D0 mm, V m/s, extra[, r0 as D0/n: n, default 25]
    ("tay_WG275_L47", 46.94, 7.62, 275, ""),
    ("tay_WG373_L23", 23.47, 7.62, 373, ""),
    ("tay_G200", 32.1, 6.3, 200, ""),
    ("tay_G358", 32.9, 6.4, 358, ""),
    ("tay_WG207_L47", 46.94, 7.62, 207, ""),
    ("tay_WG367_L47", 46.94, 7.62, 367, ""),
    ("tay_WG434_L47", 46.94, 7.62, 434, ""),
    ("tay_WG373_L23_dense", 23.47, 7.62, 373, "--set mass=dense"),
    ("tay_WG373_L23_stick", 23.47, 7.62, 373, "--set wall=sticking"),
    ("tay_WG373_L23_rep", 23.47, 7.62, 373, "--set boundaries=repulsive"),
    # the packing the flow-stress study picks for 6061-T6 (grains 5 r0, 20% porosity, rc 1.10, repulsive)
    ("tay_WG373_L23_fs", 23.47, 7.62, 373, FLOW_STRESS_PICK.format(g=5 * 7.62 / 25)),
    ("tay_G200_fs", 32.1, 6.3, 200, FLOW_STRESS_PICK.format(g=5 * 6.3 / 25)),
    # three resolutions (with the r0 = D0/25 runs above)
    ("tay_WG373_L23_r20", 23.47, 7.62, 373, "", 20),
    ("tay_G200_r20", 32.1, 6.3, 200, "", 20),
    ("tay_WG373_L23_r30", 23.47, 7.62, 373, "", 30),
    ("tay_G200_r30", 32.1, 6.3, 200, "", 30),
]
HYPER = [("hv_r0.4_s1", 0.4, 1), ("hv_r0.4_s2", 0.4, 2), ("hv_r0.4_s3", 0.4, 3), ("hv_r0.267", 0.2667, 1),
         ("hv_r0.2", 0.2, 1)]


def commands(runs):
    out = []
    for name, L0, D0, V, extra, *div in TAYLOR:
        n = div[0] if div else 25
        tmax = 120 if L0 > 40 else (80 if L0 < 25 else 100)
        if name.endswith("_rep"):
            tmax = 40                        # the rod falls apart; the run shows how, no stop is expected
        out.append(f"{PY} taylor --set L0={L0}mm --set D0={D0}mm --set V={V} --set r0={D0 / n:.4g}mm "
                   f"--set t_max={tmax} {extra} --out {runs}/{name}".replace("  ", " "))
    for name, r0, seed in HYPER:
        out.append(f"{PY} hypervelocity --set r0={r0}mm --set seed={seed} --out {runs}/{name}")
    out.append(f"{PY} multilayer --out {runs}/ml_default")
    out.append(f"{PY} multilayer --set r0=2mm --out {runs}/ml_r2")
    out.append(f"python benchmarks/multilayer_lammps.py --r0 2mm --cd-result {runs}/ml_r2/result.json")
    out.append(f"{PY} taylor --out {runs}/tay_default")
    return out


def _load(runs, name):
    p = Path(runs) / name / "result.json"
    return json.loads(p.read_text()) if p.exists() else None


def _v(d, k):
    x = d.get(k)
    return None if x is None else x.get("value")


def _r(d, k):
    x = d.get(k)
    return None if x is None else x.get("reference")


def _f(x, fmt=".3f"):
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def _err(a, b):
    if a is None or b is None or b == 0 or (isinstance(a, float) and math.isnan(a)):
        return "-"
    return f"{100 * (a - b) / abs(b):+.1f}%"


def taylor_measures_now(runs, name, d):
    """The Taylor measures recomputed with the present analysis from the run's taylor_final.npz
    (None without it): Lf/L0, X/L0, Df/D0, W/D0, outline deviation, Y (GPa)."""
    import re

    import numpy as np

    from clusterdyn import units
    from clusterdyn.analysis.impact import find_taylor_test, outline_deviation, taylor_outline
    from clusterdyn.scenes.taylor import analyse_rod
    p = Path(runs) / name / "taylor_final.npz"
    if not p.exists():
        return None
    z = np.load(p)
    par = d["params"]
    L0 = float(z["L0_A"]) if "L0_A" in z else par["L0"]["value"] * units.mm
    D0 = float(z["D0_A"]) if "D0_A" in z else par["D0"]["value"] * units.mm
    V = float(z["V_ase"]) if "V_ase" in z else par["V"]["value"] * units.m_s
    if "rho_ase" in z:
        rho = float(z["rho_ase"])
    else:
        rho = float(re.search(r"density ([0-9.]+) g/cm3", " ".join(d["notes"])).group(1)) * units.g_cm3
    info = {"axis": int(z["axis"]), "r0": float(z["r0_A"]), "D0": D0, "L0": L0, "offset": float(z["offset_A"]),
            "L_init": float(z["L_init_A"]), "rho": rho, "V": V}
    m = analyse_rod({"info": info, "positions": z["positions_A"].astype(float), "main": z["main"]})
    out = {"Lf_over_L0": m["Lf_over_L0"], "X_over_L0": m["X"] / L0, "Df_over_D0": m["Df"] / D0,
           "W_over_D0": m["W"] / D0, "Y_taylor": m["Y"] / units.GPa}
    test = find_taylor_test(L0, D0, V)
    if test is not None and test["has_outline"]:
        ze, re_ = taylor_outline(test["name"])
        out["outline_deviation"] = outline_deviation(m["z"], m["r"], ze, re_, D0)
    return out


def taylor_table(runs):
    rows = ["| test | V (m/s) | L0 (mm) | r0 (mm) | Lf/L0 CD / exp (err) | X/L0 CD / exp | Df/D0 CD / exp | W/D0 CD / exp "
            "| outline dev. | Y_Taylor CD / exp (GPa) | rebound (m/s) | t_end (us) | clusters | wall (s) |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, L0, D0, V, extra, *div in TAYLOR:
        d = _load(runs, name)
        if d is None:
            rows.append(f"| {name} | {V} | {L0} | {D0 / (div[0] if div else 25):.4g} | pending | | | | | | | | | |")
            continue
        cells = [name.replace("tay_", "") + (f" ({extra.replace('--set ', '')})" if extra else ""), str(V), str(L0),
                 _f(d["params"]["r0"]["value"], ".4g")]
        now = taylor_measures_now(runs, name, d) or {}

        def val(k):
            return now.get(k, _v(d, k))
        for k in ("Lf_over_L0", "X_over_L0", "Df_over_D0", "W_over_D0"):
            a, b = val(k), _r(d, k)
            cells.append(f"{_f(a)} / {_f(b)}" + (f" ({_err(a, b)})" if k == "Lf_over_L0" else ""))
        cells.append(_f(val("outline_deviation")))
        cells.append(f"{_f(val('Y_taylor'), '.2f')} / {_f(_r(d, 'Y_taylor'), '.2f')}")
        cells.append(_f(-_v(d, "v_com_end"), ".0f"))
        cells.append(_f(_v(d, "t_end"), ".1f"))
        cells.append(str(d.get("extra", {}).get("n_clusters", "-")))
        cells.append(_f(d["wall_time_s"], ".0f"))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def hyper_table(runs):
    rows = ["| run | r0 (mm) | clusters | hole (mm, vs 17.3) | through-hole (mm) | ejecta half-angle from normal / "
            "to plane (deg, vs 20.67) | cloud lead speed (km/s) | length / diameter (mm) | fragments | wall (s) |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r0, seed in HYPER:
        d = _load(runs, name)
        if d is None:
            rows.append(f"| {name} | {r0} | pending | | | | | | | |")
            continue
        h = _v(d, "hole_diameter")
        rows.append(f"| {name} (seed {seed}) | {r0} | {d['extra']['n_clusters']} | {_f(h, '.2f')} ({_err(h, 17.3)}) | "
                    f"{_f(_v(d, 'hole_through'), '.2f')} | {_f(_v(d, 'ejecta_half_angle'), '.1f')} / "
                    f"{_f(_v(d, 'ejecta_angle_to_plane'), '.1f')} | {_f(_v(d, 'cloud_lead_speed'), '.2f')} | "
                    f"{_f(_v(d, 'cloud_length'), '.1f')} / {_f(_v(d, 'cloud_diameter'), '.1f')} | "
                    f"{_f(_v(d, 'n_fragments'), '.0f')} | {_f(d['wall_time_s'], '.0f')} |")
    return "\n".join(rows)


def multilayer_table(runs):
    d = _load(runs, "ml_default")
    if d is None:
        return "multilayer: pending"
    rows = ["| layer | hole (mm) | note |", "|---|---|---|"]
    for k, x in d.items():
        if k.startswith("layer") and k.endswith("_hole"):
            rows.append(f"| {k[:-5]} | {_f(x['value'], '.1f')} | {x.get('note', '')} |")
    rows.append("")
    rows.append("| quantity | value | note |")
    rows.append("|---|---|---|")
    for k, x in d.items():
        if k.startswith(("projectile", "fragment")):
            rows.append(f"| {k} | {_f(x['value'], '.3g')} {x['unit']} | {x.get('note', '')} |")
    rows.append(f"\nwall time {d['wall_time_s']:.0f} s, {d['extra']['n_clusters']} clusters, "
                f"{d['extra']['steps']} steps")
    return "\n".join(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("commands", "tables"))
    ap.add_argument("--runs", default="runs/impact")
    a = ap.parse_args()
    if a.what == "commands":
        print("\n".join(commands(a.runs)))
    else:
        print("## Taylor\n\n" + taylor_table(a.runs) + "\n\n## Hypervelocity\n\n" + hyper_table(a.runs)
              + "\n\n## Multilayer\n\n" + multilayer_table(a.runs))


if __name__ == "__main__":
    main()
