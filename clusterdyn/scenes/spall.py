"""Scene ``spall``: a thin aluminium flyer on a thicker target, fast enough to spall it.

docs/theory.md 1.8.  The plates are the ``plate-impact`` scene's
(:func:`~clusterdyn.scenes.plate_impact.build_impact`: free along x,
periodic across, a [100] single crystal or a relaxed polycrystal, each plate
moving at v/2 toward the other), with a flyer thinner than the target (20 and
40 r0 by default: the acoustic spall plane lies one flyer thickness from the
rear face, in the middle of the target).  Recorded
(:class:`SpallRecord`, an :class:`~clusterdyn.scenes.plate_impact.ImpactRecord`
with a Lagrangian stress map):

* the rear free-surface velocity (VISAR trace, target frame) and its
  pullback ``du = u_max - u_min`` (:func:`clusterdyn.analysis.spall.pullback`);
* the spall strength ``rho0 c du / 2`` with c the bulk speed c_b = c0 and the
  lattice's longitudinal speed c_L = sqrt(3/2) c0 along [100]; the largest
  tension any 2 r0 slab of the target held (from the stress profiles); both
  beside the perfect lattice's uniaxial-strain limit (19.2 GPa along [100])
  and aluminium's measured spall strength (1-1.6 GPa at 1e5-1e6 /s);
* the spall plane from the fragments at the end (the scab's thickness,
  Lagrangian) against the plane expected from the measured wave speeds: the
  releases from the flyer's rear and from the target's rear, tracked on the
  stress map in material coordinates (at ``level`` of the pulse, half by
  default) and fitted by straight lines, cross where the target goes into
  tension from both sides (:func:`clusterdyn.analysis.spall.wave_speeds`);
  beside it the acoustic estimate (the flyer's thickness) and the thickness
  the VISAR's ringing gives (c_L T / 2);
* the fragments after the spall (spectrum N(g), PNG + CSV);
* the energy ledger of the run (kinetic, potential, damping loss) against the
  plates' initial kinetic energy.
"""

import csv
import math
from dataclasses import dataclass

import numpy as np

from .. import units
from ..analysis.fragment_spectra import write_spectrum_csv
from ..analysis.fragments import fragments
from ..analysis.spall import LagrangianMap, pullback, ring_thickness, spall_plane, spall_strength, wave_speeds
from ..build.lattice import SQRT2, lattice_sound_speed
from ..errors import InputError
from ..materials import get_material
from .base import Param, Quantity, register_scene
from .common import ledger_joules, matplotlib_agg
from .lifecycle import SceneDef, Stage, scene_params
from .plate_impact import ImpactRecord, ImpactSetup, build_impact, write_visar_csv

#: perfect [100] lattice, uniaxial strain, rc = 1.15: the tension it holds (docs/theory.md 1.8)
IDEAL_SPALL_100_GPA = 19.2
#: measured spall strength of aluminium at strain rates 1e5-1e6 /s, GPa (docs/theory.md 1.8)
MEASURED_AL_SPALL_GPA = (1.0, 1.6)

