"""``clusterdyn study stability``: the measured time-step limit of CD runs, u = 0 ... 8 km/s.

For every piston speed u a small [100] piston sample (at u = 0: a periodic
block with thermal noise) is run, undamped, over the same physical time at
growing time steps, and the energy balance is tracked step by step:

.. math::

    \\epsilon(t) = \\frac{|E_{kin} + E_{pot} - E(0) - W_{piston}(t)|}{E_{scale}},
    \\qquad W_{piston} = -\\int F_{sample \\to piston} \\cdot u \\, dt

(trapezoidal rule; ``E_scale`` is the work done by the piston at the end, or
the initial kinetic energy at u = 0).  A time step is *bounded* when the run
ends without :class:`~clusterdyn.errors.InstabilityError` and
``max_t epsilon < energy_tol`` (default 20%: past the limit the error grows
exponentially, so the value matters little; at u = 0, where the error of a
stable step is an oscillating offset, bounded means not growing: the second
half of the run within twice the first, and below the kinetic energy); the
largest step with ``epsilon < accuracy_tol`` (1%) is listed beside it.  The limit is found by
stepping the time step up by sqrt(2) from the default until it fails (down
by 2 if the default fails), then bisecting.  The table lists, in units of
r0/c0: the default time step, the measured limit, their ratio (the margin), the
energy error at the default step, the closest approach seen (r/r0), the
limit the dynamics' own stiffness check predicts at that approach
(:func:`clusterdyn.md.stability_limit`), and what stopped the first failing
run.

While the limit is measured the dynamics' stiffness check is switched off
(``check_interval`` beyond the run) so the measurement is the integrator's,
not the check's; the guard against a particle moving more than 0.25 r0 in a
step stays on and is reported when it is what stops a run.  The default step
is the shock scene's (:func:`clusterdyn.scenes.shock.shock_timestep`:
``0.03 r0/(c0 + u)``, smaller for stiff cold curves).
"""

import math

import numpy as np

from .. import units
from ..build import fcc_packing
from ..calculators import ClusterDynamics
from ..analysis.energy_balance import EnergyBalance
from ..errors import InputError, InstabilityError
from ..md import DampedVerlet, stability_limit
from ..md.damped import TIMESTEP_FACTOR
from ..scenes.base import Param
from ..scenes.common import thermal_noise
from ..scenes.shock import CD_MATERIALS, build_shock, shock_timestep
from .base import Report, Study, register_study
from .common import ListParam, format_table, markdown_table, write_csv

PARAMS = [
    Param("material", "Al", "material", kind="choice", choices=CD_MATERIALS),
    ListParam("u", (0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0), "piston speeds", unit="km/s", low=0.0, high=20.0),
    Param("size", (30, 3, 3), "piston sample (repeat cells)", kind="ints"),
    Param("rest_size", (4, 4, 4), "periodic block of the u = 0 runs (repeat cells)", kind="ints"),
    Param("rest_noise", 100.0, "thermal noise of the u = 0 runs", unit="m/s", low=0.0, low_open=True),
    Param("rest_time", 20.0, "duration of the u = 0 runs, in r0/c0", low=0.0, low_open=True),
    Param("noise", 10.0, "initial noise of the piston runs", unit="m/s", low=0.0),
    Param("rc", 1.15, "cutoff (multiple of r0)", low=1.0, high=1.414, low_open=True),
    Param("attraction", "all", "pair attraction", kind="choice", choices=("all", "initial")),
    Param("energy_tol", 0.2, "largest energy error of a bounded run (of the piston's work, or of the "
          "kinetic energy at u = 0)", low=0.0, low_open=True),
    Param("accuracy_tol", 0.01, "energy error of the 'accurate' column", low=0.0, low_open=True),
    Param("bisections", 4, "bisection steps after the first failure", kind="int", low=0),
    Param("seed", 1, "random seed", kind="int", low=0),
    Param("plots", True, "write the PNG figure", kind="bool"),
]

COLUMNS = [("u", "u km/s", ".3g"), ("dt_default", "dt default", ".4f"), ("dt_limit", "dt limit", ".4f"),
           ("margin", "limit/default", ".2f"), ("dt_accurate", "dt err<1%", ".4f"),
           ("err_default", "E err default", ".2e"), ("default_ok", "default ok", ""),
           ("min_r", "min r/r0", ".3f"), ("dt_check", "check predicts", ".4f"),
           ("dt_rest", "2/w_max rest", ".4f"), ("stopped_by", "first failure", ""), ("n_runs", "runs", "d")]


