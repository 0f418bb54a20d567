"""``clusterdyn study hugoniot``: the CD Hugoniot of a material (or a two-phase sample).

Sweeps the piston speed of the ``shock`` scene (default 0.5, 1, 1.5, 2, 3, 4,
6 km/s) and writes, in ``--out`` (default ``runs/hugoniot-<material>``):

* ``hugoniot.csv`` -- every run (group, u, D from the front fit with its
  error, the experimental D and the relative error, ``D_cold`` where the
  cold curve meets the Rayleigh line of the piston speed (the model's own
  zero-temperature Hugoniot: what a CD lattice can at best reproduce), D from mass
  conservation, u behind the front, P = -sigma_xx against rho0 D u, rho, von
  Mises intensity, fit residual, steadiness, wall time, particle-steps);
* ``hugoniot_du.png`` and ``hugoniot_prho.png`` -- D-u and P-rho with the
  experimental Hugoniot (``data/hugoniot.csv``) and the cold curve beside the
  CD points (the cold curve in the D-u plane is its Rayleigh-line image
  ``D^2 = P_x(delta) / (rho0 (1 - 1/delta))``, ``u = D (1 - 1/delta)``);
* ``uniaxial.csv`` / ``uniaxial.png`` -- the static check behind the soft
  response near 2 km/s: the longitudinal stress of the lattice under uniaxial
  compression along the shock direction, with all pairs attracting and with
  attraction only between pairs bonded at set-up;
* ``hugoniot.json`` -- every run and every summary table.

Options: ``compare_J=50`` reruns the sweep damped and reports the shift of D
per u; ``compare_attraction=true`` reruns it with ``attraction=initial``;
``low_u=0.05,0.1,0.15,0.2`` adds weak-shock runs extrapolated to u = 0 and
compared with the lattice's longitudinal sound speed; ``case=hBN-B4C`` or
``case=B4C-hBN`` (or ``inclusion=...``) runs a two-phase sample, the two pure
phases over the same speeds, and compares the sample with the mixture rule
(both closures).  Any parameter of the ``shock`` scene (direction, size, r0,
rc, J, noise, seed, dt_factor, frames, attraction, ...) is passed to every run.
"""

import math

import numpy as np

from .. import units
from ..analysis.elastic import uniaxial_stress
from ..analysis.shock import (STEADY_D_HALVES, STEADY_FIT_RMS, STEADY_U_TOL, hugoniot_interpolant,
                              mixture_D)
from ..build.lattice import LATTICE_CL
from ..build.two_phase import PAPER_CASES
from ..errors import InputError
from ..materials import get_material, hugoniot
from ..scenes import get_scene
from ..scenes.base import Param, display_text
from ..scenes.shock import CD_MATERIALS, U_MAX, ShockScene, cold_shock_state
from .base import Report, Study, register_study
from .common import ListParam, format_table, markdown_table, shock_row, write_csv

DEFAULT_U = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)


class SizeParam(Param):
    """An optional sample size ``NXxNYxNZ`` (repeat cells); ``none`` = not given."""

    def __init__(self, name, default, doc):
        super().__init__(name, default, doc, kind="ints", optional=True)

    def describe(self):
        d = "none" if self.default is None else "x".join(map(str, self.default))
        return f"{self.name} = {d}  -- {self.doc}"

    def parse(self, value):
        if value is None or (isinstance(value, str) and value.strip().lower() in ("none", "off", "")):
            return None
        return Param(self.name, (1, 1, 1), self.doc, kind="ints").parse(value)

LATTICE_MODULUS = {"100": "C11 = 3/2", "110": "15/8", "111": "2"}

PARAMS = [
    Param("material", "Al", "material (the matrix of a two-phase sample)", kind="choice",
          choices=CD_MATERIALS),
    Param("case", None, "a two-phase sample of the CD paper (sets material, inclusion, inclusion_fraction, "
          "inclusion_diameter)", kind="choice", choices=tuple(PAPER_CASES), optional=True),
    ListParam("u", DEFAULT_U, "piston speeds of the sweep", unit="km/s", low=0.0, high=U_MAX, low_open=True),
    Param("compare_J", None, "also run the sweep with damping Gamma = c0/(J r0) and report the shift of D",
          low=0.0, low_open=True, optional=True),
    Param("compare_attraction", False, "also run the sweep with attraction=initial", kind="bool"),
    ListParam("low_u", None, "weak-shock piston speeds extrapolated to u = 0 (e.g. 0.05,0.1,0.15,0.2)",
              unit="km/s", low=0.0, high=1.0, low_open=True, optional=True),
    Param("low_u_size", (160, 4, 4), "sample of the weak-shock runs (repeat cells)", kind="ints"),
    Param("low_u_noise", 1.0, "initial noise of the weak-shock runs", unit="m/s", low=0.0),
    Param("low_u_frames", 100, "profiles recorded in a weak-shock run", kind="int", low=5),
    ListParam("phase_u", (8.0,), "extra piston speeds for the pure-phase Hugoniots of a two-phase sample "
              "(the equal-pressure closure needs them beyond the sweep)", unit="km/s", low=0.0, low_open=True,
              optional=True),
    SizeParam("phase_size", None, "sample of the pure-phase runs of a two-phase study (default: the sample's)"),
    Param("refine_length", 250, "a steady run of the sweep that misses a conservation check (mass 2%, momentum "
          "5%) is run again on a sample this many cells long (same cross-section) and the long run is "
          "reported; 0 = off", kind="int", low=0),
    Param("cache", None, "folder of the runs' results, shared between studies (default OUT/runs)",
          kind="str", optional=True),
    Param("reuse", True, "read back runs of the same parameters found in the cache (false after a change "
          "of the model code)", kind="bool"),
    Param("uniaxial", True, "static uniaxial-compression check of the longitudinal stress", kind="bool"),
    Param("plots", True, "write the PNG figures", kind="bool"),
]