PARAMS = [
    Param("sample", "both", "single crystal ([100]), polycrystal, or both", kind="choice",
          choices=("single", "polycrystal", "both")),
    Param("v", 2300.0, "relative impact speed (each plate moves at v/2); the single crystal spalls from 2300",
          unit="m/s", low=0.0, high=8000.0,
          low_open=True),
    Param("r0", 10.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("flyer", 20.0, "flyer thickness, in r0", low=4.0),
    Param("target", 40.0, "target thickness, in r0 (thicker than the flyer)", low=8.0),
    Param("width", 8.0, "periodic width across (y, z), in r0 (rounded to sqrt(2) r0 cells)", low=3.0),
    Param("grain_size", 6.0, "polycrystal: mean grain diameter, in r0", low=3.0),
    Param("d_min", 0.85, "polycrystal: minimum distance at grain boundaries, in r0", low=0.6, high=1.1),
    Param("porosity", None, "polycrystal: target porosity (sets d_min by bisection)", low=0.0, high=0.5,
          optional=True),
    Param("J", 50.0, "pair damping Gamma = c0/(J r0) (free surfaces: damped); none = off", low=0.0,
          low_open=True, optional=True),
    Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
    Param("seed", 1, "random seed (grains, orientations, noise)", kind="int", low=0),
    Param("duration", None, "run time; none = (target + 6 flyer)/c_L (x1.6 for a polycrystal)", unit="ns",
          low=0.0, low_open=True, optional=True),
    Param("frames", 150, "stress maps recorded over the run", kind="int", low=20),
    Param("level", 0.5, "release fronts tracked where the compression has fallen to this fraction of the pulse", low=0.01,
          high=0.5),
    Param("relax_cycles", 12, "polycrystal: quench cycles of 100 steps before the impact", kind="int", low=0),
    Param("packing", None, "polycrystal: a packing preset or JSON file (clusterdyn.scenes.packing; sets grain "
          "size, porosity and boundaries, e.g. the boundary law); none = the parameters above", kind="str",
          optional=True),
]


def spall_duration(info, duration=None):
    """Run time: ``duration`` or the pulse's way to the rear face, its release and a few ringing periods."""
    if duration is not None:
        return duration
    cL = lattice_sound_speed(info["c0"])
    slow = 1.0 if info["sample"] == "single" else 1.6
    return slow * (info["target"] + 6.0 * info["flyer"]) / cL


@dataclass
class SpallSetup(ImpactSetup):
    """An :class:`~clusterdyn.scenes.plate_impact.ImpactSetup` with what the spall analysis adds."""

    x0: np.ndarray = None          #: every particle's x at set-up (the material coordinates)
    target_rows: np.ndarray = None
    x_flyer_rear: float = 0.0
    x_target_front: float = 0.0
    rho0: float = 0.0              #: the target's density at rest


class SpallRecord(ImpactRecord):
    """An :class:`~clusterdyn.scenes.plate_impact.ImpactRecord` (slab profiles, VISAR trace) with a
    :class:`~clusterdyn.analysis.spall.LagrangianMap` of sigma_xx in material coordinates (r0 bins)."""

    def __init__(self, setup):
        super().__init__(setup)
        r0 = setup.r0
        self.lmap = LagrangianMap(np.asarray(setup.x0, float), r0, r0 ** 3 / SQRT2)

    def frame(self, d):
        vir = super().frame(d)
        self.lmap.add(vir, d.get_time())
        return vir

    def get_state(self):
        st = super().get_state()
        st["lmap"] = self.lmap.get_state()
        return st

    def set_state(self, st):
        super().set_state(st)
        self.lmap.set_state(st["lmap"])


class SpallScene(SceneDef):
    """The ``spall`` scene on the lifecycle (module docstring), one stage per sample."""

    name = "spall"
    description = ("thin Al flyer on a thicker target: VISAR trace, pullback, spall strength (c_b and c_L), "
                   "spall plane vs the measured wave speeds, fragments; single crystal vs polycrystal")
    params = scene_params(PARAMS)
    setup_class = SpallSetup

    def check(self, v):
        if v.target <= v.flyer:
            raise InputError("target", v.target, f"thicker than the flyer ({v.flyer:g} r0)")
        if v.sample != "single" and v.grain_size > 2 * v.flyer:
            raise InputError("grain_size", v.grain_size, f"at most twice the flyer ({v.flyer:g} r0)")
        if v.packing is not None:
            from .packing import resolve_packing
            resolve_packing(v.packing)            # checked before any work

    def plan(self, v):
        return ["single", "polycrystal"] if v.sample == "both" else [v.sample]

    def setup(self, v, stage):
        s = build_impact(stage, "Al", v.v, v.r0, v.flyer, v.target, v.width, v.grain_size,
                         v.d_min, v.porosity, v.seed, v.noise, v.J, relax_cycles=v.relax_cycles,
                         packing=v.packing)
        atoms = s["atoms"]
        plate = atoms.arrays["plate"]
        x0 = atoms.positions[:, 0].copy()
        setup = SpallSetup.built(s, x0=x0, target_rows=np.nonzero(plate == 1)[0],
                                 x_flyer_rear=float(x0[plate == 0].min()), x_target_front=float(x0[plate == 1].min()),
                                 rho0=_density(atoms, plate == 1, s["width"], s["r0"]))
        setup.nsteps = int(math.ceil(spall_duration(setup, v.duration) / s["dt"]))
        s["dyn"].start_ledger()
        return setup

    def attach(self, v, stage, setup):
        rec = SpallRecord(setup)
        return Stage(stage, setup.atoms, setup.dyn, int(setup.nsteps), v.frames, on_frame=rec.frame, analysis=rec,
                     observers=[(rec.fsv, 5)])

    def finish(self, v, stage):
        rec, atoms, info = stage.analysis, stage.atoms, stage.info
        f = fragments(atoms)
        target = np.zeros(len(atoms), bool)
        target[np.asarray(info["target_rows"], np.int64)] = True
        plane = spall_plane(atoms, f, np.asarray(info["x0"]), target, np.asarray(info["rear"], np.int64))
        g, n = f.spectrum()
        return {"name": stage.name, "info": info, "profiles": rec.rec.arrays(), "lmap": rec.lmap.arrays(),
                "fsv_t": np.array(rec.fsv_t), "fsv_v": np.array(rec.fsv_v), "plane": plane,
                "spectrum_g": g, "spectrum_n": n, "ledger": stage.dyn.energy_ledger(), "n": len(atoms),
                "nsteps": stage.nsteps, "t_run": stage.t_run}

    def analyse(self, v, summaries):
        q, notes, extra, analysed = {}, [], {}, []
        for sm in summaries:
            a = analyse_spall(sm, v)
            qq, nn, ex = spall_quantities(sm, v, a)
            q.update(qq)
            notes += nn
            extra[sm["name"]] = ex
            analysed.append(a)
        return q, notes, extra, analysed

    def report(self, v, summaries, result, out):
        files = [plot_spall(summaries, result.data, v, out / "spall.png")]
        for sm in summaries:
            files.append(write_visar_csv(out / f"spall_visar_{sm['name']}.csv", sm))
            files.append(write_lmap_csv(out / f"spall_stress_map_{sm['name']}.csv", sm["lmap"]))
            files.append(write_spectrum_csv(out / f"spall_fragments_{sm['name']}.csv", sm["spectrum_g"],
                                            sm["spectrum_n"]))
        return files


register_scene(SpallScene())


def _density(atoms, mask, width, r0):
    """Density of a plate at rest: its mass over its thickness (plus one plane spacing) times the
    cross-section, ASE units."""
    x = atoms.positions[mask, 0]
    vol = (np.ptp(x) + r0 / SQRT2) * width * width
    return float(atoms.get_masses()[mask].sum() / vol)


def analyse_spall(sm, v):
    """The measured quantities of one stage (ASE units) from its summary."""
    info = sm["info"]
    mat = get_material("Al")
    c0 = info["c0"]
    cL = lattice_sound_speed(c0)
    r0 = info["r0"]
    Lf, Lt = info["flyer"], info["target"]
    pulse = 2.0 * Lf / cL * (1.0 if info["sample"] == "single" else 1.6)
    pb = pullback(sm["fsv_t"], sm["fsv_v"], info["v"], pulse=pulse, c=c0)
    rho0 = info["rho0"]
    ws = wave_speeds(sm["lmap"], info["x_target_front"] - 0.5 * r0 / SQRT2, info["x_rear"] + 0.5 * r0 / SQRT2,
                     level=v.level)
    plane = sm["plane"]
    depth = plane["scab_fraction"] * Lt if plane["spalled"] else float("nan")
    ring, T = (ring_thickness(sm["fsv_t"], sm["fsv_v"], pb["t_signal"], cL) if pb["spall_signal"]
               else (float("nan"), float("nan")))
    prof = sm["profiles"]
    s_xx = prof["stress"][:, :, 0]
    occupied = prof["count"] > 0
    tension = float(np.max(np.where(occupied, s_xx, -np.inf)))
    compression = float(np.max(np.where(occupied, -s_xx, -np.inf)))
    return {"pullback": pb, "rho0": rho0, "c_b": c0, "c_L": cL, "sigma_cb": spall_strength(rho0, c0, pb["du"]),
            "sigma_cL": spall_strength(rho0, cL, pb["du"]), "waves": ws, "depth": depth, "ring": ring,
            "ring_T": T, "max_tension": tension, "max_compression": compression, "material": mat}


def spall_quantities(sm, v, a=None):
    """``(quantities, notes, extra)`` of one stage (``a``: its :func:`analyse_spall`, made when not given)."""
    a = analyse_spall(sm, v) if a is None else a
    info, pb, ws, plane = sm["info"], a["pullback"], a["waves"], sm["plane"]
    p = "sc_" if sm["name"] == "single" else "pc_"
    r0 = info["r0"]
    L = sm["ledger"]
    LJ = ledger_joules(L)
    lo, hi = MEASURED_AL_SPALL_GPA
    ideal = IDEAL_SPALL_100_GPA if sm["name"] == "single" else None
    measured = 0.5 * (lo + hi) if sm["name"] != "single" else None
    q = {
        p + "spalled": Quantity(float(plane["spalled"]), "", note="1: the scab (fragment of the rear layer) holds "
                                                                   "none of the target's front 5%"),
        p + "fsv_max": Quantity(pb["u_max"] / units.m_s, "m/s", info["v"] / units.m_s,
                                note="first free-surface maximum vs the impact speed"),
        p + "fsv_min": Quantity(pb["u_min"] / units.m_s, "m/s", note="minimum before the velocity rises again"),
        p + "pullback": Quantity(pb["du"] / units.m_s, "m/s", note="u_max - u_min"),
        **_strengths(p, a, bool(plane["spalled"]), measured, ideal, lo, hi),
        p + "max_tension": Quantity(a["max_tension"] / units.GPa, "GPa", ideal,
                                    note="largest sigma_xx (tension) of any 2 r0 slab over the run"),
        p + "max_compression": Quantity(a["max_compression"] / units.GPa, "GPa",
                                        note="largest -sigma_xx of any 2 r0 slab over the run"),
        p + "strain_rate": Quantity(pb["strain_rate"] * units.s, "1/s",
                                    note="unloading: -(du_fs/dt)/(2 c_b) between 20% and 80% of the drop"),
        p + "spall_depth": Quantity(a["depth"] / r0, "r0", _finite(ws["d_expected"] / r0),
                                    note="scab thickness (its share of the target's clusters x target) vs where "
                                         "the releases cross (measured speeds)"),
        p + "ring_depth": Quantity(a["ring"] / r0, "r0", _finite(a["depth"] / r0),
                                   note=f"c_L T / 2 from the VISAR ringing, T = {a['ring_T'] / units.ns:.4g} ns, "
                                        "vs the scab"),
        p + "D": Quantity(ws["D"] / units.km_s, "km/s", note="shock speed (half amplitude), material coordinates"),
        p + "c_release_forward": Quantity(ws["c_forward"] / units.km_s, "km/s",
                                          note=f"release from the flyer's rear, at {v.level:g} of the pulse"),
        p + "c_release_backward": Quantity(ws["c_backward"] / units.km_s, "km/s",
                                           note="release reflected from the target's rear face"),
        p + "target_fragments": Quantity(plane["n_target_fragments"], "", note="fragments of the target at the end"),
        p + "ledger_residual": Quantity(L["residual"] / L["energy_in"], "",
                                        note="energy ledger residual / initial kinetic energy"),
    }
    notes = []
    for key, why in ((p + "spall_depth", "no scab (the target did not spall)"),
                     (p + "ring_depth", "no ringing after a spall signal in the free-surface velocity")):
        if not math.isfinite(q[key].value):
            del q[key]
            notes.append(f"{key}: not measured: {why}")
    notes += [f"{sm['name']}: {sm['n']} clusters, {sm['nsteps']} steps, {sm['t_run']:.1f} s stepping; flyer "
             f"{info['flyer'] / r0:g} r0, target {info['target'] / r0:g} r0 (acoustic spall plane: "
             f"{info['flyer'] / r0:g} r0 from the rear face); largest target fragments "
             f"{plane['largest_target_fragments']}",
             f"{sm['name']}: waves in material coordinates: D {ws['D'] / units.km_s:.3f} km/s, releases at "
             f"{v.level:g} of the pulse {ws['c_forward'] / units.km_s:.3f} / {ws['c_backward'] / units.km_s:.3f} km/s "
             f"({ws['n_forward']} / {ws['n_backward']} frames), " + _crossing(ws, r0),
             f"{sm['name']}: perfect [100] lattice in uniaxial strain holds {IDEAL_SPALL_100_GPA} GPa; measured "
             f"aluminium {lo:g}-{hi:g} GPa at 1e5-1e6 /s",
             f"{sm['name']}: energy ledger (J): kinetic {LJ['kinetic']:.6g}, potential {LJ['potential']:.6g}, damping "
             f"loss {LJ['damping_loss']:.6g}, energy in {LJ['energy_in']:.6g}, residual {LJ['residual']:.3g}"]
    ex = {"ledger_J": LJ, "pullback": {k: _num(x) for k, x in pb.items()},
          "waves": {k: _num(x) for k, x in ws.items()}, "plane": plane,
          "spectrum": {"g": sm["spectrum_g"].tolist(), "N": sm["spectrum_n"].tolist()}}
    return q, notes, ex


def _finite(x):
    return x if math.isfinite(x) else None


def _crossing(ws, r0):
    """Where the two releases cross (or why there is no such point)."""
    if math.isfinite(ws["d_expected"]) and math.isfinite(ws["t_cross"]):
        return f"crossing at {ws['d_expected'] / r0:.2f} r0 from the rear face, t = {ws['t_cross'] / units.ns:.1f} ns"
    return "no crossing point: a release speed was not measured (too few frames above the level)"


def _strengths(p, a, spalled, measured, ideal, lo, hi):
    """The pullback strengths: spall strengths when the target spalled, else the tension it held (a lower
    bound of its spall strength), under keys that say so."""
    name, what = ("spall_strength", "") if spalled else ("tension_held", "no spall: the tension the target held, "
                                                         "a lower bound of its spall strength; ")
    return {
        p + name + "_cb": Quantity(a["sigma_cb"] / units.GPa, "GPa", measured,
                                   note=f"{what}rho0 c_b du / 2, c_b = c0 = {a['c_b'] / units.km_s:.3f} km/s, "
                                        f"rho0 = {a['rho0'] / units.g_cm3:.4f} g/cm3"
                                        + (f"; vs measured Al {lo:g}-{hi:g} GPa" if measured else "")),
        p + name + "_cL": Quantity(a["sigma_cL"] / units.GPa, "GPa", ideal,
                                   note=f"{what}rho0 c_L du / 2, c_L = sqrt(3/2) c0 = {a['c_L'] / units.km_s:.3f} "
                                        "km/s ([100] lattice)"
                                        + ("; vs the perfect [100] lattice in uniaxial strain" if ideal else "")),
    }


def _num(x):
    return bool(x) if isinstance(x, (bool, np.bool_)) else float(x)


def write_lmap_csv(path, lmap):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_ns", "x0_um", "sigma_xx_per_rest_volume_GPa"])
        for k, t in enumerate(lmap["t"]):
            for x, s in zip(lmap["x"], lmap["stress"][k]):
                w.writerow([f"{t / units.ns:.6g}", f"{x / units.um:.6g}", f"{s / units.GPa:.5g}"])
    return path


def plot_spall(summaries, analysed, v, path):
    """VISAR traces with the pullback, the stress maps with the fitted waves, the fragment spectra
    (``analysed``: each stage's :func:`analyse_spall`)."""
    plt = matplotlib_agg()
    n = len(summaries)
    fig, axs = plt.subplots(n, 3, figsize=(16, 4.3 * n), squeeze=False)
    for row, (sm, a) in enumerate(zip(summaries, analysed)):
        info, pb, ws = sm["info"], a["pullback"], a["waves"]
        r0 = info["r0"]
        ax = axs[row, 0]
        ax.plot(sm["fsv_t"] / units.ns, sm["fsv_v"] / units.m_s, "k-", lw=1)
        for val, lab, c in ((pb["u_max"], "u_max", "C0"), (pb["u_min"], "u_min", "C1")):
            ax.axhline(val / units.m_s, color=c, ls="--", lw=0.8, label=f"{lab} = {val / units.m_s:.0f} m/s")
        ax.set_xlabel("t (ns)")
        ax.set_ylabel("rear free-surface velocity (m/s)")
        ax.set_title(f"{sm['name']}: v = {info['v'] / units.m_s:.0f} m/s, du = {pb['du'] / units.m_s:.0f} m/s, "
                     f"sigma_sp = {a['sigma_cb'] / units.GPa:.2f} (c_b) / {a['sigma_cL'] / units.GPa:.2f} (c_L) GPa",
                     fontsize=9)
        ax.legend(fontsize=7)
        lm = sm["lmap"]
        ax = axs[row, 1]
        S = lm["stress"] / units.GPa
        lim = np.nanpercentile(np.abs(S), 99)
        im = ax.pcolormesh(lm["x"] / r0, lm["t"] / units.ns, S, cmap="RdBu_r", vmin=-lim, vmax=lim,
                           shading="auto")
        fig.colorbar(im, ax=ax, label="sigma_xx per rest volume (GPa, tension +)")
        tt = np.linspace(0, lm["t"][-1], 50)
        if math.isfinite(ws["t_cross"]):
            tc = ws["t_cross"]
            xc = ws["x_cross"]
            for c, t0 in ((ws["c_forward"], tt[tt <= tc]), (-ws["c_backward"], tt[tt <= tc])):
                sel = t0[(xc + c * (t0 - tc) > lm["x"][0]) & (xc + c * (t0 - tc) < lm["x"][-1])]
                ax.plot((xc + c * (sel - tc)) / r0, sel / units.ns, "k--", lw=0.8)
            ax.plot([xc / r0], [tc / units.ns], "ko", ms=5, label=f"releases cross: {ws['d_expected'] / r0:.1f} r0 "
                    "from the rear")
        if plane_ok(sm):
            xs = info["x_rear"] + 0.5 * r0 / SQRT2 - a["depth"]
            ax.axvline(xs / r0, color="g", lw=1, label=f"spall plane (scab {a['depth'] / r0:.1f} r0)")
        ax.set_xlabel("x0 / r0 (material coordinate)")
        ax.set_ylabel("t (ns)")
        ax.set_title(f"{sm['name']}: stress in material coordinates")
        if ax.get_legend_handles_labels()[0]:      # no release crossing and no spall plane: no empty legend
            ax.legend(fontsize=7, loc="upper left")
        ax = axs[row, 2]
        g, nn = sm["spectrum_g"], sm["spectrum_n"]
        ax.loglog(g, nn, "o")
        ax.set_xlabel("clusters per fragment g")
        ax.set_ylabel("fragments N(g)")
        ax.set_title(f"{sm['name']}: fragments at the end ({int(np.sum(nn))})")
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def plane_ok(sm):
    return bool(sm["plane"]["spalled"])
