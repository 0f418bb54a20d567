"""``clusterdyn study dusting``: the CD paper's numerical dusting against u, rc, damping and r0.

Runs the ``dusting`` scene (a plane shock from a piston at u onto a smooth
rear free surface, aluminium, r0 = 10 um, by default the paper's 5 mm sample
with 2 x 2 lattice periods across, 1.5 us) over

* the sweep: particle velocities ``us`` (0.5-6 km/s) x cutoffs ``rcs`` (1.1,
  1.2) x damping ``Js`` (off and J = 50) x ``seeds`` of the initial noise
  (3): the dispersed clusters per mm^2 and the dispersed mass fraction at the
  end, mean and spread over the seeds (the paper's figs. 18-19);
* the layer profiles at u = ``profile_u`` (2 km/s), rc = 1.1, without and
  with damping (the paper's fig. 20);
* the resolution sweep: ``r0s`` (5, 10, 20 um) at u = ``resolution_u``,
  rc = 1.1, damping off, with the wall time of each run.

Each run is cached in ``OUT/runs/dusting-<hash>/result.json``
(:func:`clusterdyn.studies.common.run_scene`): a run already there with the
same parameters is read back, so an interrupted study resumes and a longer
list of speeds or seeds only runs what is new.  ``workers`` runs that many
scenes at once in separate processes (each on one thread).

Files in ``--out`` (default ``runs/dusting-<length>mm``): ``dusting_runs.csv``
(one row per run), ``dusting_sweep.csv`` (mean, spread, min, max over the
seeds), ``dusting_count_vs_u.png``, ``dusting_layers.png`` (+ CSV),
``dusting_resolution.csv`` and ``.png``, ``dusting.json``.
"""

import math
from pathlib import Path

import numpy as np

from .. import units
from ..errors import InputError
from ..scenes import get_scene
from ..scenes.base import Param
from .base import Report, Study, register_study
from .common import ListParam, format_table, markdown_table, run_scene, write_csv


class DampingListParam(Param):
    """Comma-separated damping settings: ``none`` (off) or J values, e.g. ``"none,50"``."""

    def __init__(self, name, default, doc):
        super().__init__(name, default, doc, kind="Js")

    def describe(self):
        return f"{self.name} = {','.join('none' if j is None else f'{j:g}' for j in self.default)}  -- {self.doc}"

    def parse(self, value):
        items = value.split(",") if isinstance(value, str) else list(value)
        out = []
        for it in items:
            if it is None or str(it).strip().lower() in ("none", "off"):
                out.append(None)
                continue
            try:
                j = float(it)
            except (TypeError, ValueError):
                raise InputError(self.name, value, "none or positive J values, comma separated (none,50)") from None
            if not (j > 0 and math.isfinite(j)):
                raise InputError(self.name, value, "none or positive J values, comma separated (none,50)")
            out.append(j)
        if not out:
            raise InputError(self.name, value, "at least one damping setting")
        return tuple(out)


PARAMS = [
    ListParam("us", (0.5, 1.0, 2.0, 3.0, 4.0, 6.0), "particle velocities of the sweep", unit="km/s", low=0.0,
              high=10.0, low_open=True),
    ListParam("rcs", (1.1, 1.2), "cutoffs (multiples of r0)", low=1.0, high=1.414, low_open=True),
    DampingListParam("Js", (None, 50.0), "damping settings: none (off) and J values"),
    ListParam("seeds", (1, 2, 3), "seeds of the initial noise", low=0),
    Param("length", 5.0, "sample length (the paper's: 5 mm)", unit="mm", low=0.0, low_open=True),
    Param("r0", 10.0, "cluster size of the sweep", unit="um", low=0.0, low_open=True),
    Param("duration", None, "run time; none = the scene's 1.5 us per 5 mm", unit="us", low=0.0, low_open=True,
          optional=True),
    Param("profile_u", 2.0, "particle velocity of the layer profiles (fig. 20)", unit="km/s", low=0.0,
          low_open=True),
    ListParam("r0s", (5.0, 10.0, 20.0), "cluster sizes of the resolution sweep", unit="um", low=0.0,
              low_open=True, optional=True),
    Param("resolution_u", 2.0, "particle velocity of the resolution sweep", unit="km/s", low=0.0, low_open=True),
    ListParam("resolution_seeds", (1,), "seeds of the resolution sweep", low=0),
    Param("frames", 100, "analysis frames per run", kind="int", low=5),
    Param("workers", 1, "scenes run at once (separate processes, one thread each)", kind="int", low=1),
    Param("cache", None, "folder of the runs' results (default OUT/runs)", kind="str", optional=True),
    Param("reuse", True, "read back runs of the same parameters found in the cache", kind="bool"),
    Param("plots", True, "write the PNG figures", kind="bool"),
]