MAIN_COLUMNS = [
    ("u_piston", "u_p km/s", ".3g"), ("D", "D km/s", ".4f"), ("D_err", "+-", ".3f"),
    ("D_ref", "D_exp", ".4f"), ("exp_range", "exp", ""), ("err_ref", "err", "+.2%"), ("D_cold", "D_cold", ".4f"), ("D_mass", "D_mass", ".4f"),
    ("mass_check", "mass", "+.2%"), ("u", "u km/s", ".4f"), ("u_dev", "u/u_p-1", "+.2%"),
    ("P", "P GPa", ".2f"), ("P_momentum", "rho0Du", ".2f"), ("momentum_check", "P/rho0Du-1", "+.2%"),
    ("rho", "rho g/cm3", ".4f"), ("sigma_u", "sig_u GPa", ".3g"), ("fit_rms_slabs", "rms slab", ".3f"),
    ("steady", "steady", ""), ("size", "size", ""), ("wall_s", "wall s", ".1f"), ("particle_steps", "p-steps", ".3g"),
]


def _fwd_with(fwd, **kw):
    d = dict(fwd)
    d.update({k: v for k, v in kw.items() if v is not None})
    d.setdefault("h5md", "false")
    d.setdefault("checkpoint_every", "0")
    return d


# --------------------------------------------------------------------------- static checks
def cold_curve_du(material, deltas):
    """The cold curve's image in the D-u plane (Rayleigh line from rest to P_x(delta)); km/s."""
    mat = get_material(material)
    d = np.asarray(deltas, float)
    P = np.array([mat.curve.pressure(x) for x in d])
    eps = 1.0 - 1.0 / d
    D = np.sqrt(P / (mat.rho0 * eps))
    return D * eps / units.km_s, D / units.km_s


def stress_du(sigma, deltas, rho0):
    """A stress-compression curve's Rayleigh-line image (u, D) in km/s."""
    d = np.asarray(deltas, float)
    eps = 1.0 - 1.0 / d
    with np.errstate(invalid="ignore"):
        D = np.sqrt(np.asarray(sigma) / (rho0 * eps))
    return D * eps / units.km_s, D / units.km_s


# --------------------------------------------------------------------------- the study
def _row_info(row, res, ov, pv, n, group):
    """Complete a run's table row: its place in the plan, its parameters, the cold-curve D and the
    experimental range (one phase) or the sample's fractions (two phases)."""
    row.update({"run": n, "group": group, "material": ov["material"], "u_piston": float(ov["u"]),
                "J": pv["J"], "attraction": pv["attraction"], "noise_m_s": pv["noise"]["value"],
                "size": "x".join(map(str, pv["size"])), "direction": pv["direction"]})
    if not (res is not None and "two_phase" in res.extra):
        d_c, _ = cold_shock_state(ov["material"], float(ov["u"]) * units.km_s)
        row["D_cold"] = float(ov["u"]) / (1.0 - 1.0 / d_c)
        try:
            row["exp_range"] = ("extrap." if float(ov["u"]) * units.km_s > hugoniot(ov["material"]).u_max
                                * (1 + 1e-9) else "meas.")
        except InputError:
            pass
    if res is not None and "two_phase" in res.extra:
        row["inclusion_mass_fraction"] = res.extra["two_phase"]["mass_fraction"]
        row["inclusion_volume_fraction"] = res.extra["two_phase"]["volume_fraction"]
        row["rho0"] = res.extra["rho0_g_cm3"]
    return row


def _damping_table(main, rows, J):
    damp = [r for r in rows if r["group"] == "damped"]
    tab = []
    for a, b in zip(main, damp):
        tab.append({"u": a["u_piston"], "D_off": a["D"], "D_on": b["D"], "shift": b["D"] / a["D"] - 1.0,
                    "err_off": a["err_ref"], "err_on": b["err_ref"], "steady_on": b["steady"]})
    cols = [("u", "u km/s", ".3g"), ("D_off", "D (J off)", ".4f"), ("D_on", f"D (J={J:g})", ".4f"),
            ("shift", "shift", "+.2%"), ("err_off", "err off", "+.2%"), ("err_on", "err on", "+.2%"),
            ("steady_on", "steady on", "")]
    return tab, cols, f"damping on (J = {J:g}) against off: shift of D"