def _run(material, u, dt, v, rest_duration=None):
    """One run at time step ``dt`` (ASE); returns dict(ok, err, min_r, stopped_by, steps)."""
    if u > 0:
        s = build_shock(material, u, "100", v["size"], 5 * units.um, v["rc"], None, v["noise"], v["seed"],
                        TIMESTEP_FACTOR, attraction=v["attraction"])
        atoms, dyn, calc = s.atoms, s.dyn, s.calc
        pistons = [s.piston]
        t_end = s.nsteps * s.dyn.dt
    else:
        atoms = fcc_packing(material, 5 * units.um, size=v["rest_size"], pbc=True)
        calc = ClusterDynamics(rc=v["rc"])
        if v["attraction"] == "initial":
            from ..calculators import mark_initial_bonds
            mark_initial_bonds(atoms, v["rc"])
            calc = ClusterDynamics(rc=v["rc"], attraction="initial")
        atoms.calc = calc
        calc.setup(atoms)
        thermal_noise(atoms, v["rest_noise"], v["seed"])
        dyn = DampedVerlet(atoms, timestep=0.01 * calc.potentials[0].r0 / calc.potentials[0].c0, J=None)
        pistons = []
        t_end = rest_duration
    # measure the integrator, not the stiffness check
    dyn.stability_limit = None
    dyn.dt = dt
    nsteps = max(10, int(math.ceil(t_end / dt)))
    bal = EnergyBalance(dyn, atoms, pistons)
    dyn.attach(bal, interval=1)
    stopped = None
    try:
        with np.errstate(all="ignore"):
            dyn.run(nsteps)
    except InstabilityError as exc:
        stopped = f"InstabilityError: {exc.quantity}"
    errs = np.abs(np.array(bal.errors))
    if u > 0:
        scale = max(abs(bal.W), 1e-300)
    else:
        ke0 = 0.5 * v["rest_noise"] ** 2 * atoms.get_masses().sum()
        scale = ke0
    err = float(np.nanmax(errs) / scale) if len(errs) else math.inf
    if not math.isfinite(err):
        err = math.inf
        stopped = stopped or "non-finite energy"
    if u > 0:
        ok = stopped is None and err < v["energy_tol"]
        if stopped is None and not ok:
            stopped = f"energy error {err:.2g} > {v['energy_tol']:g}"
    else:
        # a lattice at rest: velocity Verlet's energy error is an offset that oscillates; bounded
        # while it does not grow (second half of the run within twice the first) and stays below KE
        h = len(errs) // 2
        growing = len(errs) > 4 and np.nanmax(errs[h:]) > 2.0 * np.nanmax(errs[:h]) + 1e-12 * scale
        ok = stopped is None and not growing and err < 1.0
        if stopped is None and not ok:
            stopped = "energy error growing" if growing else f"energy error {err:.2g} of the kinetic energy"
    return {"ok": ok, "err": err, "min_r": bal.min_r, "stopped_by": stopped, "steps": len(errs) - 1,
            "calc": calc}


def find_limit(material, u, v, log=None):
    """Largest bounded time step at piston speed ``u`` (ASE units); returns a summary dict.

    From the default step, scan up by sqrt(2) until a run fails (or down by
    2 until one passes), then bisect geometrically ``bisections`` times.
    """
    probe = fcc_packing(material, 5 * units.um, size=(2, 2, 2))
    calc0 = ClusterDynamics(rc=v["rc"])
    calc0.setup(probe)
    pot = calc0.potentials[0]
    r0c0 = pot.r0 / pot.c0
    dt0 = shock_timestep(calc0, u)
    rest_duration = v["rest_time"] * r0c0
    runs = []

    def run(dt):
        r = _run(material, u, dt, v, rest_duration)
        runs.append((dt, r))
        if log:
            log(u, dt / r0c0, r)
        return r

    first = run(dt0)
    good = bad = None
    if first["ok"]:
        good = (dt0, first)
        dt = dt0
        while dt < 5 * r0c0:
            dt *= math.sqrt(2.0)
            r = run(dt)
            if r["ok"]:
                good = (dt, r)
            else:
                bad = (dt, r)
                break
    else:
        bad = (dt0, first)
        dt = dt0
        while dt > dt0 / 64:
            dt /= 2.0
            r = run(dt)
            if r["ok"]:
                good = (dt, r)
                break
            bad = (dt, r)
    first_fail = bad[1]["stopped_by"] if bad is not None else None
    for _ in range(v["bisections"]):
        if bad is None or good is None:
            break
        mid = math.sqrt(good[0] * bad[0])
        r = run(mid)
        if r["ok"]:
            good = (mid, r)
        else:
            bad = (mid, r)
    accurate = [d for d, r in runs if r["ok"] and r["err"] < v["accuracy_tol"]]
    ref = good[1] if good is not None else first
    calc = ref["calc"]
    min_r = ref["min_r"]
    dt_check = stability_limit(calc, min(min_r, 1.0)) if math.isfinite(min_r) else stability_limit(calc)
    return {"u": u / units.km_s, "dt_default": dt0 / r0c0,
            "dt_limit": (good[0] / r0c0) if good else float("nan"),
            "margin": (good[0] / dt0) if good else float("nan"),
            "dt_accurate": (max(accurate) / r0c0) if accurate else float("nan"),
            "err_default": first["err"], "default_ok": first["ok"],
            "min_r": min_r, "dt_check": dt_check / r0c0, "dt_rest": stability_limit(calc) / r0c0,
            "stopped_by": first_fail, "n_runs": len(runs),
            "scan": [{"dt_r0_c0": d / r0c0, "ok": r["ok"], "energy_error": r["err"], "min_r": r["min_r"],
                      "stopped_by": r["stopped_by"], "steps": r["steps"]} for d, r in runs]}


