"""``clusterdyn study flow-stress``: the flow stress of a CD polycrystal against its packing.

The material-point test is :func:`clusterdyn.scenes.material_point.material_point`: a periodic
cube of clusters quenched, then compressed in uniaxial strain at the strain rate ``rate`` (per
r0/c0) to the last strain of ``strains`` and held for ``hold``; the cell's stress is read along
the way.  Each run is the cached unit :data:`clusterdyn.studies.point.POINT`.

**Flow stress** (what the study reports): the relaxed von Mises intensity
at the last strain of ``strains`` (default 15%, reached at 1e-3 per r0/c0).
In uniaxial strain an ideally plastic isotropic solid that has yielded
carries ``sigma_axial - sigma_lateral = Y``, so the intensity, which is
``|sigma_axial - sigma_lateral|`` here, is its yield stress ``Y``; an
elastic solid instead carries ``(C11 - C12) eps``, which grows with the
strain.  The intensity on the ramp at the smaller strains is reported
beside it, so a reader sees whether it has levelled off.  The relaxed value
depends on the rate (a fast ramp overshoots, breaks boundary pairs and
relaxes lower), so the rate is part of the definition; the study sweeps it.

The study (:class:`FlowStressStudy`)
------------------------------------

Around a default packing (grain diameter, porosity, cutoff rc, grain
boundaries bonded or repulsive) it varies one factor at a time, plus (with
``grid``) the grain size x porosity grid and the strain rates, with
``seeds`` polycrystals per point (mean and standard deviation), and the
[100] single crystal as a reference row.  It writes ``flow_stress.csv``
(the data behind the figure), ``flow_stress_runs.csv``, ``flow_stress.md``,
``flow_stress.png`` and ``flow_stress.json``, and prints the packing
closest to ``target`` (a yield stress); if none reaches it, how far the
nearest is and which change of which factor lowers the flow stress
(:func:`advise`), and (``combine``) it runs the packing with every lowering
change at once.  Every run is kept in
``OUT/runs/flow-stress-point-<hash of its parameters>/result.json`` (or
``error.json``); a study run again on the same folder reads them back, so
an interrupted or extended study only runs what is missing.

The point runner (:mod:`clusterdyn.studies.point`) also takes the boundary pair law (``law_sigma_t``, ``law_G_c``, ``law_tau_c``,
``law_mu``, ``law_select``; docs/theory.md 1.11) and the kind of test (``test``: ``confined``,
the uniaxial strain above; ``unconfined``, uniaxial stress; ``tension``, stretched in uniaxial
strain: the spall strength).  :mod:`clusterdyn.studies.calibrate` maps the law's strength to the
unconfined flow stress, the spall strength, the confined flow stress and the moduli with them.
"""

import math

import numpy as np

from .. import units
from ..analysis.stress import von_mises
from ..errors import InputError
from ..scenes.base import Param
from ..scenes.common import matplotlib_agg
from ..scenes.material_point import BOUNDARIES
from ..scenes.shock import CD_MATERIALS
from .base import Report, Study, register_study
from .common import (ListParam, format_table, markdown_table, progress_bar, run_folder, run_scene,
                     write_csv, write_json)
from .point import POINT, RUNS


