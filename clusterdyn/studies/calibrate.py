"""``clusterdyn study calibrate``: packing parameters of the boundary pair law for target strengths.

The law (docs/theory.md 1.11) adds a tensile strength, a fracture energy and a shear resistance to
a CD polycrystal's pairs.  This study **tunes** them: the presets it produces are calibrated to
targets, not predicted.  For each candidate packing (the law on the pairs across grain boundaries
or on every pair, ``selects``, times the tensile strengths ``sigma_ts``) it runs the material-point
tests of :func:`clusterdyn.scenes.material_point.material_point` on a periodic cube:

- ``unconfined``: uniaxial stress (lateral axes rescaled toward zero stress), compressed to 8%
  and held: **flow_stress** = the relaxed von Mises intensity (a metal's flow stress is measured
  so: 6061-T6 0.3 GPa), and Young's modulus E (a line through the ramp up to 2%);
- ``tension``: uniaxial strain, stretched: **spall_strength** = the largest tensile axial stress;
- ``confined`` (``confined=true``): uniaxial strain compressed to 15% (the flow-stress study's
  definition): **confined_flow**, and the longitudinal modulus M (a line up to 5%).

The fracture energy of each candidate follows from the ``ductility`` ratio ``delta_f / delta_0``
of the law (``G_c = ductility F_t^2 / (2 k_n A_w)``, r0-dependent: stated per candidate).  The
objective is the sum of squared log-ratios to the targets given.  After the grid, every select's
values are interpolated (log-log in sigma_t) to the sigma_t that minimises the objective, and that
candidate is run too.  The best measured candidate is written as a packing file
(``best_packing.json``, usable as ``--set packing=FILE`` in the impact scenes) with the values it
achieved.  With ``packing=NAME`` the study measures that packing only (e.g. to check a preset).

Every run is cached in ``OUT/runs`` (the flow-stress study's point runner): an interrupted or
extended study only runs what is missing.  Outputs: ``calibrate.csv``, ``calibrate.md``,
``calibrate.png``, ``calibrate.json``, ``best_packing.json``.
"""

import math

import numpy as np

from .. import units
from ..build.polycrystal import packing_spec
from ..errors import InputError
from ..materials import get_material
from ..potentials import ClusterPotential
from ..scenes.base import Param
from ..scenes.common import matplotlib_agg
from ..scenes.shock import CD_MATERIALS
from .base import Report, Study, register_study
from .common import ListParam, format_table, markdown_table, run_scene, write_csv, write_json
from .point import POINT

TARGETS = ("flow_stress", "spall_strength", "confined_flow")

PARAMS = [
    Param("material", "Al-6061-T6", "material", kind="choice", choices=CD_MATERIALS),
    Param("flow_stress", None, "target: unconfined (uniaxial-stress) flow stress", unit="GPa", low=0.0,
          low_open=True, optional=True),
    Param("spall_strength", None, "target: spall strength (tension in uniaxial strain)", unit="GPa", low=0.0,
          low_open=True, optional=True),
    Param("confined_flow", None, "target: confined flow stress (the flow-stress study's)", unit="GPa", low=0.0,
          low_open=True, optional=True),
    Param("packing", None, "measure this packing only (a preset name or JSON file), no search", kind="str",
          optional=True),
    Param("r0", 100.0, "cluster size (sets G_c through the ductility)", unit="um", low=0.0, low_open=True),
    Param("size", 16.0, "cube edge, in r0", low=6.0),
    Param("grain_size", 5.0, "grain diameter, in r0", low=3.0),
    Param("porosity", 0.14, "porosity as built", low=0.0, high=0.5),
    Param("rc", 1.15, "cutoff (multiple of r0)", low=1.0, high=1.414, low_open=True),
    Param("selects", "all,boundary", "pairs with the law: all and/or boundary (comma separated)", kind="str"),
    ListParam("sigma_ts", (2.0, 4.0, 8.0, 16.0), "bond tensile strengths tried, GPa", low=0.0, low_open=True),
    Param("ductility", 8.0, "delta_f / delta_0 of the law (sets G_c)", low=1.0, low_open=True),
    Param("mu", 0.0, "Coulomb friction of the law", low=0.0),
    Param("tau_c", 0.0, "cohesive shear strength of the law", unit="GPa", low=0.0),
    Param("confined", True, "also the confined test (15% uniaxial strain; the longest run)", kind="bool"),
    Param("unconfined", True, "the unconfined test (the flow stress); false: only what the targets need",
          kind="bool"),
    Param("relax_cycles", 12, "quench cycles of 100 damped steps (held, then a third of them released)",
          kind="int", low=1),
    Param("reference", True, "also the packing without the law (bonded boundaries, the paper's rule)",
          kind="bool"),
    Param("refine", True, "run the interpolated best sigma_t of every select", kind="bool"),
    Param("seeds", 1, "polycrystals (seeds 1..n) per candidate", kind="int", low=1),
    Param("reuse", True, "read back runs found in OUT/runs", kind="bool"),
    Param("plots", True, "write the PNG", kind="bool"),
]