RUN_COLUMNS = [("u", "u km/s", ".3g"), ("rc", "rc", ".3g"), ("J", "J", ""), ("seed", "seed", "d"),
               ("r0", "r0 um", ".3g"), ("per_mm2", "per mm2", ".4g"), ("clusters", "clusters", "d"),
               ("fragments", "fragments", "d"), ("mass_fraction", "mass frac", ".2e"),
               ("monolayers", "monolayers", ".2f"), ("fsv", "u_fs km/s", ".4f"),
               ("ledger", "ledger res", ".1e"), ("wall_s", "wall s", ".1f"), ("error", "error", "")]

SWEEP_COLUMNS = [("u", "u km/s", ".3g"), ("rc", "rc", ".3g"), ("J", "J", ""), ("n", "seeds", "d"),
                 ("per_mm2_mean", "per mm2 mean", ".4g"), ("per_mm2_spread", "spread (std)", ".3g"),
                 ("per_mm2_min", "min", ".4g"), ("per_mm2_max", "max", ".4g"),
                 ("clusters_max", "max clusters", ".0f"),
                 ("mass_fraction_mean", "mass frac mean", ".2e"), ("fsv_mean", "u_fs km/s", ".4f")]

RES_COLUMNS = [("r0", "r0 um", ".3g"), ("seed", "seed", "d"), ("n_particles", "clusters", "d"),
               ("n_steps", "steps", "d"), ("per_mm2", "per mm2", ".4g"), ("clusters", "clusters", "d"),
               ("mass_fraction", "mass frac", ".2e"), ("spectrum", "N(g) g=1..", ""), ("wall_s", "wall s", ".1f")]


def _k(x):
    """A float rounded for use in a run key (display units)."""
    return round(float(x), 9)


def _jtxt(J):
    return "none" if J is None else f"{J:g}"


def _overrides(v, u, rc, J, seed, r0):
    ov = {"u": u, "rc": rc, "J": _jtxt(J), "seed": int(seed), "r0": r0, "length": v["length"] / units.mm,
          "frames": v["frames"], "h5md": "false", "checkpoint_every": "0"}
    if v["duration"] is not None:
        ov["duration"] = v["duration"] / units.us
    return ov


def _worker(overrides, cache, reuse):
    """Run one scene in a worker process (one thread); the result lands in the cache."""
    from ..parallel import set_max_threads
    set_max_threads(1)
    run_scene(get_scene("dusting"), overrides, progress=False, cache=cache, reuse=reuse)
    return overrides


def _row(res, err, wall, u, rc, J, seed, r0):
    row = {"u": u, "rc": rc, "J": _jtxt(J), "seed": int(seed), "r0": r0, "wall_s": wall, "error": err}
    if res is None:
        return row
    q, x = res.quantities, res.extra
    row.update({"per_mm2": q["dispersed_per_mm2"].value, "clusters": int(q["dispersed_clusters"].value),
                "fragments": int(q["dispersed_fragments"].value), "mass_fraction": q["mass_fraction"].value,
                "monolayers": q["monolayers"].value, "fsv": q["fsv_plateau"].value,
                "ledger": q["ledger_residual"].value, "n_particles": x.get("n_particles"),
                "n_steps": x.get("n_steps"), "stepping_s": x.get("stepping_time_s"),
                "spectrum": " ".join(str(n) for n in x.get("spectrum", {}).get("N", [])),
                "layers": x.get("layers"), "series": x.get("series"), "surface_mm": x.get("surface_mm"),
                "per_plane_mm2": x.get("clusters_per_plane", 0) / (x.get("area_um2", float("inf")) * 1e-6)})
    return row


