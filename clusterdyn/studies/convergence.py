"""``clusterdyn study convergence --set scene=shock``: error of a shock run against its cost.

Sweeps what sets the cost and the error of a run, one thing at a time around
a base run (default Al, [100], u = 3 km/s, sample 120x6x6 -- the shock scene's
``size=auto`` at 3 km/s --, dt factor 0.03, rc = 1.15, noise 10 m/s, r0 = 5 um;
the fit window starts where the scene's starts, ``fit_from=auto``):

* ``ladder``: sample sizes from tiny to the finest (the resolution ladder);
* ``cross``: cross-section n x n repeat cells (4 ... 16) at length ``cross_length``;
* ``lengths``: sample length (how long a steady front is fitted) at ``length_cross``;
* ``dt_factors``: time step as a fraction of r0/(c0 + u);
* ``rcs``: cutoff (a model change, not a resolution: reported beside);
* ``noises``: initial noise amplitude (m/s);
* ``r0s``: cluster size at fixed geometry in cells.  CD is scale-free at fixed
  geometry in cells: forces scale as r0^2, masses as r0^3, the time step as
  r0, so the trajectory in units of r0 is the same and D does not depend on r0.

Every run reports D, its error against the experimental Hugoniot and against
the finest run (largest sample at the smallest time step, default physics),
the wall time and particle-steps.  Files in ``--out`` (default
``runs/convergence-<material>``): ``convergence.csv``, ``convergence.png``
(error against wall time, Pareto front marked) and ``convergence.json``.
"""

import numpy as np

from .. import units
from ..errors import InputError
from ..scenes import get_scene
from ..scenes.base import Param
from .base import Report, Study, register_study
from .common import ListParam, format_table, markdown_table, pareto_front, shock_row, write_csv


class SizeListParam(Param):
    """Comma-separated sample sizes ``"20x4x4,40x8x8"`` -> tuple of (nx, ny, nz)."""

    def __init__(self, name, default, doc, optional=True):
        super().__init__(name, default, doc, kind="sizes", optional=optional)

    def describe(self):
        d = "none" if self.default is None else ",".join("x".join(map(str, s)) for s in self.default)
        return f"{self.name} = {d}  -- {self.doc}"

    def parse(self, value):
        if value is None or (isinstance(value, str) and value.strip().lower() in ("none", "off", "")):
            if self.optional:
                return None
            raise InputError(self.name, value, "sample sizes like 20x4x4,40x8x8")
        items = value.split(",") if isinstance(value, str) else list(value)
        single = Param(self.name, (1, 1, 1), self.doc, kind="ints")
        return tuple(single.parse(it) for it in items)


PARAMS = [
    Param("scene", "shock", "scene whose cost and error are swept", kind="choice", choices=("shock",)),
    Param("base", (120, 6, 6), "sample of the base run (repeat cells; the shock scene's size=auto at 3 km/s)",
          kind="ints"),
    SizeListParam("ladder", ((40, 4, 4), (80, 6, 6), (120, 6, 6), (180, 6, 6), (240, 8, 8)),
                  "resolution ladder: sample sizes, each at the base time step"),
    Param("finest", (240, 8, 8), "sample of the finest run", kind="ints"),
    Param("finest_dt", 0.015, "time-step factor of the finest run", low=0.0, high=0.5, low_open=True),
    ListParam("cross", (4, 6, 8, 12), "cross-sections n x n (repeat cells)", low=1, optional=True),
    Param("cross_length", 120, "length of the cross-section sweep (repeat cells)", kind="int", low=4),
    ListParam("lengths", (60, 120, 180, 240), "sample lengths (repeat cells)", low=4, optional=True),
    Param("length_cross", 6, "cross-section of the length sweep (repeat cells)", kind="int", low=1),
    ListParam("dt_factors", (0.015, 0.03, 0.06, 0.12), "time-step factors (of r0/(c0 + u))", low=0.0,
              high=0.5, low_open=True, optional=True),
    ListParam("rcs", (1.1, 1.15, 1.2), "cutoffs (multiples of r0)", low=1.0, high=1.414, low_open=True,
              optional=True),
    ListParam("noises", (0.0, 10.0, 30.0), "initial noise amplitudes", unit="m/s", low=0.0, optional=True),
    ListParam("r0s", (1.0, 5.0, 25.0), "cluster sizes at fixed geometry in cells", unit="um", low=0.0,
              low_open=True, optional=True),
    Param("cache", None, "folder of the runs' results, shared between studies (default OUT/runs)",
          kind="str", optional=True),
    Param("reuse", True, "read back runs of the same parameters found in the cache (false after a change "
          "of the model code)", kind="bool"),
    Param("plots", True, "write the PNG figure", kind="bool"),
]