def _attraction_table(main, rows):
    att = [r for r in rows if r["group"] == "attraction=initial"]
    tab = [{"u": a["u_piston"], "D_all": a["D"], "D_initial": b["D"], "D_ref": a["D_ref"],
            "err_all": a["err_ref"], "err_initial": b["err_ref"], "steady": b["steady"],
            "mass": b["mass_check"], "momentum": b["momentum_check"]} for a, b in zip(main, att)]
    cols = [("u", "u km/s", ".3g"), ("D_all", "D all", ".4f"), ("D_initial", "D initial", ".4f"),
            ("D_ref", "D_exp", ".4f"), ("err_all", "err all", "+.2%"), ("err_initial", "err initial", "+.2%"),
            ("mass", "mass (ini)", "+.2%"), ("momentum", "mom. (ini)", "+.2%"), ("steady", "steady", "")]
    return tab, cols, "attraction between all pairs in the cutoff against set-up bonds only"


class HugoniotStudy(Study):
    """The piston-speed sweep of the shock scene (module docstring)."""

    name = "hugoniot"
    summary = ("piston-speed sweep of the shock scene: D-u and P-rho against the experimental Hugoniot (also "
               "forwards the shock scene's parameters)")
    params = PARAMS
    scene = "shock"
    json_name = "hugoniot.json"

    def prepare(self, run):
        v, fwd = run.v, run.fwd
        if v["case"] is not None:
            m, inc, frac, dia = PAPER_CASES[v["case"]]
            v["material"] = m
            fwd.setdefault("inclusion", inc)
            fwd.setdefault("inclusion_fraction", frac)
            fwd.setdefault("inclusion_diameter", f"{dia / units.um:g}um")
            fwd.setdefault("r0", "4um")
        run.sv = sv = get_scene("shock").parse(_fwd_with(fwd, material=v["material"]))
        run.two = sv["inclusion"] is not None
        mat = v["material"]
        run.label = ((f"{mat}+{sv['inclusion']}" if run.two else mat)
                     + (f"-{sv['direction']}" if sv["direction"] != "100" else ""))

    def tag(self, run):
        return run.label

    def plan(self, run):
        """(group, overrides) of every run; sets ``run.phases`` (the pure phases of a two-phase sample)."""
        v, fwd, mat = run.v, run.fwd, run.v["material"]
        plan = [("main", _fwd_with(fwd, material=mat, u=u)) for u in v["u"]]
        if v["compare_J"] is not None:
            plan += [("damped", _fwd_with(fwd, material=mat, u=u, J=v["compare_J"])) for u in v["u"]]
        if v["compare_attraction"]:
            plan += [("attraction=initial", _fwd_with(fwd, material=mat, u=u, attraction="initial")) for u in v["u"]]
        if v["low_u"]:
            lsize = "x".join(map(str, v["low_u_size"]))
            for u in v["low_u"]:
                noise = f"{v['low_u_noise'] / units.m_s:g}m/s"
                plan.append(("low-u", _fwd_with(fwd, material=mat, u=u, size=lsize, noise=noise,
                                                 frames=v["low_u_frames"])))
            # the same weakest shock with the sweep's noise, to show what the noise does there
            plan.append(("low-u noise check", _fwd_with(fwd, material=mat, u=min(v["low_u"]), size=lsize,
                                                         frames=v["low_u_frames"])))
        run.phases = {}
        if run.two:
            pu = sorted(set(v["u"]) | set(v["phase_u"] or ()))
            pure = {k: x for k, x in fwd.items() if not k.startswith("inclusion")}
            if v["phase_size"] is not None:
                pure["size"] = "x".join(map(str, v["phase_size"]))
            run.phases = {"matrix": mat, "inclusion": run.sv["inclusion"]}
            for role, m in run.phases.items():
                for u in pu:
                    plan.append((f"pure {m}", _fwd_with(pure, material=m, u=u)))
        return plan

    @staticmethod
    def _run_row(run, ov):
        scene = get_scene("shock")
        res, err, wall = run.run_scene(scene, ov)
        pv = scene.display(scene.parse(display_text(scene, ov)))     # the sweep's numbers: display units
        # the sample that ran (size=auto resolved)
        pv["size"] = tuple(res.extra["size_used"]) if res is not None and "size_used" in res.extra else \
            tuple(ShockScene.size(scene.parse(display_text(scene, ov))))
        return res, shock_row(res, err, wall), pv

    def collect(self, run, plan):
        """The rows of every run; a steady run off a conservation check is run again on a longer sample."""
        rows = []
        bar = run.bar(len(plan), f"hugoniot {run.label}")
        for n, (group, ov) in enumerate(plan):
            if bar is not None:
                bar.set_postfix_str(f"{group} u={ov['u']}")
            res, row, pv = self._run_row(run, ov)
            long_size = _refine_size(row, group, pv["size"], run.v["refine_length"])
            if long_size is not None:
                if bar is not None:
                    bar.set_postfix_str(f"{group} u={ov['u']} on {long_size}")
                short = {f"{k}_short": row.get(k) for k in ("D", "D_mass", "mass_check", "momentum_check",
                                                             "steady", "wall_s")}
                short["size_short"] = "x".join(map(str, pv["size"]))
                ov = _fwd_with(ov, size=long_size)
                res, row, pv = self._run_row(run, ov)
                row.update(short)
            rows.append(_row_info(row, res, ov, pv, n, group))
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        return rows

    def report(self, run, rows):
        v, sv, two, mat = run.v, run.sv, run.two, run.v["material"]
        summary, text = {}, []
        main = [r for r in rows if r["group"] == "main"]
        title = (f"CD Hugoniot of {run.label} [{sv['direction']}], r0 = {sv['r0'] / units.um:g} um, rc = {sv['rc']:g}, "
                 f"size {sv['size'] if isinstance(sv['size'], str) else 'x'.join(map(str, sv['size']))}, "
                 f"J = {sv['J'] if sv['J'] else 'off'}, noise "
                 f"{sv['noise'] / units.m_s:g} m/s, attraction = {sv['attraction']}")
        text.append(format_table(main, MAIN_COLUMNS, title))
        text.append(_conservation_verdict(main))
        summary["main"] = _strip(main)
        for key, on, table in (("damping", v["compare_J"] is not None, lambda: _damping_table(main, rows, v["compare_J"])),
                               ("attraction", v["compare_attraction"], lambda: _attraction_table(main, rows))):
            if on:
                tab, cols, title = table()
                text.append(format_table(tab, cols, title))
                summary[key] = tab
                summary[f"{key}_md"] = markdown_table(tab, cols)
        if v["low_u"]:
            lu = _low_u(rows, mat, sv, two)
            text.append(lu.pop("text"))
            summary["low_u"] = lu
        if two:
            mix = _mixture(rows, main, run.phases, run.label)
            text.append(mix.pop("text"))
            summary["mixture"] = mix
        uni = _uniaxial(mat, sv, two) if v["uniaxial"] else None
        if uni is not None:
            text.append(uni.pop("text"))
            summary["uniaxial"] = {k: x for k, x in uni.items() if k != "arrays"}
        files = [write_csv(run.folder / "hugoniot.csv", _strip(rows))]
        if uni is not None:
            files.append(write_csv(run.folder / "uniaxial.csv", uni["rows"]))
        if v["plots"]:
            files += _plots(run.folder, rows, mat, sv, two, run.phases, summary, uni)
        result = {"study": "hugoniot", "material": run.label, "direction": sv["direction"],
                  "params": {k: (list(x) if isinstance(x, tuple) else x) for k, x in v.items()},
                  "scene_overrides": run.fwd, "runs": _strip(rows), "summary": summary,
                  "files": [str(f) for f in files]}
        return Report(result, text, files)