# --------------------------------------------------------------------------- the study
PARAMS = [
    Param("material", "Al", "material", kind="choice", choices=CD_MATERIALS),
    Param("r0", 100.0, "cluster size (stresses do not depend on it)", unit="um", low=0.0, low_open=True),
    Param("size", 24.0, "cube edge, in r0", low=6.0),
    Param("grain_size", 11.0, "default packing: mean grain diameter, in r0", low=3.0),
    Param("porosity", 0.14, "default packing: porosity", low=0.0, high=0.5),
    Param("rc", 1.15, "default packing: cutoff (multiple of r0)", low=1.0, high=1.414, low_open=True),
    Param("boundaries", "bonded", "default packing: grain boundaries", kind="choice", choices=BOUNDARIES),
    ListParam("grain_sizes", (5.0, 8.0, 11.0, 14.0), "grain diameters swept, in r0", low=3.0),
    ListParam("porosities", (0.08, 0.11, 0.14, 0.20), "porosities swept", low=0.0, high=0.5),
    ListParam("rcs", (1.10, 1.15, 1.20), "cutoffs swept", low=1.0, high=1.414, low_open=True),
    Param("boundary_kinds", "bonded,repulsive", "grain boundaries swept (comma separated: bonded, repulsive)",
          kind="str"),
    ListParam("rates", (5e-4, 1e-3, 2e-3), "strain rates swept at the default packing (per r0/c0; not a "
              "packing factor: shows the rate dependence)", low=0.0, low_open=True),
    Param("grid", True, "also every grain_size x porosity pair (at the default rc and boundaries)", kind="bool"),
    Param("combine", True, "if no packing reaches the target: one more point with every factor at the end of "
          "its sweep that lowers the flow stress", kind="bool"),
    Param("seeds", 2, "polycrystals (seeds 1..n) per point", kind="int", low=1),
    Param("single", True, "the [100] single crystal as a reference row", kind="bool"),
    ListParam("strains", (0.05, 0.10, 0.15), "strains at which the curve is read; the flow stress is the "
              "relaxed intensity at the last", low=0.0, high=0.49, low_open=True),
    Param("rate", 1e-3, "default strain rate of the ramp, per r0/c0", low=0.0, low_open=True),
    Param("hold", 30.0, "hold at the final strain, in r0/c0", low=0.0, low_open=True),
    Param("average", 10.0, "window at the end of the hold, in r0/c0", low=0.0, low_open=True),
    Param("dt", 0.1, "time step, in r0/c0", low=0.0, high=0.5, low_open=True),
    Param("J", 50.0, "pair damping during the test (Gamma = c0/(J r0)); none = off", low=0.0, low_open=True,
          optional=True),
    Param("noise", 10.0, "random velocity after the quench", unit="m/s", low=0.0),
    Param("relax_cycles", 12, "quench cycles of 100 damped steps", kind="int", low=0),
    Param("target", 0.35, "target yield stress (6061-T6: 0.3-0.4 GPa)", unit="GPa", low=0.0, low_open=True),
    Param("reuse", True, "read back runs of the same parameters found in OUT/runs", kind="bool"),
    Param("plots", True, "write the PNG figure", kind="bool"),
]

#: the packing factors, in the order the table and the advice use
FACTORS = ("grain_size", "porosity", "rc", "boundaries")
MIN_GRAINS = 4


def _check(v):
    """Refuse combinations the parameters' own ranges cannot see; returns the boundary list."""
    kinds = tuple(x.strip() for x in str(v["boundary_kinds"]).split(",") if x.strip())
    if not kinds or any(k not in BOUNDARIES for k in kinds):
        raise InputError("boundary_kinds", v["boundary_kinds"], "a comma-separated list of bonded, repulsive")
    strains = v["strains"]
    if any(b <= a for a, b in zip(strains, strains[1:])):
        raise InputError("strains", ",".join(f"{e:g}" for e in strains), "increasing strains")
    if v["average"] > v["hold"]:
        raise InputError("average", v["average"], f"at most the hold ({v['hold']:g} r0/c0)")
    for g in set(v["grain_sizes"]) | {v["grain_size"]}:
        n = v["size"] ** 3 / (math.pi / 6 * g ** 3)
        if n < MIN_GRAINS:
            name = "grain_size" if g == v["grain_size"] else "grain_sizes"
            raise InputError(name, g, f"a grain diameter of at most "
                             f"{v['size'] / (math.pi / 6 * MIN_GRAINS) ** (1 / 3):.3g} r0 ({MIN_GRAINS} grains "
                             f"in the {v['size']:g} r0 cube; {n:.1f} given)")
    return kinds


