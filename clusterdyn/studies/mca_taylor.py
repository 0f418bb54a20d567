"""Every room-temperature Taylor test of 6061-T6 with the MCA rod (docs/impact.md, Taylor section).

    clusterdyn study mca-taylor [--set across=5] [--set tests=all|seven|NAME,...] [--out DIR]

Runs the scene ``taylor --set method=mca`` (Johnson-Cook 6061-T6, large-strain
switching) on the tests of ``clusterdyn/data/taylor_6061t6.csv`` at room
temperature, at each resolution of ``across`` (automata across D0; r0 = D0 /
across), and writes the table (Lf/L0, X/L0, Df/D0, W/D0 and the outline
deviation where measured, against the test; wall time), ``mca_taylor.csv``
and ``mca_taylor.png`` (computed against measured Lf/L0 with the identity
line, and error against wall time when several resolutions ran).  Each run is
cached in ``DIR/runs`` (``studies.common.run_scene``): an interrupted study
resumes where it stopped; a run that stops with an InstabilityError is
recorded as such (its message in the table) and the study goes on.
"""

import sys

import numpy as np

from ..analysis.impact import taylor_test_label
from ..errors import InputError
from ..scenes.base import Param, get_scene
from .base import Report, Study, register_study
from .common import ListParam, format_table, markdown_table, run_scene, write_csv

#: the seven named tests of issue 42 (V in m/s, L0 in mm)
SEVEN = (("WG 275/L47", 275, 46.94), ("WG 373/L23", 373, 23.47), ("G200", 200, None), ("G358", 358, None),
         ("WG 207/L47", 207, 46.94), ("WG 367/L47", 367, 46.94), ("WG 434/L47", 434, 46.94))

PARAMS = [
    ListParam("across", (5,), "automata across D0 (comma list: one run per test and resolution)", low=4),
    Param("tests", "all", "all (every room-temperature test), seven (the seven named ones) or a comma list "
          "of test labels like 'WG 373/L23,G200'", kind="str"),
    Param("wall", "frictionless", "the wall: frictionless or sticking", kind="choice",
          choices=("frictionless", "sticking")),
    Param("material", "Al6061-T6", "MCA material: Al6061-T6 (isothermal Johnson-Cook) or Al6061-T6-thermal "
          "(with the thermal term: each automaton heats from its plastic work)", kind="choice",
          choices=("Al6061-T6", "Al6061-T6-thermal")),
]

AIM_LF, AIM_DF = 0.05, 0.10


def select_tests(which):
    from ..analysis.impact import ROOM_TEMPERATURE_K, taylor_tests
    room = [t for t in taylor_tests() if t["T0_K"] is None or t["T0_K"] <= ROOM_TEMPERATURE_K]
    by_label = {taylor_test_label(t): t for t in room}
    if which == "all":
        return room
    names = [s for s, _, _ in SEVEN] if which == "seven" else [x.strip() for x in which.split(",") if x.strip()]
    missing = [n for n in names if n not in by_label]
    if missing:
        raise InputError("tests", which, "all, seven or labels among: " + ", ".join(sorted(by_label)))
    return [by_label[n] for n in names]


def _q(res, key):
    q = res.quantities.get(key)
    return (None, None) if q is None else (q.value, q.reference)


def _row(t, across, res, err, wall):
    """One run's row: the measured shape against the test's."""
    row = {"test": taylor_test_label(t), "across": int(across), "V_m_s": t["V_m_s"], "L0_mm": t["L0_mm"],
           "wall_s": wall, "error": err}
    if res is not None:
        for key, name in (("Lf_over_L0", "Lf"), ("X_over_L0", "X"), ("Df_over_D0", "Df"), ("W_over_D0", "W")):
            val, ref = _q(res, key)
            row[f"{name}_mca"] = val
            row[f"{name}_test"] = ref
            row[f"{name}_err"] = None if (ref is None or val is None) else (val - ref) / ref
        row["outline_dev"] = _q(res, "outline_deviation")[0]
        row["residual_over_plastic"] = _q(res, "residual_over_plastic")[0]
        row["automata"] = res.extra.get("n_clusters")
        row["stopped"] = res.extra.get("stopped")
        if "T_max" in res.quantities:                  # the thermal term
            row["T_max"] = _q(res, "T_max")[0]
    return row


def _summary(rows):
    ok = [r for r in rows if r.get("Lf_err") is not None]
    return {"n_runs": len(rows), "n_failed": sum(1 for r in rows if r["error"]),
            "Lf_within_aim": sum(1 for r in ok if abs(r["Lf_err"]) <= AIM_LF),
            "Lf_max_abs_err": max((abs(r["Lf_err"]) for r in ok), default=None),
            "Lf_mean_err": float(np.mean([r["Lf_err"] for r in ok])) if ok else None,
            "Df_within_aim": sum(1 for r in rows if r.get("Df_err") is not None and abs(r["Df_err"]) <= AIM_DF),
            "Df_measured": sum(1 for r in rows if r.get("Df_err") is not None)}