hugoniot_study = register_study(HugoniotStudy())


def _strip(rows):
    return [{k: x for k, x in r.items()} for r in rows]


#: tolerances of the conservation checks of a steady run: D_mass/D_fit - 1, P/(rho0 D u) - 1
MASS_TOL, MOMENTUM_TOL = 0.02, 0.05
#: groups of runs whose conservation misses are run again on a longer sample
REFINED_GROUPS = ("main", "damped", "attraction=initial")


def _off_checks(row):
    return bool(row.get("steady")) and not (abs(row["mass_check"]) <= MASS_TOL
                                            and abs(row["momentum_check"]) <= MOMENTUM_TOL)


def _refine_size(row, group, size, length):
    """``NXxNYxNZ`` of the longer sample a run is repeated on, or None (checks met, off, or long already)."""
    if length <= size[0] or group not in REFINED_GROUPS or not _off_checks(row):
        return None
    return f"{length}x{size[1]}x{size[2]}"


def _conservation_verdict(rows):
    st = [r for r in rows if r.get("steady")]
    ref = [r for r in rows if r.get("size_short")]
    text = "no steady run" if not st else ""
    if st:
        mass_ok = [abs(r["mass_check"]) <= MASS_TOL for r in st]
        mom_ok = [abs(r["momentum_check"]) <= MOMENTUM_TOL for r in st]
        uns = [f"{r['u_piston']:g}" for r in rows if not r.get("steady")]
        text = (f"steady runs: {len(st)} of {len(rows)}" + (f" (unsteady: u = {', '.join(uns)} km/s)" if uns else "")
                + f"; D_fit and D_mass within {MASS_TOL:.0%}: {sum(mass_ok)}/{len(st)}; -sigma_xx and rho0 D u "
                f"within {MOMENTUM_TOL:.0%}: {sum(mom_ok)}/{len(st)}"
                + f"\nsteady = front linear in time (rms residual <= {STEADY_FIT_RMS:g} slab, D over the two halves "
                f"of the fit within {STEADY_D_HALVES:.0%}) and u behind the front within {STEADY_U_TOL:.0%} of the "
                "piston")
    if ref:
        text += ("\nrun again on a longer sample (steady on the short one but off a conservation check): "
                 + "; ".join(f"u = {r['u_piston']:g} km/s, {r['size_short']} -> {r['size']} (mass "
                             f"{r['mass_check_short']:+.1%} -> {r['mass_check']:+.1%}, momentum "
                             f"{r['momentum_check_short']:+.1%} -> {r['momentum_check']:+.1%}, D "
                             f"{r['D_short']:.4f} -> {r['D']:.4f} km/s"
                             f"{'' if r.get('steady') else ', not steady'})" for r in ref))
    off = [r for r in st if _off_checks(r)]
    if off:
        text += ("\nsteady but off the conservation checks: "
                 + "; ".join(f"u = {r['u_piston']:g} km/s (mass {r['mass_check']:+.1%}, momentum "
                             f"{r['momentum_check']:+.1%})" for r in off)
                 + "\n  on a short sample the state behind the front may still be settling: check these runs on "
                 "a longer one (--set refine_length=..., or --set size=250x8x8; docs/hugoniot.md, open points)")
    return text