def plan_points(v, kinds):
    """The points of the study: list of (sweeps, packing dict), the default packing first."""
    base = {"grain_size": v["grain_size"], "porosity": v["porosity"], "rc": v["rc"],
            "boundaries": v["boundaries"], "rate": v["rate"]}
    points = {}

    def add(tag, **change):
        p = {**base, **change}
        key = tuple(p[k] for k in (*FACTORS, "rate"))
        points.setdefault(key, (set(), p))[0].add(tag)

    add("default")
    for g in v["grain_sizes"]:
        add("grain_size", grain_size=g)
    for p in v["porosities"]:
        add("porosity", porosity=p)
    for rc in v["rcs"]:
        add("rc", rc=rc)
    for b in kinds:
        add("boundaries", boundaries=b)
    for r in v["rates"]:
        add("rate", rate=r)
    if v["grid"]:
        for g in v["grain_sizes"]:
            for p in v["porosities"]:
                add("grid", grain_size=g, porosity=p)
    return [(sorted(t), p) for t, p in points.values()]


def _overrides(v, packing, seed, sample="polycrystal"):
    ov = {"material": v["material"], "r0": v["r0"] / units.um, "size": v["size"], "sample": sample,
          "strains": v["strains"], "rate": packing["rate"], "hold": v["hold"], "average": v["average"],
          "dt": v["dt"], "J": v["J"], "noise": v["noise"] / units.m_s, "seed": seed,
          "relax_cycles": v["relax_cycles"], "rc": packing["rc"]}
    if sample == "polycrystal":
        ov.update({k: packing[k] for k in ("grain_size", "porosity", "boundaries")})
    return ov


def _pct(e):
    return f"{100 * e:g}"


def _mean_spread(xs):
    xs = np.array([x for x in xs if x is not None and np.isfinite(x)], float)
    if not len(xs):
        return float("nan"), float("nan")
    return float(xs.mean()), (float(xs.std(ddof=1)) if len(xs) > 1 else float("nan"))


def _point_row(sweeps, packing, runs, strains, sample="polycrystal"):
    """One table row from the runs (SceneResult or error text) of one point."""
    ok = [r for r in runs if not isinstance(r, str)]
    errors = [r for r in runs if isinstance(r, str)]
    row = {"sweeps": "default" if "default" in sweeps else " ".join(sweeps), "sample": sample,
           "grain_size": packing.get("grain_size") if sample == "polycrystal" else None,
           "porosity_target": packing.get("porosity") if sample == "polycrystal" else None,
           "rc": packing["rc"], "boundaries": packing.get("boundaries") if sample == "polycrystal" else None,
           "rate": packing["rate"], "runs": len(ok), "failed": len(errors),
           "error": "; ".join(sorted(set(errors))) or None}
    x = [r.extra for r in ok]
    row["porosity"], _ = _mean_spread([e["sample"].get("porosity", 0.0) for e in x])
    row["n_clusters"], _ = _mean_spread([e["n_clusters"] for e in x])
    for k, e in enumerate(strains):
        row[f"sigma_u_{_pct(e)}"], row[f"sigma_u_{_pct(e)}_spread"] = _mean_spread([d["curve"][k]["sigma_u"]
                                                                                   for d in x])
    row["sigma_u_ramp_end"], _ = _mean_spread([d["sigma_u_ramp_end"] for d in x])
    row["flow_stress"], row["flow_stress_spread"] = _mean_spread([d["flow_stress"] for d in x])
    row["sigma_axial"], _ = _mean_spread([d["relaxed"]["sigma_axial"] for d in x])
    row["sigma_lateral"], _ = _mean_spread([d["relaxed"]["sigma_lateral"] for d in x])
    row["wall_s"] = float(sum(r.wall_time_s for r in ok))
    return row