class DustingStudy(Study):
    """Numerical dusting of a shocked smooth free surface (module docstring)."""

    name = "dusting"
    summary = "dispersed clusters of a shocked smooth free surface against u, rc, damping and r0 (CD paper figs. 18-20)"
    params = PARAMS
    json_name = "dusting.json"

    def tag(self, run):
        return f"{run.v['length'] / units.mm:g}mm"

    def plan(self, run):
        """(kind, u, rc, J, seed, r0) of every run: the sweep, the profiles, the resolution."""
        v = run.v
        run.r0_um = r0_um = _k(v["r0"] / units.um)
        run.pu = pu = _k(v["profile_u"] / units.km_s)
        ru = _k(v["resolution_u"] / units.km_s)
        plan = []
        for rc in v["rcs"]:
            for J in v["Js"]:
                for u in v["us"]:
                    for seed in v["seeds"]:
                        plan.append(("sweep", _k(u), _k(rc), J, int(seed), r0_um))
        for J in v["Js"]:
            plan.append(("profile", pu, 1.1, J, int(v["seeds"][0]), r0_um))
        for r in v["r0s"] or ():
            for seed in v["resolution_seeds"]:
                plan.append(("resolution", ru, 1.1, None, int(seed), _k(r)))
        return plan

    def collect(self, run, plan):
        """Every distinct run once, cheapest first (in ``workers`` processes); the rows by run key."""
        v, cache = run.v, run.cache
        scene = get_scene("dusting")
        keys = []
        for p in plan:
            if p[1:] not in keys:
                keys.append(p[1:])
        # cheapest first (clusters ~ 1/r0^3, steps ~ (c0 + u)/r0; rc = 1.2 costs ~1.6x): partial results come early
        keys.sort(key=lambda k: (k[4] ** -4) * (5.35 + k[0]) * (1.6 if k[1] > 1.15 else 1.0))
        bar = run.bar(len(keys), "dusting study")
        results = {}
        if v["workers"] > 1:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed
            with ProcessPoolExecutor(v["workers"], mp_context=mp.get_context("spawn")) as ex:
                futs = [ex.submit(_worker, _overrides(v, *k), str(cache), v["reuse"]) for k in keys]
                for fu in as_completed(futs):
                    fu.result()
                    if bar is not None:
                        bar.update(1)
            for k in keys:
                results[k] = run_scene(scene, _overrides(v, *k), cache=cache, reuse=True)
        else:
            for k in keys:
                if bar is not None:
                    bar.set_postfix_str(f"u={k[0]:g} rc={k[1]:g} J={_jtxt(k[2])} seed={k[3]} r0={k[4]:g}")
                results[k] = run.run_scene(scene, _overrides(v, *k))
                if bar is not None:
                    bar.update(1)
        if bar is not None:
            bar.close()
        return plan, {k: _row(*results[k], *k) for k in keys}

    def report(self, run, collected):
        plan, rows = collected
        v, folder, r0_um, pu = run.v, run.folder, run.r0_um, run.pu
        sweep_rows = [rows[p[1:]] for p in plan if p[0] == "sweep"]
        summary = _summary(sweep_rows)
        prof = {_jtxt(J): rows[(pu, 1.1, J, int(v["seeds"][0]), r0_um)] for J in v["Js"]}
        res_rows = [rows[p[1:]] for p in plan if p[0] == "resolution"]
        headline = _headline(rows, v, pu, r0_um)
        text = [format_table(sweep_rows, RUN_COLUMNS, f"dusting runs: aluminium, {v['length'] / units.mm:g} mm, "
                             f"r0 = {r0_um:g} um, 2 x 2 periods, g_max = 10"),
                format_table(summary, SWEEP_COLUMNS, "dispersed clusters per mm^2 over the seeds"),
                format_table(res_rows, RES_COLUMNS, f"resolution: u = {v['resolution_u'] / units.km_s:g} km/s, "
                             "rc = 1.1, damping off"),
                _headline_text(headline)]
        plain = [{k: x for k, x in r.items() if k not in ("layers", "series")} for r in rows.values()]
        files = [write_csv(folder / "dusting_runs.csv", plain), write_csv(folder / "dusting_sweep.csv", summary),
                 write_csv(folder / "dusting_resolution.csv",
                           [{k: x for k, x in r.items() if k not in ("layers", "series")} for r in res_rows])]
        if v["plots"]:
            files.append(_plot_counts(folder / "dusting_count_vs_u.png", summary, sweep_rows, v))
            files += _plot_layers(folder / "dusting_layers.png", prof, v)
            files += _plot_series(folder / "dusting_time.png", rows, v, r0_um)
            if res_rows:
                files.append(_plot_resolution(folder / "dusting_resolution.png", res_rows))
        result = {"study": "dusting", "length_mm": v["length"] / units.mm, "r0_um": r0_um, "runs": plain,
                  "sweep": summary, "resolution": [{k: x for k, x in r.items() if k not in ("layers", "series")}
                                                  for r in res_rows],
                  "headline": headline, "markdown": {"sweep": markdown_table(summary, SWEEP_COLUMNS),
                                                     "resolution": markdown_table(res_rows, RES_COLUMNS),
                                                     "runs": markdown_table(sweep_rows, RUN_COLUMNS)}}
        return Report(result, text, files)