#: the tests: overrides of the point (strains, hold, average in r0/c0)
TEST_SETTINGS = {
    "unconfined": {"strains": (0.02, 0.05, 0.08), "hold": 10.0, "average": 5.0},
    "tension": {"strains": (0.01, 0.03, 0.06), "hold": 2.0, "average": 1.0},
    "confined": {"strains": (0.05, 0.10, 0.15), "hold": 10.0, "average": 5.0},
}


def g_c_for(material, r0, sigma_t, ductility):
    """G_c (J/m^2) of a bond of tensile strength sigma_t (GPa) whose softening ends at
    ``ductility`` times its peak opening (docs/theory.md 1.11)."""
    pot = ClusterPotential(material, r0)
    k = float(pot.stiffness())
    ft = sigma_t * units.GPa * r0 ** 2 / (2 * math.sqrt(2))
    d0 = ft / k
    wb = 0.5 * ft * ductility * d0
    return wb / (r0 ** 2 / 4) / (units.J / units.m ** 2)


def secant_modulus(extra, upto):
    """Slope (GPa) of a straight line through the ramp's -sigma_axial against the strain up to
    ``upto`` (the first reading): Young's modulus of the unconfined test, the longitudinal one of
    the confined test.  (The first 0.5% alone is dominated by the quenched packing's settling.)"""
    ser = extra["series"]
    e = np.asarray(ser["strain"])
    s = -np.asarray(ser["stress"])[:, int(extra.get("axis", 0))]
    sel = (e > 0) & (e <= upto + 1e-12)
    if sel.sum() < 3:
        return float("nan")
    return float(np.polyfit(e[sel], s[sel], 1)[0])


def _candidates(v, mat):
    sel = [x.strip() for x in str(v["selects"]).split(",") if x.strip()]
    if not sel or any(x not in ("all", "boundary") for x in sel):
        raise InputError("selects", v["selects"], "a comma-separated list of all, boundary")
    return [(s, float(st)) for s in sel for st in v["sigma_ts"]]


def _law(v, select, sigma_t, mat):
    return {"sigma_t": sigma_t, "G_c": g_c_for(mat, v["r0"], sigma_t, v["ductility"]), "tau_c": v["tau_c"] / units.GPa,
            "mu": v["mu"], "select": select}


def _overrides(v, law, test, seed, spec=None):
    ov = {"material": v["material"], "r0": v["r0"] / units.um, "size": v["size"], "grain_size": v["grain_size"],
          "porosity": v["porosity"], "rc": v["rc"], "seed": seed, "test": test, **TEST_SETTINGS[test]}
    if v["relax_cycles"] != 12:
        ov["relax_cycles"] = v["relax_cycles"]
    if spec is not None:
        ov.update(grain_size=spec["grain_size"], porosity=spec["porosity"], rc=spec["rc"])
        if spec["boundaries"] in ("bonded", "repulsive"):
            ov["boundaries"] = spec["boundaries"]
        law = spec.get("law") if spec["boundaries"] == "law" else None
    if law is not None:
        ov.update({"law_sigma_t": law["sigma_t"], "law_G_c": law["G_c"], "law_tau_c": law.get("tau_c", 0.0),
                   "law_mu": law.get("mu", 0.0), "law_select": law.get("select", "boundary")})
    return ov


def _measure(v, label, law, cache, tests, bar, spec=None):
    """Run (or read back) the tests of one candidate over the seeds; returns its row."""
    row = {"candidate": label, "select": (law or {}).get("select", "-"),
           "sigma_t": (law or {}).get("sigma_t"), "G_c": (law or {}).get("G_c")}
    vals = {"flow_stress": [], "spall_strength": [], "confined_flow": [], "E_young": [], "M_long": [],
            "failed_at_release": [], "porosity": []}
    wall = 0.0
    errors = []
    for seed in range(1, v["seeds"] + 1):
        for test in tests:
            res, err, w = run_scene(POINT, _overrides(v, law, test, seed, spec), progress=False, cache=cache,
                                    reuse=v["reuse"])
            wall += w
            if bar is not None:
                bar.update(1)
            if res is None:
                errors.append(f"{test} seed {seed}: {err}")
                continue
            x = res.extra
            if test == "unconfined":
                vals["flow_stress"].append(x["flow_stress"])
                vals["E_young"].append(secant_modulus(x, TEST_SETTINGS[test]["strains"][0]))
            elif test == "tension":
                vals["spall_strength"].append(x["spall_strength"])
            else:
                vals["confined_flow"].append(x["flow_stress"])
                vals["M_long"].append(secant_modulus(x, TEST_SETTINGS[test]["strains"][0]))
            b = (x.get("relax") or {}).get("boundary")
            if b and test == "tension":
                vals["failed_at_release"].append(b["failed"] / max(1, b["bonds"]))
            vals["porosity"].append(x["sample"].get("porosity", 0.0))
    for k, xs in vals.items():
        xs = [a for a in xs if a is not None and np.isfinite(a)]
        row[k] = float(np.mean(xs)) if xs else float("nan")
        row[k + "_spread"] = float(np.std(xs, ddof=1)) if len(xs) > 1 else float("nan")
    row["wall_s"] = wall
    row["error"] = "; ".join(errors) or None
    return row