def columns(strains):
    last = _pct(strains[-1])
    cols = [("sweeps", "sweeps", ""), ("grain_size", "grain (r0)", "g"), ("porosity_target", "porosity target", ".2f"),
            ("porosity", "porosity built", ".3f"), ("rc", "rc", "g"), ("boundaries", "boundaries", ""),
            ("rate", "rate (1/tau)", "g"), ("runs", "runs", "d"), ("failed", "failed", "d")]
    cols += [(f"sigma_u_{_pct(e)}", f"s_u {_pct(e)}% ramp", ".2f") for e in strains]
    cols += [("flow_stress", f"flow stress (s_u {last}% relaxed)", ".2f"), ("flow_stress_spread", "+-", ".2f"),
             ("sigma_axial", "-s_xx", ".2f"), ("sigma_lateral", "-s_yy", ".2f"), ("n_clusters", "clusters", ".0f"),
             ("wall_s", "wall s", ".0f")]
    return cols


def advise(rows, v):
    """The packing closest to the target, and (if none reaches it) how far and what lowers the flow stress.

    Returns a dict with ``closest`` (a row), ``reached`` (bool: measured flow
    stresses lie on both sides of the target, or one within 10% of it),
    ``lines`` (text) and ``directions`` (per factor: the change that lowers
    the flow stress, from the one-factor sweep through the default packing).
    """
    target = v["target"] / units.GPa
    cand = [r for r in rows if r["sample"] == "polycrystal" and r["rate"] == v["rate"]
            and np.isfinite(r["flow_stress"])]
    if not cand:
        return {"closest": None, "reached": False, "lines": ["closest packing: no successful run"],
                "directions": []}
    best = min(cand, key=lambda r: abs(r["flow_stress"] - target))
    fs = np.array([r["flow_stress"] for r in cand])
    reached = bool((fs.min() <= target <= fs.max()) or abs(best["flow_stress"] - target) <= 0.1 * target)
    lines = [f"closest packing: grain_size={best['grain_size']:g} r0, porosity={best['porosity_target']:g} "
             f"(built {best['porosity']:.3f}), rc={best['rc']:g}, boundaries={best['boundaries']} gives "
             f"{best['flow_stress']:.3g} GPa (target {target:g} GPa)"]
    directions = []
    for f in FACTORS:
        line = [r for r in cand if (f in r["sweeps"].split() or "default" in r["sweeps"].split())
                and all(r[g] == v[g] for g in FACTORS if g not in (f, "porosity"))
                and (f == "porosity" or r["porosity_target"] == v["porosity"])]
        dflt = [r for r in line if "default" in r["sweeps"].split()]
        if len(line) < 2 or not dflt:
            continue
        ref = dflt[0]
        lower = min(line, key=lambda r: r["flow_stress"])
        if lower is ref:
            continue
        key = "porosity_target" if f == "porosity" else f
        if f == "boundaries":
            change = f"{lower[f]} boundaries"
        else:
            word = {"grain_size": ("smaller", "larger"), "porosity": ("lower", "higher"), "rc": ("smaller", "larger")}
            change = f"{word[f][0] if lower[key] < ref[key] else word[f][1]} {f}"
        directions.append({"factor": f, "change": change, "from": ref[key], "to": lower[key],
                           "flow_from": ref["flow_stress"], "flow_to": lower["flow_stress"],
                           "drop": ref["flow_stress"] - lower["flow_stress"]})
    directions.sort(key=lambda d: -d["drop"])
    if not reached:
        side = "above" if best["flow_stress"] > target else "below"
        ratio = best["flow_stress"] / target
        how = f"{ratio:.1f} times the target" if side == "above" else f"{ratio:.0%} of the target"
        lines.append(f"no packing reaches the target: the nearest, {best['flow_stress']:.3g} GPa, is "
                     f"{abs(best['flow_stress'] - target):.3g} GPa {side} it ({how})")
        if side == "above":
            for d in directions:
                fr = d["from"] if isinstance(d["from"], str) else f"{d['from']:g}"
                to = d["to"] if isinstance(d["to"], str) else f"{d['to']:g}"
                lines.append(f"  lowers it: {d['change']} ({d['factor']} {fr} -> {to}: "
                             f"{d['flow_from']:.3g} -> {d['flow_to']:.3g} GPa)")
    return {"closest": best, "reached": reached, "lines": lines, "directions": directions}