def _low_u(rows, mat, sv, two):
    lo = [r for r in rows if r["group"] == "low-u" and np.isfinite(r.get("D", np.nan))]
    chk = [r for r in rows if r["group"] == "low-u noise check"]
    out = {"rows": lo}
    lines = []
    cols = [("u_piston", "u_p km/s", ".3g"), ("D", "D km/s", ".4f"), ("D_err", "+-", ".4f"),
            ("u_dev", "u/u_p-1", "+.2%"), ("mass_check", "mass", "+.2%"), ("fit_rms_slabs", "rms slab", ".3f"),
            ("noise_m_s", "noise m/s", ".3g"), ("steady", "steady", ""), ("wall_s", "wall s", ".1f")]
    lines.append(format_table(lo + chk, cols, "weak shocks"))
    if len(lo) >= 2:
        u = np.array([r["u_piston"] for r in lo])
        D = np.array([r["D"] for r in lo])
        w = np.array([1.0 / max(r["D_err"] or 1e-3, 1e-4) ** 2 for r in lo])
        A = np.vstack([np.ones_like(u), u]).T
        cov = np.linalg.inv(A.T @ (w[:, None] * A))
        coef = cov @ (A.T @ (w * D))
        res = D - A @ coef
        dof = max(1, len(u) - 2)
        scale = max(1.0, float((w * res ** 2).sum() / dof))
        D0, s = float(coef[0]), float(coef[1])
        D0_err = float(math.sqrt(cov[0, 0] * scale))
        out.update({"D0": D0, "D0_err": D0_err, "slope": s})
        lines.append(f"D(u) = {D0:.4f} (+- {D0_err:.4f}) + {s:.3f} u km/s from u = {u.min():g}-{u.max():g} km/s")
        if not two:
            c0 = get_material(mat).c0 / units.km_s
            target = LATTICE_CL[sv["direction"]] * c0
            dev = D0 / target - 1.0
            out.update({"c0": c0, "lattice_cL": target, "deviation": dev})
            fac = {"100": "sqrt(3/2)", "110": "sqrt(15/8)", "111": "sqrt(2)"}[sv["direction"]]
            lines.append(f"extrapolated to u = 0: D0 = {D0:.4f} km/s against the lattice's longitudinal sound "
                         f"speed along [{sv['direction']}] {fac} c0 = {target:.4f} km/s (c0 = {c0:.4f} km/s): "
                         f"{dev:+.2%}")
            try:
                ref = hugoniot(mat)
                lines.append(f"the lattice is stiffer than the real metal at low u: D0 is {D0 / ref.c0_km_s - 1:+.1%} "
                             f"above the experimental Hugoniot's intercept ({ref.name}: {ref.c0_km_s:g} km/s) and "
                             f"{D0 / c0 - 1:+.1%} above the bulk sound speed c0 (a nearest-neighbour central-force "
                             f"lattice has rho c_L^2 = {LATTICE_MODULUS[sv['direction']]} K along "
                             f"[{sv['direction']}], docs/theory.md 1.5)")
            except InputError:
                lines.append(f"the lattice is stiffer than the material at low u: D0 is {D0 / c0 - 1:+.1%} above "
                             "the bulk sound speed c0")
    if chk and lo:
        base = [r for r in lo if r["u_piston"] == chk[0]["u_piston"]]
        if base and np.isfinite(chk[0].get("D", np.nan)):
            d = chk[0]["D"] / base[0]["D"] - 1.0
            out["noise_effect"] = d
            lines.append(f"noise at u = {chk[0]['u_piston']:g} km/s: {chk[0]['noise_m_s']:g} m/s instead of "
                         f"{base[0]['noise_m_s']:g} m/s changes D by {d:+.2%} and u behind the front by "
                         f"{(chk[0]['u'] - base[0]['u']) / base[0]['u_piston']:+.2%} of u_p")
    out["text"] = "\n".join(lines)
    return out