CSV_COLUMNS = ["test", "across", "V_m_s", "L0_mm", "automata", "Lf_mca", "Lf_test", "Lf_err", "X_mca", "X_test",
               "X_err", "Df_mca", "Df_test", "Df_err", "W_mca", "W_test", "W_err", "outline_dev",
               "residual_over_plastic", "wall_s", "stopped", "error"]
TABLE = [("test", "test", "s"), ("across", "across", "d"), ("Lf_mca", "Lf/L0", ".4f"),
         ("Lf_test", "test", ".4f"), ("Lf_err", "err", "+.3f"), ("Df_mca", "Df/D0", ".3f"),
         ("Df_test", "test", ".3f"), ("Df_err", "err", "+.3f"), ("X_mca", "X/L0", ".3f"),
         ("W_mca", "W/D0", ".3f"), ("outline_dev", "outline", ".3f"), ("wall_s", "wall (s)", ".0f")]


class TaylorStudy(Study):
    """``clusterdyn study mca-taylor`` (module docstring)."""

    name = "mca-taylor"
    summary = ("every room-temperature 6061-T6 Taylor test with the MCA rod (Johnson-Cook, large strain): Lf/L0, "
               "Df/D0 against the tests, error against wall time")
    params = PARAMS
    json_name = "result.json"

    def tag(self, run):
        t = f"{run.v['tests'].replace(',', '_').replace('/', '').replace(' ', '')}"
        return t if run.v["material"] == "Al6061-T6" else f"{t}_{run.v['material']}"

    def plan(self, run):
        """(test, across, taylor scene overrides) of every run."""
        v = run.v
        plan = []
        for across in v["across"]:
            for t in select_tests(v["tests"]):
                plan.append((t, across, {"method": "mca", "L0": f"{t['L0_mm']}mm", "D0": f"{t['D0_mm']}mm",
                                         "V": f"{t['V_m_s']}m/s", "r0": f"{t['D0_mm'] / across:.6g}mm",
                                         "wall": v["wall"]}))
                if v["material"] != "Al6061-T6":           # the isothermal runs keep their cache keys
                    plan[-1][2]["mca_material"] = v["material"]
        return plan

    def collect(self, run, plan):
        scene = get_scene("taylor")
        stream = None if run.quiet else sys.stdout
        rows = []
        for t, across, ov in plan:
            res, err, wall = run_scene(scene, ov, cache=run.cache)
            row = _row(t, across, res, err, wall)
            rows.append(row)
            if stream:
                e = row.get("Lf_err")
                print(f"  {row['test']:>12} at {int(across)} across: Lf/L0 "
                      f"{row.get('Lf_mca') if row.get('Lf_mca') is None else round(row['Lf_mca'], 4)} vs "
                      f"{row.get('Lf_test')} ({'-' if e is None else f'{100 * e:+.1f}%'}), {wall:.0f} s"
                      + (f"  {err}" if err else ""), file=stream, flush=True)
        return rows

    def report(self, run, rows):
        folder = run.folder
        cols = CSV_COLUMNS + (["T_max"] if any("T_max" in r for r in rows) else [])
        write_csv(folder / "mca_taylor.csv", rows, cols)
        text = format_table(rows, TABLE, title="MCA Taylor rods (Johnson-Cook 6061-T6) against the tests")
        (folder / "mca_taylor.md").write_text(markdown_table(rows, TABLE) + "\n")
        png = plot_taylor(rows, folder / "mca_taylor.png")
        files = [folder / "mca_taylor.csv", folder / "mca_taylor.md", png]
        res = {"study": "mca-taylor", "rows": rows, "summary": _summary(rows), "aims": {"Lf": AIM_LF, "Df": AIM_DF},
               "files": [str(f) for f in files]}
        return Report(res, [text], files)


taylor_study = register_study(TaylorStudy())


def plot_taylor(rows, path):
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    acr = sorted({r["across"] for r in rows})
    two = len(acr) > 1
    fig, axes = plt.subplots(1, 2 if two else 1, figsize=(11 if two else 5.5, 5))
    ax = axes[0] if two else axes
    for a in acr:
        sel = [r for r in rows if r["across"] == a and r.get("Lf_mca") is not None and r.get("Lf_test")]
        ax.plot([r["Lf_test"] for r in sel], [r["Lf_mca"] for r in sel], "o", ms=4, label=f"MCA, {a} across")
    ax.plot([0.3, 1.0], [0.3, 1.0], "k-", lw=0.8, label="identity")
    ax.fill_between([0.3, 1.0], [0.3 * 0.95, 0.95], [0.3 * 1.05, 1.05], color="0.88", label="+-5%")
    ax.set_xlabel("measured Lf/L0")
    ax.set_ylabel("computed Lf/L0")
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    if two:
        b = axes[1]
        for name in sorted({r["test"] for r in rows}):
            sel = sorted([r for r in rows if r["test"] == name and r.get("Lf_err") is not None],
                         key=lambda r: r["wall_s"])
            if sel:
                b.plot([r["wall_s"] for r in sel], [100 * abs(r["Lf_err"]) for r in sel], "o-", ms=4, label=name)
        b.set_xscale("log")
        b.set_xlabel("wall time (s)")
        b.set_ylabel("|Lf/L0 error| (%)")
        b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