COLUMNS = [("sweep", "sweep", ""), ("value", "value", ""), ("size", "size", ""), ("dt_factor", "dt", ".4g"),
           ("rc", "rc", ".3g"), ("noise", "noise m/s", ".3g"), ("r0", "r0 um", ".3g"),
           ("D", "D km/s", ".4f"), ("D_err", "+-", ".3f"), ("err_ref", "err exp", "+.2%"),
           ("err_finest", "err finest", "+.2%"), ("steady", "steady", ""), ("wall_s", "wall s", ".2f"),
           ("particle_steps", "p-steps", ".3g"), ("pareto", "Pareto", "")]


def _key(s):
    """A run's identity: the settings that change it."""
    return (tuple(s["size"]), round(s["dt_factor"], 12), round(s["rc"], 12), round(s["noise"], 9),
            round(s["r0"], 9))


def _pareto(rows, defaults):
    """Pareto fronts (indices into ``rows``) of |error vs finest| and |error vs experiment| against wall
    time, over the runs of the default model (rc, noise): the numerical choices."""
    numerical = [i for i, r in enumerate(rows) if r["rc"] == defaults["rc"] and r["noise"] == defaults["noise"]
                 and r.get("D") is not None and r["sweep"] != "finest"]
    seen, uniq = set(), []
    for i in numerical:
        k = (rows[i]["size"], rows[i]["dt_factor"], rows[i]["r0"])
        if k not in seen:
            seen.add(k)
            uniq.append(i)
    front_f = [uniq[j] for j in pareto_front([rows[i]["wall_s"] for i in uniq],
                                              [rows[i]["err_finest"] for i in uniq])]
    front_e = [uniq[j] for j in pareto_front([rows[i]["wall_s"] for i in uniq],
                                              [rows[i]["err_ref"] for i in uniq])]
    for i, r in enumerate(rows):
        r["pareto"] = ("F" if i in front_f else "") + ("E" if i in front_e else "")
    return front_f, front_e