def _check_sizes(v):
    """The piston sample and the periodic block big enough for their boundaries (before any run)."""
    from ..scenes.shock import MIN_CELLS
    rep = math.sqrt(2.0)                # [100] repeat cell, in r0
    need = int(math.ceil(2.0 * v["rc"] / rep))
    nx, ny, nz = v["size"]
    if nx < MIN_CELLS or min(ny, nz) < need:
        raise InputError("size", "x".join(map(str, v["size"])), f"at least {MIN_CELLS} cells along the shock and "
                         f"{need} across (a periodic cross-section 2 rc r0 wide), e.g. {max(nx, MIN_CELLS)}x"
                         f"{max(ny, need)}x{max(nz, need)}")
    if min(v["rest_size"]) < need:
        raise InputError("rest_size", "x".join(map(str, v["rest_size"])), f"at least {need} cells each way (a "
                         "periodic block 2 rc r0 wide)")


class StabilityStudy(Study):
    """The measured time-step limit against u (module docstring)."""

    name = "stability"
    summary = "the measured time-step limit (bounded energy error) against u"
    params = PARAMS
    json_name = "stability.json"

    def tag(self, run):
        return run.v["material"]

    def prepare(self, run):
        _check_sizes(run.v)

    def plan(self, run):
        return list(run.v["u"])

    def collect(self, run, plan):
        mat = run.v["material"]
        bar = run.bar(len(plan), f"stability {mat}")
        rows = []
        for u in plan:
            if bar is not None:
                bar.set_postfix_str(f"u={u:g} km/s")
            rows.append(find_limit(mat, u * units.km_s, run.v))
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        return rows

    def report(self, run, rows):
        v, mat = run.v, run.v["material"]
        lim = [r["dt_limit"] for r in rows if np.isfinite(r["dt_limit"])]
        text = [format_table(rows, COLUMNS, f"time-step limit of {mat} (rc = {v['rc']:g}, attraction = "
                                            f"{v['attraction']}); time steps in r0/c0; bounded = no instability "
                                            f"and energy error < {v['energy_tol']:g}")]
        for r in rows:
            if not np.isfinite(r["dt_limit"]):
                kinds = {x["stopped_by"] for x in r["scan"]}
                text.append(f"u = {r['u']:g} km/s: no bounded time step down to 1/64 of the default; every run "
                            f"stopped ({'; '.join(sorted(k for k in kinds if k))}): compression beyond the "
                            "potential's range, not a time-step limit")
        if lim:
            text.append(f"smallest margin of the default time step below the measured limit: "
                        f"{min(r['margin'] for r in rows if np.isfinite(r['margin'])):.1f}x")
        files = [write_csv(run.folder / "stability.csv", [{k: x for k, x in r.items() if k != "scan"} for r in rows])]
        if v["plots"]:
            files.append(_plot(run.folder / "stability.png", rows, mat))
        result = {"study": "stability", "material": mat, "rows": rows, "markdown": markdown_table(rows, COLUMNS)}
        return Report(result, text, files)


stability_study = register_study(StabilityStudy())


def _plot(path, rows, mat):
    from ..scenes.common import matplotlib_agg
    plt = matplotlib_agg()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    u = [r["u"] for r in rows]
    ax.plot(u, [r["dt_limit"] for r in rows], "o-", label="measured limit (bounded energy)")
    ax.plot(u, [r["dt_check"] for r in rows], "s--", label="stiffness check at the closest approach")
    ax.plot(u, [r["dt_default"] for r in rows], "k-", label="default (shock scene)")
    ax.axhline(rows[0]["dt_rest"], color="0.5", ls=":", label="2/omega_max at rest")
    ax.set_yscale("log")
    ax.set_xlabel("piston speed u (km/s)")
    ax.set_ylabel("time step (r0/c0)")
    ax.set_title(f"velocity-Verlet stability, {mat} [100]")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