def _run_jobs(jobs, cache, v, progress, results, run_rows):
    """Run (or read back) ``jobs`` = [(point key, seed, overrides)]; fills ``results`` and ``run_rows``."""
    bar = progress_bar(len(jobs), "flow-stress", progress)
    for n, seed, ov in jobs:
        if bar is not None:
            keys = ("sample", "grain_size", "porosity", "rc", "boundaries", "rate")
            bar.set_postfix_str(", ".join(f"{k}={ov[k]}" for k in keys if k in ov) + f" seed {seed}")
        try:
            res, err, wall = run_scene(POINT, ov, progress=False, cache=cache, reuse=v["reuse"])
        except InputError as exc:             # e.g. a porosity the boundary rule cannot reach at this grain size
            res, err, wall = None, f"InputError: {exc}", 0.0
            folder = run_folder(cache, POINT, ov)     # kept like a failed run, so a resumed study skips it
            folder.mkdir(parents=True, exist_ok=True)
            write_json(folder / "error.json", {"params": POINT.display(POINT.parse(ov)), "error": err,
                                               "wall_time_s": wall})
        results.setdefault(n, []).append(res if res is not None else err)
        rr = {"point": n, "seed": seed, "folder": str(run_folder(cache, POINT, ov)), "wall_s": wall, "error": err,
              **{k: ov.get(k) for k in ("sample", "grain_size", "porosity", "rc", "boundaries", "rate")}}
        if res is not None:
            rr.update({"flow_stress": res.extra["flow_stress"], "porosity_built": res.extra["sample"].get("porosity"),
                       "sigma_u_ramp_end": res.extra["sigma_u_ramp_end"], "n_clusters": res.extra["n_clusters"]})
        run_rows.append(rr)
        if bar is not None:
            bar.update(1)
            bar.write(f"  {rr['sample']} {rr.get('grain_size', '')} {rr.get('porosity', '')} rc={rr['rc']} "
                      f"{rr.get('boundaries', '')} rate={rr['rate']} seed {seed}: "
                      + (f"flow stress {rr['flow_stress']:.3f} GPa, {wall:.1f} s" if res is not None else str(err)))
    if bar is not None:
        bar.close()