class ConvergenceStudy(Study):
    """Error of a shock run against its cost (module docstring)."""

    name = "convergence"
    summary = ("error of D against experiment and the finest run versus wall time, over size, time step, cutoff, "
               "noise and r0")
    params = PARAMS
    scene = "shock"
    json_name = "convergence.json"

    def prepare(self, run):
        v = run.v
        run.fwd = {k: x for k, x in run.fwd.items()}
        run.fwd.setdefault("h5md", "false")
        run.fwd.setdefault("checkpoint_every", "0")
        run.base = base = get_scene(v["scene"]).parse(run.fwd)
        run.defaults = {"size": v["base"], "dt_factor": base["dt_factor"], "rc": base["rc"],
                        "noise": base["noise"] / units.m_s, "r0": base["r0"] / units.um}
        run.mat, run.u = base["material"], base["u"] / units.km_s

    def tag(self, run):
        return f"{run.mat}-{run.u:g}kms"

    def plan(self, run):
        """(sweep, label, settings) of every run, the finest first."""
        v, plan = run.v, []

        def add(sweep, label, **kw):
            s = dict(run.defaults)
            s.update(kw)
            plan.append((sweep, label, s))

        add("finest", "x".join(map(str, v["finest"])), size=v["finest"], dt_factor=v["finest_dt"])
        for sz in v["ladder"] or ():
            add("ladder", "x".join(map(str, sz)), size=sz)
        for n in v["cross"] or ():
            add("cross-section", f"{int(n)}x{int(n)}", size=(v["cross_length"], int(n), int(n)))
        for L in v["lengths"] or ():
            add("length", f"{int(L)}", size=(int(L), v["length_cross"], v["length_cross"]))
        for f in v["dt_factors"] or ():
            add("time step", f"{f:g}", dt_factor=f)
        for rc in v["rcs"] or ():
            add("cutoff", f"{rc:g}", rc=rc)
        for nz in v["noises"] or ():
            add("noise", f"{nz:g} m/s", noise=nz)
        for r in v["r0s"] or ():
            add("r0", f"{r:g} um", r0=r)
        return plan

    def collect(self, run, plan):
        """Every distinct run once, cheapest first (partial results come early); the table rows."""
        scene = get_scene(run.v["scene"])
        todo = []
        for sweep, label, s in plan:
            if _key(s) not in {_key(x[2]) for x in todo}:
                todo.append((sweep, label, s))
        todo.sort(key=lambda x: np.prod(x[2]["size"]) / x[2]["dt_factor"])
        bar = run.bar(len(todo), f"convergence {run.mat} u={run.u:g}")
        done = {}
        for sweep, label, s in todo:
            ov = dict(run.fwd)
            ov.update({"size": "x".join(map(str, s["size"])), "dt_factor": s["dt_factor"], "rc": s["rc"],
                       "noise": s["noise"], "r0": s["r0"]})
            if bar is not None:
                bar.set_postfix_str(f"{sweep} {label}")
            done[_key(s)] = shock_row(*run.run_scene(scene, ov))
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        D_f = done[_key(plan[0][2])].get("D", float("nan"))
        rows = []
        for sweep, label, s in plan:
            r = dict(done[_key(s)])
            r.update({"sweep": sweep, "value": label, "size": "x".join(map(str, s["size"])),
                      "dt_factor": s["dt_factor"], "rc": s["rc"], "noise": s["noise"], "r0": s["r0"]})
            r["err_finest"] = (r["D"] / D_f - 1.0) if r.get("D") is not None and np.isfinite(D_f) else None
            rows.append(r)
        return plan[0][1], D_f, rows

    def report(self, run, collected):
        finest_label, D_f, rows = collected
        v, mat, u = run.v, run.mat, run.u
        front_f, front_e = _pareto(rows, run.defaults)
        text = [format_table(rows, COLUMNS,
                             f"convergence of D for {mat} [{run.base['direction']}] u = {u:g} km/s "
                             f"(finest: {finest_label} at dt factor {v['finest_dt']:g}, D = {D_f:.4f} km/s)")]
        text.append("Pareto: F = on the front of |error vs finest| against wall time, E = of |error vs experiment|, "
                    "over the runs of the default model (rc, noise)")
        r0rows = [r for r in rows if r["sweep"] == "r0" and r.get("D") is not None]
        if len(r0rows) > 1:
            Ds = np.array([r["D"] for r in r0rows])
            dtxt = ", ".join(f"{d:.6f}" for d in Ds)
            rtxt = ", ".join(f"{r['r0']:g}" for r in r0rows)
            text.append(f"r0 at fixed geometry in cells: D = {dtxt} km/s for r0 = {rtxt} um: spread "
                        f"{np.ptp(Ds) / Ds.mean():.2e} "
                        "(scale-free: same trajectory in units of r0)")
        lad = [r for r in rows if r["sweep"] in ("ladder", "finest") and r.get("wall_s")]
        if lad:
            w = [r["wall_s"] for r in lad]
            text.append(f"resolution ladder: {len(lad)} samples, wall time {min(w):.2g}-{max(w):.3g} s "
                        f"({max(w) / min(w):.0f}x)")
        files = [write_csv(run.folder / "convergence.csv", rows)]
        if v["plots"]:
            files.append(_plot(run.folder / "convergence.png", rows, front_f, front_e, mat, u))
        result = {"study": "convergence", "scene": v["scene"], "material": mat, "u_km_s": u,
                  "finest": {"size": finest_label, "dt_factor": v["finest_dt"], "D": D_f},
                  "runs": rows, "pareto_finest": front_f, "pareto_experiment": front_e,
                  "markdown": markdown_table(rows, COLUMNS)}
        return Report(result, text, files)


convergence_study = register_study(ConvergenceStudy())


def _plot(path, rows, front_f, front_e, mat, u):
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 2, figsize=(13, 5))
    sweeps = []
    for r in rows:
        if r["sweep"] not in sweeps:
            sweeps.append(r["sweep"])
    marks = dict(zip(sweeps, "*osD^v<>ph"))
    for ax, key, front, lab in ((axs[0], "err_finest", front_f, "|D / D_finest - 1|"),
                                (axs[1], "err_ref", front_e, "|D / D_exp - 1|")):
        for k, sw in enumerate(sweeps):
            rr = [r for r in rows if r["sweep"] == sw and r.get(key) is not None and np.isfinite(r[key])]
            if sw == "finest" and key == "err_finest":
                for r in rr:
                    ax.axvline(r["wall_s"], color=f"C{k}", ls="--", lw=1, label=f"finest ({r['value']})")
                continue
            if not rr:
                continue
            ax.scatter([r["wall_s"] for r in rr], [max(abs(r[key]), 1e-6) for r in rr], marker=marks[sw],
                       s=40 if sw != "finest" else 120, label=sw, color=f"C{k}", alpha=0.8)
            for r in rr:
                ax.annotate(r["value"], (r["wall_s"], max(abs(r[key]), 1e-6)), fontsize=6,
                            xytext=(3, 2), textcoords="offset points")
        pts = sorted((rows[i]["wall_s"], max(abs(rows[i][key]), 1e-6)) for i in front)
        if pts:
            ax.step([p[0] for p in pts], [p[1] for p in pts], where="post", color="k", lw=1.2,
                    label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel(lab)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axs[0].set_title(f"{mat}, u = {u:g} km/s: error against the finest run")
    axs[1].set_title("error against the experimental Hugoniot (model + numerical error)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