dusting_study = register_study(DustingStudy())


def _summary(rows):
    groups = {}
    for r in rows:
        groups.setdefault((r["u"], r["rc"], r["J"]), []).append(r)
    out = []
    for (u, rc, J), rr in groups.items():
        ok = [r for r in rr if r.get("per_mm2") is not None]
        if not ok:
            out.append({"u": u, "rc": rc, "J": J, "n": 0})
            continue
        c = np.array([r["per_mm2"] for r in ok])
        out.append({"u": u, "rc": rc, "J": J, "n": len(ok), "per_mm2_mean": float(c.mean()),
                    "per_mm2_spread": float(c.std(ddof=1)) if len(c) > 1 else 0.0,
                    "per_mm2_min": float(c.min()), "per_mm2_max": float(c.max()),
                    "clusters_max": float(max(r["clusters"] for r in ok)),
                    "mass_fraction_mean": float(np.mean([r["mass_fraction"] for r in ok])),
                    "fsv_mean": float(np.mean([r["fsv"] for r in ok]))})
    return out


def _headline(rows, v, u, r0_um):
    """u = profile_u, rc = 1.1: undamped counts over the seeds; J = 50 at most one monolayer per seed and its
    free-surface plateau against the undamped run of the same seed."""
    out = {"u": u, "rc": 1.1, "seeds": []}
    for seed in v["seeds"]:
        off = rows.get((u, 1.1, None, int(seed), r0_um))
        on = rows.get((u, 1.1, 50.0, int(seed), r0_um))
        if off is None or on is None or off.get("per_mm2") is None or on.get("per_mm2") is None:
            continue
        out["seeds"].append({"seed": int(seed), "off_per_mm2": off["per_mm2"], "off_clusters": off["clusters"],
                             "off_mass_fraction": off["mass_fraction"], "J50_clusters": on["clusters"],
                             "J50_per_mm2": on["per_mm2"], "J50_fsv": on["fsv"], "off_fsv": off["fsv"],
                             "fsv_change": on["fsv"] / off["fsv"] - 1.0, "fsv_vs_2u": on["fsv"] / (2 * u) - 1.0})
    return out


def _headline_text(h):
    lines = [f"u = {h['u']:g} km/s, rc = 1.1: damping off against J = 50, per seed"]
    for s in h["seeds"]:
        lines.append(f"  seed {s['seed']}: off {s['off_clusters']} clusters ({s['off_per_mm2']:.4g} /mm2, mass "
                     f"fraction {s['off_mass_fraction']:.2e}); J = 50 {s['J50_clusters']} clusters (one monolayer "
                     f"= 8); free-surface plateau {s['J50_fsv']:.4f} vs {s['off_fsv']:.4f} km/s undamped "
                     f"({100 * s['fsv_change']:+.2f}%), vs 2u {100 * s['fsv_vs_2u']:+.2f}%")
    return "\n".join(lines)