class FlowStressStudy(Study):
    """The flow stress of CD packings around a default one (module docstring).

    Its result holds ``rows`` (one per point: means and spreads over seeds), ``runs`` (every run),
    ``default`` (the default packing's row), ``single`` (the single crystal's row or None),
    ``advice`` (closest packing to ``target``), ``runs_computed`` and ``runs_reused`` (runs read
    back from ``OUT/runs``), ``markdown``, ``files`` and ``wall_time_s``.  With ``combine``, when no
    packing reaches the target, one more point is run: every factor at the end of its sweep that
    lowers the flow stress (the floor of the swept ranges).
    """

    name = "flow-stress"
    summary = ("flow stress of a CD polycrystal (material-point test) against grain size, porosity, rc and "
               "boundary cohesion; the packing closest to a target")
    params = PARAMS
    json_name = "flow_stress.json"

    def tag(self, run):
        return run.v["material"]

    def prepare(self, run):
        run.kinds = _check(run.v)

    def plan(self, run):
        """(point key, seed, overrides) of every run, each checked before any work."""
        v = run.v
        run.points = plan_points(v, run.kinds)
        run.seeds = list(range(1, v["seeds"] + 1))
        jobs = [(n, seed, _overrides(v, p, seed)) for n, (_, p) in enumerate(run.points) for seed in run.seeds]
        if v["single"]:
            jobs.append(("single", 1, _overrides(v, {"rc": v["rc"], "rate": v["rate"]}, 1, sample="single")))
        for _, _, ov in jobs:
            POINT.parse(ov)                       # every run's parameters checked before any work
        return jobs

    def collect(self, run, jobs):
        """Every run (or read back); the rows, the advice and (``combine``) the combined point."""
        v, points, strains = run.v, run.points, run.v["strains"]
        n0 = RUNS[0]
        results, run_rows = {}, []
        _run_jobs(jobs, run.cache, v, run.progress, results, run_rows)
        rows = [_point_row(t, p, results[n], strains) for n, (t, p) in enumerate(points)]
        advice = advise(rows, v)
        if v["combine"] and not advice["reached"] and len(advice["directions"]) >= 2:
            combo = {**points[0][1], **{d["factor"]: d["to"] for d in advice["directions"]}}
            key = tuple(combo[k] for k in (*FACTORS, "rate"))
            if key not in {tuple(p[k] for k in (*FACTORS, "rate")) for _, p in points}:
                points.append((["combined"], combo))
                n = len(points) - 1
                more = [(n, seed, _overrides(v, combo, seed)) for seed in run.seeds]
                jobs += more
                _run_jobs(more, run.cache, v, run.progress, results, run_rows)
                rows.append(_point_row(["combined"], combo, results[n], strains))
                advice = advise(rows, v)
        single = None
        if v["single"]:
            single = _point_row(["reference"], {"rc": v["rc"], "rate": v["rate"]}, results["single"], strains,
                                sample="single")
            single["sample"] = "single [100]"
        computed = RUNS[0] - n0
        return {"rows": rows, "single": single, "advice": advice, "results": results, "run_rows": run_rows,
                "computed": computed, "reused": len(jobs) - computed}

    def report(self, run, c):
        v, folder, strains = run.v, run.folder, run.v["strains"]
        rows, single, advice, default = c["rows"], c["single"], c["advice"], c["rows"][0]
        table_rows = rows + ([single] if single else [])
        cols = columns(strains)
        last = _pct(strains[-1])
        text = [format_table(table_rows, cols,
                             f"flow stress of {v['material']} cluster packings: periodic cubes of {v['size']:g} r0, "
                             f"uniaxial strain along x to {last}% at {v['rate']:g}/tau (tau = r0/c0), hold "
                             f"{v['hold']:g} tau; stresses in GPa, mean over {v['seeds']} seed(s), +- = std")]
        text.append(f"default packing (grain_size={v['grain_size']:g} r0, porosity={v['porosity']:g}, rc={v['rc']:g}, "
                    f"{v['boundaries']}): flow stress {default['flow_stress']:.3g} +- "
                    f"{default['flow_stress_spread']:.2g} GPa (relaxed intensity at {last}%)")
        text.extend(advice["lines"])
        text.append(f"runs: {c['computed']} computed, {c['reused']} read back from {run.cache}")
        md = markdown_table(table_rows, cols)
        files = [write_csv(folder / "flow_stress.csv", table_rows),
                 write_csv(folder / "flow_stress_runs.csv", c["run_rows"])]
        (folder / "flow_stress.md").write_text(md + "\n")
        files.append(folder / "flow_stress.md")
        if v["plots"]:
            files.append(_plot(folder / "flow_stress.png", rows, single, v, c["results"]))
        result = {"study": "flow-stress", "material": v["material"], "rows": rows, "single": single,
                  "default": default, "runs": c["run_rows"],
                  "advice": {k: x for k, x in advice.items() if k != "lines"}, "advice_text": advice["lines"],
                  "runs_computed": c["computed"], "runs_reused": c["reused"], "markdown": md,
                  "definition": f"flow stress = von Mises intensity of the cell's mean stress over the last "
                  f"{v['average']:g} r0/c0 of a {v['hold']:g} r0/c0 hold at {last}% uniaxial strain, reached at "
                  f"{v['rate']:g} per r0/c0"}
        return Report(result, text, files)


flow_stress_study = register_study(FlowStressStudy())