def _mixture(rows, main, phases, tag):
    lines = []
    curves = {}
    pts = {}
    for role, m in phases.items():
        pr = [r for r in rows if r["group"] == f"pure {m}" and np.isfinite(r.get("D", np.nan))]
        pts[role] = pr
        curves[role] = hugoniot_interpolant([r["u"] for r in pr], [r["D"] for r in pr])
    tab = []
    for r in main:
        if not np.isfinite(r.get("D", np.nan)):
            continue
        w_inc = r.get("inclusion_mass_fraction")
        ph = [(1.0 - w_inc, get_material(phases["matrix"]).rho0 / units.g_cm3, curves["matrix"]),
              (w_inc, get_material(phases["inclusion"]).rho0 / units.g_cm3, curves["inclusion"])]
        Du = mixture_D(r["u"], ph, "equal_u")
        Dp = mixture_D(r["u"], ph, "equal_p")
        tab.append({"u_piston": r["u_piston"], "u": r["u"], "D": r["D"], "D_err": r["D_err"],
                    "D_equal_u": Du, "err_equal_u": r["D"] / Du - 1.0, "D_equal_p": Dp,
                    "err_equal_p": r["D"] / Dp - 1.0, "steady": r["steady"], "w_inclusion": w_inc})
    cols = [("u_piston", "u_p km/s", ".3g"), ("u", "u km/s", ".4f"), ("D", "D CD", ".4f"), ("D_err", "+-", ".3f"),
            ("D_equal_u", "rule equal_u", ".4f"), ("err_equal_u", "CD/rule-1", "+.2%"),
            ("D_equal_p", "rule equal_p", ".4f"), ("err_equal_p", "CD/rule-1", "+.2%"), ("steady", "steady", "")]
    lines.append(format_table(tab, cols, f"{tag}: CD against the mixture rule 1/(D-u) = sum alpha_i/(D_i-u_i), "
                                         "D_i(u_i) from each pure phase's own CD Hugoniot"))
    if tab:
        eu = np.abs([t["err_equal_u"] for t in tab])
        ep = np.abs([t["err_equal_p"] for t in tab])
        lines.append(f"mean |error|: equal_u {eu.mean():.2%} (max {eu.max():.2%}), equal_p {ep.mean():.2%} "
                     f"(max {ep.max():.2%}); inclusion mass fraction of the sample {tab[0]['w_inclusion']:.4f}")
    for role, pr in pts.items():
        lines.append(format_table(pr, [("u_piston", "u_p km/s", ".3g"), ("D", "D km/s", ".4f"),
                                       ("u", "u km/s", ".4f"), ("steady", "steady", "")],
                                  f"pure {phases[role]} ({role}), CD"))
    return {"rows": tab, "markdown": markdown_table(tab, cols), "text": "\n".join(lines),
            "phase_points": {phases[k]: [(r["u"], r["D"]) for r in p] for k, p in pts.items()}}


def _uniaxial(mat, sv, two):
    if two:
        return None
    m = get_material(mat)
    deltas = np.round(np.arange(1.0, 2.0125, 0.025), 4)[1:]
    s_all = uniaxial_stress(mat, deltas, sv["direction"], sv["rc"], "all")
    s_ini = uniaxial_stress(mat, deltas, sv["direction"], sv["rc"], "initial")
    Px = np.array([m.curve.pressure(d) for d in deltas])
    try:
        ref = hugoniot(mat)
        # experimental Hugoniot pressure at the same compression
        uu = np.linspace(0.0, 8.0, 801) * units.km_s
        rr = ref.density(uu) / m.rho0
        Ph = np.interp(deltas, rr * m.rho0 / (ref.rho0_g_cm3 * units.g_cm3), ref.pressure(uu), right=np.nan)
    except InputError:
        ref, Ph = None, np.full(len(deltas), np.nan)
    rows = []
    for d, a, b, p, h in zip(deltas, s_all, s_ini, Px, Ph):
        rows.append({"delta": float(d), "sigma_all_GPa": a / units.GPa, "sigma_initial_GPa": b / units.GPa,
                     "P_cold_GPa": p / units.GPa, "P_hugoniot_exp_GPa": h / units.GPa})
    note = ""
    if sv["direction"] == "100":
        dc = math.sqrt(2.0) / sv["rc"]
        dr = math.sqrt(2.0)
        note = (f"[100]: the second neighbours along x (at sqrt(2) r0 at rest) come within rc = {sv['rc']:g} r0 at "
                f"rho/rho0 = {dc:.3f} and stay on the attractive branch (r > r0) up to rho/rho0 = {dr:.3f}")
    dec = [r["delta"] for r, nxt in zip(rows, rows[1:]) if nxt["sigma_all_GPa"] < r["sigma_all_GPa"]]
    cols = [("delta", "rho/rho0", ".3f"), ("sigma_all_GPa", "-s_xx all GPa", ".2f"),
            ("sigma_initial_GPa", "-s_xx initial GPa", ".2f"), ("P_cold_GPa", "P_x cold GPa", ".2f"),
            ("P_hugoniot_exp_GPa", "P Hugoniot exp GPa", ".2f")]
    shown = [r for r in rows if abs(r["delta"] * 20 - round(r["delta"] * 20)) < 1e-6
             or 1.2 <= r["delta"] <= 1.45]
    text = [format_table(shown, cols, f"static uniaxial compression along [{sv['direction']}] (rc = {sv['rc']:g}): "
                                      "longitudinal stress (all rows in uniaxial.csv)")]
    if note:
        text.append(note)
    if dec:
        text.append(f"with all pairs attracting the longitudinal stress falls as compression rises from "
                    f"rho/rho0 = {dec[0]:.3f}: the softening that makes D low near u = 2 km/s; with set-up bonds "
                    "only it rises monotonically")
    return {"rows": rows, "text": "\n".join(text), "markdown": markdown_table(rows, cols),
            "arrays": (deltas, s_all, s_ini, Px)}