def _objective(row, targets):
    s = 0.0
    for k, t in targets.items():
        x = row.get(k)
        if x is None or not np.isfinite(x) or x <= 0:
            return math.inf
        s += math.log(x / t) ** 2
    return s


def _interpolate(rows, targets):
    """sigma_t minimising the objective on log-log lines through a select's rows (None if < 2 rows)."""
    ok = [r for r in rows if np.isfinite(_objective(r, targets))]
    if len(ok) < 2:
        return None
    ls = np.log([r["sigma_t"] for r in ok])
    fits = {k: np.polyfit(ls, np.log([r[k] for r in ok]), 1) for k in targets}
    grid = np.linspace(ls.min() - 0.7, ls.max() + 0.7, 400)
    obj = sum((np.polyval(fits[k], grid) - math.log(t)) ** 2 for k, t in targets.items())
    return float(np.exp(grid[int(np.argmin(obj))]))


COLUMNS = [("candidate", "candidate", ""), ("select", "law on", ""), ("sigma_t", "sigma_t (GPa)", ".3g"),
           ("G_c", "G_c (J/m2)", ".3g"), ("flow_stress", "flow stress, unconfined (GPa)", ".3f"),
           ("spall_strength", "spall strength (GPa)", ".3f"), ("confined_flow", "confined flow (GPa)", ".3f"),
           ("E_young", "E (GPa)", ".0f"), ("M_long", "M (GPa)", ".0f"),
           ("failed_at_release", "bonds failed at release", ".2f"), ("porosity", "porosity", ".3f"),
           ("objective", "objective", ".3g"), ("wall_s", "wall s", ".0f")]


def _best_packing(v, best, targets):
    """The packing file's content for the best candidate."""
    law = {"sigma_t": best["sigma_t"], "ductility": v["ductility"], "tau_c": v["tau_c"] / units.GPa,
           "mu": v["mu"], "select": best["select"]}
    return {"grain_size": v["grain_size"], "porosity": v["porosity"], "rc": v["rc"],
            "boundaries": "law", "law": law, "material": v["material"],
            "description": f"calibrated (tuned) by clusterdyn study calibrate to {targets} "
                           f"(G_c {best['G_c']:.4g} J/m^2 at r0 = {v['r0'] / units.um:g} um; "
                           "ductility kept at other r0)",
            "targets": targets, "calibrated": True,
            "achieved": {k: best[k] for k in ("flow_stress", "spall_strength", "confined_flow",
                                              "E_young", "M_long")}}