def _plot(path, rows, single, v, results):
    """Flow stress against each factor (one-factor lines, the grid as extra lines) and the flow curves."""
    plt = matplotlib_agg()
    fig, axs = plt.subplots(2, 3, figsize=(13, 7.5))
    target = v["target"] / units.GPa
    last = _pct(v["strains"][-1])
    at_rate = [r for r in rows if r["rate"] == v["rate"]]

    def at_default_rc_boundaries(r):
        return r["rc"] == v["rc"] and r["boundaries"] == v["boundaries"]

    # grain size: one line per porosity (the grid), the default porosity bold
    for ax, f, g, gl in ((axs[0, 0], "grain_size", "porosity_target", "porosity"),
                         (axs[0, 1], "porosity_target", "grain_size", "grain")):
        for val in sorted({r[g] for r in at_rate if r[g] is not None}):
            line = sorted((r for r in at_rate if r[g] == val and at_default_rc_boundaries(r)
                           and np.isfinite(r["flow_stress"])), key=lambda r: r[f])
            if len(line) < 1:
                continue
            dflt = val == (v["porosity"] if g == "porosity_target" else v["grain_size"])
            ax.errorbar([r[f] for r in line], [r["flow_stress"] for r in line],
                        yerr=[0 if not np.isfinite(r["flow_stress_spread"]) else r["flow_stress_spread"] for r in line],
                        fmt="o-", lw=2.2 if dflt else 1.0, capsize=3,
                        label=f"{gl} {val:g}" + (" (default)" if dflt else ""))
        ax.set_xlabel({"grain_size": "grain diameter (r0)", "porosity_target": "porosity"}[f])
    for ax, f, lab in ((axs[0, 2], "rc", "cutoff rc (r0)"), (axs[1, 0], "boundaries", "grain boundaries"),
                       (axs[1, 1], "rate", "strain rate (per r0/c0)")):
        sel = [r for r in rows if (f in r["sweeps"].split() or "default" in r["sweeps"].split())
               and np.isfinite(r["flow_stress"])]
        if f == "boundaries":
            sel.sort(key=lambda r: BOUNDARIES.index(r[f]))
            x = np.arange(len(sel))
            ax.set_xticks(x, [r[f] for r in sel])
        else:
            sel.sort(key=lambda r: r[f])
            x = [r[f] for r in sel]
        ax.errorbar(x, [r["flow_stress"] for r in sel],
                    yerr=[0 if not np.isfinite(r["flow_stress_spread"]) else r["flow_stress_spread"] for r in sel],
                    fmt="o-", capsize=3, label="default packing, one factor varied")
        if f == "rate":
            ax.set_xscale("log")
        ax.set_xlabel(lab)
    for ax in (axs[0, 0], axs[0, 1], axs[0, 2], axs[1, 0], axs[1, 1]):
        ax.axhline(target, color="r", ls="--", lw=1, label=f"target {target:g} GPa")
        ax.set_ylabel(f"flow stress (GPa): s_u relaxed at {last}%")
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
    # flow curves: the default packing's first seed, the lowest packing and the single crystal
    ax = axs[1, 2]
    picks = [(0, "default packing")]
    ok = [i for i, r in enumerate(rows) if np.isfinite(r["flow_stress"]) and r["rate"] == v["rate"]]
    if ok:
        lo = min(ok, key=lambda i: rows[i]["flow_stress"])
        if lo != 0:
            r = rows[lo]
            picks.append((lo, f"lowest: grain {r['grain_size']:g}, porosity {r['porosity_target']:g}, rc {r['rc']:g}, "
                              f"{r['boundaries']}"))
    if single is not None:
        picks.append(("single", "single crystal [100]"))
    for i, lab in picks:
        res = [x for x in results.get(i, []) if not isinstance(x, str)]
        if not res:
            continue
        ser = res[0].extra["series"]
        S = np.array(ser["stress"])
        ax.plot(100 * np.array(ser["strain"]), von_mises(S), lw=1, label=lab)
    ax.axhline(target, color="r", ls="--", lw=1)
    ax.set_xlabel("uniaxial strain (%); the drop at the end is the hold")
    ax.set_ylabel("von Mises intensity (GPa)")
    ax.legend(fontsize=7)
    fig.suptitle(f"CD flow stress of {v['material']} packings (cube {v['size']:g} r0, uniaxial strain at "
                 f"{v['rate']:g}/tau, relaxed at {last}%)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