# --------------------------------------------------------------------------- figures
class _Figs:
    """What every figure of the study draws from: the finite runs by group, the axes' range, the
    marker styles, the experimental Hugoniot (one phase) and the materials of the cold curves."""

    def __init__(self, folder, rows, mat, sv, two, phases):
        from ..scenes.common import matplotlib_agg
        self.plt = matplotlib_agg()
        self.folder, self.mat, self.sv, self.two, self.phases = folder, mat, sv, two, phases
        self.groups = {}
        for r in rows:
            if r.get("D") is None or not np.isfinite(r.get("D", np.nan)):
                continue
            self.groups.setdefault(r["group"], []).append(r)
        self.umax = max([r["u_piston"] for r in rows] + [1.0]) * 1.08
        self.style = {"main": ("o", "C0", "CD" + (" two-phase" if two else "")), "damped": ("s", "C1", "CD damped"),
                      "attraction=initial": ("D", "C2", "CD attraction=initial"),
                      "low-u": ("v", "C4", "CD weak shocks"), "low-u noise check": ("x", "C4", "CD weak shock, sweep noise")}
        self.ref = None
        if not two:
            try:
                self.ref = hugoniot(mat)
            except InputError:
                self.ref = None
        self.names = [mat] if not two else list(phases.values())

    def save(self, fig, name):
        fig.tight_layout()
        p = self.folder / name
        fig.savefig(p, dpi=120)
        self.plt.close(fig)
        return p


def _plots(folder, rows, mat, sv, two, phases, summary, uni):
    """The study's figures (D-u, P-rho, weak shocks, static uniaxial compression); returns their paths."""
    f = _Figs(folder, rows, mat, sv, two, phases)
    files = [_plot_du(f, summary, uni), _plot_prho(f, uni)]
    if "low_u" in summary and "D0" in summary["low_u"]:
        files.append(_plot_low_u(f, summary["low_u"]))
    if uni is not None:
        files.append(_plot_uniaxial(f, uni))
    return files


def _plot_du(f, summary, uni):
    """D-u: the CD runs, the experiment, the cold curve's and the static lattice's images."""
    plt, groups, umax, style, ref, names = f.plt, f.groups, f.umax, f.style, f.ref, f.names
    mat, sv, two, phases = f.mat, f.sv, f.two, f.phases
    fig, ax = plt.subplots(figsize=(7, 5.2))
    uu = np.linspace(0.0, umax, 200)
    if ref is not None:
        meas = uu <= ref.u_max / units.km_s
        ax.plot(uu[meas], ref.D(uu[meas] * units.km_s) / units.km_s, "k-", lw=1.5, label=f"experiment ({ref.name})")
        if not meas.all():
            ax.plot(uu[~meas], ref.D(uu[~meas] * units.km_s) / units.km_s, "k--", lw=1.0,
                    label=f"{ref.name} extrapolated beyond u = {ref.u_max / units.km_s:g} km/s")
    for k, m in enumerate(names):
        dd = np.linspace(1.0005, 3.0, 400)
        cu, cD = cold_curve_du(m, dd)
        sel = cu <= umax
        ax.plot(cu[sel], cD[sel], ls=":", color="k" if not two else f"C{5 + k}", lw=1.2,
                label=f"cold curve {m} (Rayleigh line to P_x)")
    if uni is not None:
        dl, sa, si, _ = uni["arrays"]
        rho0 = get_material(mat).rho0
        for s, lab, c in ((sa, "all pairs", "C3"), (si, "set-up bonds", "C2")):
            su, sD = stress_du(s, dl, rho0)
            ax.plot(su, sD, "--", color=c, lw=1, label=f"static uniaxial lattice, {lab}")
    for g, rr in groups.items():
        if g.startswith("pure "):
            continue
        mk, c, lab = style.get(g, ("o", "C7", g))
        ax.errorbar([r["u"] for r in rr], [r["D"] for r in rr], yerr=[r["D_err"] or 0 for r in rr], fmt=mk,
                    color=c, ms=5, label=lab, mfc="none" if g != "main" else c)
    if two:
        for k, (role, m) in enumerate(phases.items()):
            rr = groups.get(f"pure {m}", [])
            ax.plot([r["u"] for r in rr], [r["D"] for r in rr], "^", color=f"C{5 + k}", label=f"CD pure {m}")
        mix = summary.get("mixture", {})
        pp = mix.get("phase_points", {})
        if len(pp) == 2:
            w = mix["rows"][0]["w_inclusion"] if mix.get("rows") else 0.3
            cm = hugoniot_interpolant(*zip(*pp[phases["matrix"]]))
            ci = hugoniot_interpolant(*zip(*pp[phases["inclusion"]]))
            ph = [(1 - w, get_material(phases["matrix"]).rho0 / units.g_cm3, cm),
                  (w, get_material(phases["inclusion"]).rho0 / units.g_cm3, ci)]
            ug = np.linspace(0.3, umax, 60)
            ax.plot(ug, [mixture_D(x, ph, "equal_u") for x in ug], "k-", lw=1.3, label="mixture rule, equal_u")
            ax.plot(ug, [mixture_D(x, ph, "equal_p") for x in ug], "k--", lw=1.3, label="mixture rule, equal_p")
    ax.set_xlim(0, umax)
    ax.set_xlabel("particle velocity u (km/s)")
    ax.set_ylabel("shock speed D (km/s)")
    ax.set_title(f"D-u: {mat}{' + ' + phases.get('inclusion', '') if two else ''} [{sv['direction']}], "
                 f"r0 = {sv['r0'] / units.um:g} um")
    ax.legend(fontsize=7)
    return f.save(fig, "hugoniot_du.png")