class CalibrateStudy(Study):
    """Tunes the boundary pair law to target strengths (module docstring).  Its result holds
    ``rows``, ``best``, ``best_packing``, ``targets``, ``files``."""

    name = "calibrate"
    summary = ("tune the boundary pair law to target strengths (flow stress, spall strength): unconfined, "
               "tension and confined material-point tests; writes a packing file")
    params = PARAMS
    json_name = "calibrate.json"

    def tag(self, run):
        return run.v["material"]

    def prepare(self, run):
        v = run.v
        run.mat = get_material(v["material"])
        run.targets = {k: v[k] / units.GPa for k in TARGETS if v[k] is not None}
        run.spec = packing_spec(v["packing"]) if v["packing"] is not None else None
        if run.spec is None and not run.targets:
            raise InputError("flow_stress", None, "at least one target (flow_stress, spall_strength, confined_flow) "
                             "or a packing to measure")
        run.tests = (["unconfined"] if v["unconfined"] else []) + ["tension"] + (["confined"] if v["confined"] else [])
        if "flow_stress" in run.targets and not v["unconfined"]:
            raise InputError("unconfined", False, "true with a flow_stress target (the unconfined test measures it)")
        if "confined_flow" in run.targets and not v["confined"]:
            raise InputError("confined", False, "true with a confined_flow target")

    def plan(self, run):
        """The candidates: (select, sigma_t) of the grid (none when a packing is measured)."""
        return [] if run.spec is not None else _candidates(run.v, run.mat)

    def collect(self, run, cands):
        """The rows: the packing (or the reference), every candidate, then the interpolated ones."""
        v, spec, tests, cache, mat = run.v, run.spec, run.tests, run.cache, run.mat
        n_runs = v["seeds"] * len(tests) * (len(cands) + (1 if v["reference"] or spec is not None else 0))
        bar = run.bar(n_runs, "calibrate")
        rows = []
        if spec is not None:
            rows.append(_measure(v, f"packing {spec.get('name', '')}", spec.get("law"), cache, tests, bar, spec=spec))
        elif v["reference"]:
            rows.append(_measure(v, "no law (bonded)", None, cache, tests, bar))
        for select, st in cands:
            rows.append(_measure(v, f"{select} {st:g}", _law(v, select, st, mat), cache, tests, bar))
        if spec is None and v["refine"] and run.targets:
            for select in dict.fromkeys(s for s, _ in cands):
                st = _interpolate([r for r in rows if r["select"] == select], run.targets)
                if st is not None and all(abs(st - r["sigma_t"]) > 1e-3 * st for r in rows if r["select"] == select):
                    rows.append(_measure(v, f"{select} {st:.3g} (interpolated)", _law(v, select, round(st, 3), mat),
                                         cache, tests, None))
        if bar is not None:
            bar.close()
        return rows

    def report(self, run, rows):
        v, targets, spec, folder = run.v, run.targets, run.spec, run.folder
        for r in rows:
            r["objective"] = _objective(r, targets) if targets else float("nan")
        lawful = [r for r in rows if r["sigma_t"] is not None or spec is not None]
        best = min(lawful, key=lambda r: r["objective"]) if targets and lawful else (rows[0] if rows else None)
        lines = [format_table(rows, COLUMNS, f"calibration of the boundary law, {v['material']}: cube {v['size']:g} r0, "
                              f"grains {v['grain_size']:g} r0, porosity {v['porosity']:g} as built, "
                              f"{v['seeds']} seed(s); targets " + (", ".join(f"{k} {t:g} GPa" for k, t in targets.items())
                                                                    or "none"))]
        best_packing = None
        if best is not None and spec is None and best["sigma_t"] is not None:
            best_packing = _best_packing(v, best, targets)
            write_json(folder / "best_packing.json", best_packing)
            for k, t in targets.items():
                lines.append(f"best: {best['candidate']}: {k} {best[k]:.3g} GPa against {t:g} "
                             f"({100 * (best[k] / t - 1):+.0f}%)")
        md = markdown_table(rows, COLUMNS)
        files = [write_csv(folder / "calibrate.csv", rows)]
        (folder / "calibrate.md").write_text(md + "\n")
        files.append(folder / "calibrate.md")
        if v["plots"] and rows:
            files.append(_plot(folder / "calibrate.png", rows, targets, v))
        if best_packing is not None:
            files.append(folder / "best_packing.json")
        result = {"study": "calibrate", "material": v["material"], "targets": targets, "rows": rows, "best": best,
                  "best_packing": best_packing, "markdown": md}
        return Report(result, lines, files)


calibrate_study = register_study(CalibrateStudy())


def _plot(path, rows, targets, v):
    plt = matplotlib_agg()
    keys = [("flow_stress", "unconfined flow stress (GPa)"), ("spall_strength", "spall strength (GPa)"),
            ("confined_flow", "confined flow stress (GPa)")]
    fig, axs = plt.subplots(1, 3, figsize=(13, 4))
    for ax, (k, lab) in zip(axs, keys):
        for sel, mk in (("all", "o-"), ("boundary", "s-")):
            rr = sorted((r for r in rows if r["select"] == sel and np.isfinite(r[k])), key=lambda r: r["sigma_t"])
            if rr:
                ax.plot([r["sigma_t"] for r in rr], [r[k] for r in rr], mk, label=f"law on {sel} pairs")
        ref = [r for r in rows if r["sigma_t"] is None and np.isfinite(r[k])]
        for r in ref:
            ax.axhline(r[k], color="k", lw=1, ls=":", label=r["candidate"])
        if k in targets:
            ax.axhline(targets[k], color="r", ls="--", lw=1, label=f"target {targets[k]:g}")
        ax.set_xscale("log")
        ax.set_xlabel("bond tensile strength sigma_t (GPa)")
        ax.set_ylabel(lab)
        ax.legend(fontsize=7)
    fig.suptitle(f"boundary law of {v['material']} packings: cube {v['size']:g} r0, grains {v['grain_size']:g} r0, "
                 f"porosity {v['porosity']:g}, ductility {v['ductility']:g}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