def _plot_counts(path, summary, rows, v):
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    rcs = sorted({r["rc"] for r in summary})
    fig, axs = plt.subplots(1, len(rcs), figsize=(6.5 * len(rcs), 4.5), squeeze=False)
    for ax, rc in zip(axs[0], rcs):
        for k, J in enumerate(sorted({r["J"] for r in summary}, key=lambda j: (j != "none", j))):
            ss = sorted([r for r in summary if r["rc"] == rc and r["J"] == J and r.get("n")], key=lambda r: r["u"])
            if not ss:
                continue
            lab = "no damping" if J == "none" else f"J = {J}"
            ax.errorbar([r["u"] for r in ss], [r["per_mm2_mean"] for r in ss],
                        yerr=[r["per_mm2_spread"] for r in ss], fmt="-o", color=f"C{k}", capsize=3,
                        label=f"{lab}: mean +- std over seeds")
            pts = [r for r in rows if r["rc"] == rc and r["J"] == J and r.get("per_mm2") is not None]
            ax.plot([r["u"] for r in pts], [r["per_mm2"] for r in pts], ".", color=f"C{k}", alpha=0.5, ms=5)
        mono = [r["per_plane_mm2"] for r in rows if r.get("per_plane_mm2")]
        if mono:
            ax.axhline(mono[0], color="gray", ls=":", lw=0.8, label="one monolayer (one (200) plane)")
        ax.set_xlabel("particle velocity u (km/s)")
        ax.set_ylabel("dispersed clusters per mm^2")
        ax.set_title(f"rc = {rc:g} (CD paper fig. {18 if rc < 1.15 else 19})")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def _plot_layers(path, prof, v):
    """Clusters per layer at the end without and with damping (the CD paper's fig. 20): the whole
    sample, and the rear surface with the dispersed clusters beyond it."""
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 2, figsize=(13, 4.2))
    rows = []
    for k, (J, r) in enumerate(prof.items()):
        L = r.get("layers")
        if not L:
            continue
        x, n = np.asarray(L["x_mm"]), np.asarray(L["n"])
        lab = ("no damping" if J == "none" else f"J = {J}") + f": {r.get('clusters')} dispersed"
        for ax in axs:
            ax.step(x, n, where="mid", lw=0.9, color=f"C{k}", label=lab)
            if r.get("surface_mm") is not None:
                ax.axvline(r["surface_mm"], color=f"C{k}", lw=0.6, ls="--")
        rows += [{"J": J, "x_mm": a, "clusters": int(b)} for a, b in zip(x, n)]
    surf = [r["surface_mm"] for r in prof.values() if r.get("surface_mm") is not None]
    xmax = max((max(r["layers"]["x_mm"]) for r in prof.values() if r.get("layers")), default=None)
    if surf and xmax is not None:
        axs[1].set_xlim(min(surf) - 0.25, max(xmax, max(surf)) + 0.05)
    r0 = next((r for r in prof.values() if r.get("layers")), None)
    thick = r0["layers"]["thickness_r0"] if r0 else 0
    for ax, title in zip(axs, ("whole sample", "rear surface (dashed: main body's surface)")):
        ax.set_xlabel("x (mm)")
        ax.set_ylabel(f"clusters per layer ({thick:g} r0 thick)")
        ax.set_title(f"u = {v['profile_u'] / units.km_s:g} km/s, rc = 1.1, end of run: {title}", fontsize=9)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return [path, write_csv(Path(path).with_suffix(".csv"), rows)]


def _plot_series(path, rows, v, r0_um):
    """Dispersed clusters per mm^2, mass fraction and free-surface velocity against time at u =
    profile_u, rc = 1.1, every seed, without and with damping (CSV beside)."""
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    u = _k(v["profile_u"] / units.km_s)
    fig, axs = plt.subplots(1, 2, figsize=(13, 4.2))
    out = []
    for (key, r) in rows.items():
        if key[0] != u or key[1] != 1.1 or key[4] != r0_um or not r.get("series"):
            continue
        s = r["series"]
        c = "C0" if r["J"] == "none" else "C1"
        lab = ("no damping" if r["J"] == "none" else f"J = {r['J']}") + f", seed {r['seed']}"
        ls = ("-", "--", ":", "-.")[int(r["seed"]) % 4]
        axs[0].plot(s["t_us"], s["per_mm2"], ls, color=c, lw=1, label=lab)
        axs[1].plot(s["t_us"], s["fsv_km_s"], ls, color=c, lw=1, label=lab)
        out += [{"J": r["J"], "seed": r["seed"], "t_us": t, "per_mm2": n, "mass_fraction": m, "fsv_km_s": f}
                for t, n, m, f in zip(s["t_us"], s["per_mm2"], s["mass_fraction"], s["fsv_km_s"])]
    axs[0].set_xlabel("t (us)")
    axs[0].set_ylabel("dispersed clusters per mm^2 (mass fraction in the CSV)")
    axs[0].set_title(f"u = {u:g} km/s, rc = 1.1: dispersed clusters against time", fontsize=9)
    axs[1].set_xlabel("t (us)")
    axs[1].set_ylabel("free-surface velocity (km/s)")
    axs[1].set_title("rear free surface (clusters that started within 3 r0 of it)", fontsize=9)
    for ax in axs:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return [path, write_csv(Path(path).with_suffix(".csv"), out)]


def _plot_resolution(path, rows):
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    ok = [r for r in rows if r.get("per_mm2") is not None]
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    axs[0].plot([r["r0"] for r in ok], [r["per_mm2"] for r in ok], "o-")
    axs[0].set_xscale("log")
    axs[0].set_xlabel("r0 (um)")
    axs[0].set_ylabel("dispersed clusters per mm^2")
    axs[0].set_title("dusting against the cluster size (u = 2 km/s, rc = 1.1, no damping)")
    for r in ok:
        g = [int(x) for x in r["spectrum"].split()] if r.get("spectrum") else []
        axs[1].plot(range(1, len(g) + 1), g, "o-", label=f"r0 = {r['r0']:g} um, wall {r['wall_s']:.0f} s")
    axs[1].set_xlabel("clusters per dispersed fragment g")
    axs[1].set_ylabel("number of dispersed fragments N(g)")
    axs[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