def _plot_prho(f, uni):
    """P-rho: the CD runs, the cold curves, the experiment and the static lattice."""
    plt, groups, umax, style, ref, names = f.plt, f.groups, f.umax, f.style, f.ref, f.names
    mat, sv, two, phases = f.mat, f.sv, f.two, f.phases
    fig, ax = plt.subplots(figsize=(7, 5.2))
    for k, m in enumerate(names):
        mm = get_material(m)
        dd = np.linspace(1.0, 2.2, 300)
        ax.plot(dd * mm.rho0 / units.g_cm3, [mm.curve.pressure(x) / units.GPa for x in dd], ":",
                color="k" if not two else f"C{5 + k}", label=f"cold curve P_x {m}")
    if ref is not None:
        ur = np.linspace(0.0, umax, 200) * units.km_s
        meas = ur <= ref.u_max
        ax.plot(ref.density(ur[meas]) / units.g_cm3, ref.pressure(ur[meas]) / units.GPa, "k-", lw=1.5,
                label=f"experiment ({ref.name})")
        if not meas.all():
            ax.plot(ref.density(ur[~meas]) / units.g_cm3, ref.pressure(ur[~meas]) / units.GPa, "k--", lw=1.0,
                    label=f"{ref.name} extrapolated beyond u = {ref.u_max / units.km_s:g} km/s")
    if uni is not None:
        dl, sa, si, _ = uni["arrays"]
        r0_ = get_material(mat).rho0 / units.g_cm3
        ax.plot(dl * r0_, sa / units.GPa, "--", color="C3", lw=1, label="static uniaxial lattice, all pairs")
        ax.plot(dl * r0_, si / units.GPa, "--", color="C2", lw=1, label="static uniaxial lattice, set-up bonds")
    for g, rr in groups.items():
        mk, c, lab = style.get(g, ("^", None, f"CD {g}"))
        ax.plot([r["rho"] for r in rr], [r["P"] for r in rr], mk, color=c, ms=5, label=lab,
                mfc="none" if g != "main" else c)
    ax.set_xlabel("density rho (g/cm3)")
    ax.set_ylabel("longitudinal stress P = -sigma_xx (GPa)")
    ax.set_title(f"P-rho: {mat}{' + ' + phases.get('inclusion', '') if two else ''} [{sv['direction']}]")
    ymax = max([r["P"] for rr in groups.values() for r in rr if np.isfinite(r.get("P", np.nan))] + [1.0]) * 1.15
    ax.set_ylim(0, ymax)
    ax.legend(fontsize=7)
    return f.save(fig, "hugoniot_prho.png")


def _plot_low_u(f, lu):
    """The weak shocks and their extrapolation to u = 0."""
    plt, groups, ref, sv = f.plt, f.groups, f.ref, f.sv
    fig, ax = plt.subplots(figsize=(6, 4.2))
    rr = groups.get("low-u", [])
    ax.errorbar([r["u_piston"] for r in rr], [r["D"] for r in rr], yerr=[r["D_err"] for r in rr], fmt="v",
                color="C4", label="CD weak shocks")
    x = np.linspace(0, max(r["u_piston"] for r in rr) * 1.1, 10)
    ax.plot(x, lu["D0"] + lu["slope"] * x, "C4-", lw=1, label=f"fit, D0 = {lu['D0']:.3f} km/s")
    if "lattice_cL" in lu:
        ax.axhline(lu["lattice_cL"], color="k", ls="--", lw=1,
                   label=f"lattice c_L [{sv['direction']}] = {lu['lattice_cL']:.3f} km/s")
        ax.axhline(lu["c0"], color="k", ls=":", lw=1, label=f"c0 = {lu['c0']:.3f} km/s")
    if ref is not None:
        ax.plot(x, ref.D(x * units.km_s) / units.km_s, "k-", lw=1, label=f"experiment ({ref.name})")
    ax.set_xlabel("piston speed u (km/s)")
    ax.set_ylabel("D (km/s)")
    ax.legend(fontsize=7)
    return f.save(fig, "low_u.png")


def _plot_uniaxial(f, uni):
    """The static uniaxial compression of the lattice."""
    plt, sv = f.plt, f.sv
    dl, sa, si, Px = uni["arrays"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.plot(dl, sa / units.GPa, "o-", color="C3", ms=3, label="-sigma_xx, all pairs attract")
    ax.plot(dl, si / units.GPa, "s-", color="C2", ms=3, label="-sigma_xx, set-up bonds only")
    ax.plot(dl, Px / units.GPa, "k:", label="cold curve P_x (hydrostatic)")
    if sv["direction"] == "100":
        ax.axvline(math.sqrt(2) / sv["rc"], color="0.5", lw=0.8)
        ax.text(math.sqrt(2) / sv["rc"], ax.get_ylim()[1] * 0.9, " 2nd neighbours\n enter rc", fontsize=7)
    ax.set_xlabel("rho/rho0 (uniaxial strain)")
    ax.set_ylabel("GPa")
    ax.set_title(f"static uniaxial compression along [{sv['direction']}], rc = {sv['rc']:g}")
    ax.legend(fontsize=7)
    return f.save(fig, "uniaxial.png")
