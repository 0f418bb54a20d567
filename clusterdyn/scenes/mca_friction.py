"""MCA friction scene: ``clusterdyn run mca-friction`` (segment method or explicit roughness).

Two 2D (plane strain) MCA blocks of hexagonally packed automata, periodic along x
(``size = Lx x H`` automaton sizes each), stacked along y.  The bottom row of the lower
block is held (:class:`~clusterdyn.md.Piston` at rest); the top row of the upper block is a
:class:`~clusterdyn.md.Traction` pressed down by the normal stress (ramped up over the
first ``ramp`` of the run) and driven along x at the speed V (ramped linearly from
``ramp`` to ``2 ramp`` of the run, then constant); the layers do not rotate; pair damping
``damping`` (quasi-static).

``method="segment"``: the two surfaces meet through the segment method and the friction
law of :mod:`clusterdyn.mca.contact` (mu0, mu1, K_av, the two sinusoids, v_reg).
``method="explicit"``: no segments; the surfaces are cut to a step pattern (``steps_w``
automata removed, ``steps_w`` kept, along the contacting rows) and meet through the
ordinary unlinked-pair contact with Coulomb friction mu1.

Measured on every frame (:class:`FrictionCurve`): the macroscopic friction coefficient
``mu_dr = F_dr / F_N`` with F_dr the tangential force the drive needs (minus the
traction's recorded friction along x) and F_N the applied normal force (stress x Lx x unit
thickness), against time and sliding distance (the drive's x displacement); the friction
work of the segment law, the pair-damping dissipation and the drive's work; the contact
state (contacts, mean K_mu, clips).  The result compares the mean mu_dr over the steady
part (the second half of the sliding) with ``mu1 + K_av``.
"""

import csv
import math

import numpy as np

from .. import units
from ..build.mca import mca_packing, set_masses
from ..errors import InputError
from ..materials import get_material
from ..mca.contact import SegmentContact, stack_blocks
from ..mca.dynamics import MCADynamics
from ..md.histories import Table
from ..md.layer_drives import Piston, Traction
from .base import Param, Quantity, register_scene
from .lifecycle import SceneDef, Stage, scene_params

MATERIALS = ("alumina", "concrete", "Al6061", "copper")
#: energy per unit thickness (1 Angstrom) -> J per metre of thickness
JM = units.m / units.J
#: mu0 is given in MPa per m/s
MU0_UNIT = units.MPa / units.m_s


def _params():
    return scene_params([
        Param("method", "segment", "contact of the two surfaces", kind="choice", choices=("segment", "explicit")),
        Param("material", "alumina", "lower block material", kind="choice", choices=MATERIALS),
        Param("material_top", "alumina", "upper block material", kind="choice", choices=MATERIALS),
        Param("d", 10.0, "automaton size (2R)", unit="um", low=0.0, low_open=True),
        Param("size", (24, 4), "each block: periodic length x height in automaton sizes", kind="ints", low=2),
        Param("stress", 0.05, "normal stress pressing the blocks together (below the softer block's "
              "compressive or yield strength)", unit="GPa", low=0.0, low_open=True),
        Param("V", 20.0, "sliding speed of the upper block's top row (at most 1% of the slower block's "
              "bar wave speed, sqrt(E/rho): a quasi-static slide)", unit="m/s", low=0.0, low_open=True),
        Param("mu0", 0.0, "viscous friction coefficient, MPa per m/s", low=0.0),
        Param("mu1", 0.3, "dry friction coefficient", low=0.0),
        Param("K_av", 0.0, "mean interlocking", low=0.0),
        Param("A1", 0.0, "mean amplitude of sinusoid 1", unit="um", low=0.0),
        Param("l1", 5.0, "mean half-period of sinusoid 1", unit="um"),
        Param("d1", 20.0, "regularity length (mean section) of sinusoid 1", unit="um"),
        Param("A2", 0.0, "mean amplitude of sinusoid 2", unit="um", low=0.0),
        Param("l2", 1.0, "mean half-period of sinusoid 2", unit="um"),
        Param("d2", 5.0, "regularity length of sinusoid 2", unit="um"),
        Param("v_reg", 0.001, "regularising velocity of the dry part", unit="m/s", low=0.0, low_open=True),
        Param("steps_w", 2, "explicit method: width of the steps cut in the surfaces (automata; 0 = none: "
              "the bare rows of automata)", kind="int", low=0),
        Param("steps", 6000, "time steps (dt = 0.15 d / c_L)", kind="int", low=100),
        Param("ramp", 0.1, "fraction of the run ramping the stress (then as much ramping V)", low=0.0,
              low_open=True, high=0.4),
        Param("damping", 0.2, "fraction of critical damping of relative pair velocity", low=0.0, high=1.0),
        Param("seed", 0, "seed of the interlocking sections", kind="int", low=0),
        Param("frames", 200, "samples of mu_dr over the run", kind="int", low=10),
    ], h5md_frames=20, checkpoint_every=20)


def _check_coefficients(v):
    for k in ("mu0", "mu1", "K_av"):
        if not (v[k] >= 0 and math.isfinite(v[k])):
            raise InputError(k, v[k], "a coefficient >= 0")
    for k in ("A1", "A2"):
        if not v[k] >= 0:
            raise InputError(k, f"{v[k] / units.um:g}um", "an amplitude >= 0 um")
    if not v.stress > 0:
        raise InputError("stress", f"{v.stress / units.GPa:g}GPa",
                         "a normal stress > 0 GPa (pressing the blocks together)")
    if not v.V >= 0:
        raise InputError("V", f"{v.V / units.m_s:g}m/s", "a sliding speed >= 0 m/s")


def _block(mat, mats, mid, d, size, pbc, remove_rows=None, steps_w=0):
    L, H = size
    b = mca_packing(mat, d, (L * d, H * d), packing="hex", pbc=pbc, materials=mats,
                    material_id=lambda p: np.full(len(p), mid))
    if b.info["mca_dim"] != 2:
        raise InputError("dim", 3, "2D blocks")
    if remove_rows is not None and steps_w > 0:
        y = b.positions[:, 1]
        row = np.isclose(y, y.max() if remove_rows == "top" else y.min())
        xr = b.positions[:, 0]
        k = np.floor(xr / d + 1e-9).astype(int)
        cut = row & ((k // steps_w) % 2 == (0 if remove_rows == "top" else 1))
        keep = ~cut
        info = dict(b.info)
        b = b[keep]
        b.info = info
        b.arrays["id"] = np.arange(len(b), dtype=np.int64)
        set_masses(b)
    return b


def build_friction(v):
    """Sample, drives and dynamics of the friction scene (``v``: parsed parameters)."""
    _check_coefficients(v)
    mats = [get_material(v.material), get_material(v.material_top)]
    if v.method == "explicit":
        mats = [m.replace(extra={**m.extra, "mu": v.mu1}) for m in mats]
    d = v.d
    pbc = (True, False, False)
    explicit = v.method == "explicit"
    lo = _block(mats[0], mats, 0, d, v.size, pbc, "top" if explicit else None, v.steps_w)
    up = _block(mats[1], mats, 1, d, v.size, pbc, "bottom" if explicit else None, v.steps_w)
    atoms = stack_blocks([lo, up])
    st = atoms.calc.state
    y = atoms.positions[:, 1]
    body = atoms.arrays["body"]
    bottom = np.nonzero((body == 0) & np.isclose(y, y[body == 0].min()))[0]
    top = np.nonzero((body == 1) & np.isclose(y, y[body == 1].max()))[0]
    from ..mca.dynamics import default_timestep
    dt = default_timestep(atoms, st.materials)
    T = v.steps * dt
    t1, t2 = v.ramp * T, 2 * v.ramp * T
    hold = Piston(bottom, 0.0)
    tr = Traction(top, normal=(0.0, 1.0, 0.0), stress=Table([0.0, t1, T], [0.0, v.stress, v.stress]),
                  velocity=Table([0.0, t1, t2, T], [0.0, 0.0, v.V, v.V]), tangent=(1.0, 0.0, 0.0))
    atoms.set_constraint([hold, tr])
    contact = None
    if not explicit:
        contact = SegmentContact(mu0=v.mu0 * MU0_UNIT, mu1=v.mu1, K_av=v.K_av, A1=v.A1, l1=v.l1,
                                 d1=v.d1, A2=v.A2, l2=v.l2, d2=v.d2, v_reg=v.v_reg,
                                 seed=v.seed)
    else:
        st.flags["contacts"] = True
    dyn = MCADynamics(atoms, dt, damping=v.damping, hold_layer_rotation=True, contact=contact,
                      contact_every=5 if explicit else 25)
    if explicit:
        dyn._contacts()           # the touching pairs across the interface from the start
        dyn._evaluate(commit=False)
    info = {"t_slide": float(t2), "T": float(T), "area": float(atoms.cell[0, 0]) * 1.0,
            "top": top, "bottom": bottom, "n": len(atoms), "dt": float(dt)}
    return atoms, dyn, info


class FrictionCurve:
    """mu_dr, sliding distance and energy records sampled by :meth:`add` (an analysis frame)."""

    KEYS = ("time", "slide", "mu_dr", "FN", "FN_contacts", "friction_work", "damping_work", "drive_work",
            "contacts", "mean_K", "clips", "energy")

    def __init__(self, area):
        self.area = float(area)
        self.x0 = None
        self.rec = {k: [] for k in self.KEYS}

    def add(self, dyn):
        tr = [c for c in dyn.atoms.constraints if isinstance(c, Traction)][0]
        t = float(dyn.state.time)
        s = tr.stress_at(t)
        FN = s * self.area
        x = float(dyn.atoms.positions[tr.index, 0].mean())
        if self.x0 is None:
            self.x0 = x
        Fdr = -float(tr.friction[0])
        c = dyn.contact
        r = self.rec
        r["time"].append(t)
        r["slide"].append(x - self.x0)
        r["mu_dr"].append(Fdr / FN if FN > 0 else float("nan"))
        r["FN"].append(FN)
        summ = c.summary() if c is not None else {}
        r["FN_contacts"].append(summ.get("sum_FN", float("nan")))
        r["friction_work"].append(summ.get("friction_work", 0.0))
        r["damping_work"].append(float(dyn.dissipated))
        r["drive_work"].append(float(sum(float(d.work) for d in dyn.atoms.constraints if hasattr(d, "work"))))
        r["contacts"].append(float(summ.get("contacts", 0)))
        r["mean_K"].append(summ.get("mean_K", float("nan")))
        r["clips"].append(float(summ.get("clips", 0)))
        r["energy"].append(float(dyn.total_energy()))

    def get_state(self):
        return {"x0": self.x0 if self.x0 is not None else float("nan"), **{k: list(v) for k, v in self.rec.items()}}

    def set_state(self, d):
        self.x0 = float(d["x0"])
        if math.isnan(self.x0):
            self.x0 = None
        self.rec = {k: list(map(float, d[k])) for k in self.KEYS}

    def arrays(self):
        return {k: np.array(v, float) for k, v in self.rec.items()}


def steady_mu(curve, t_slide, T):
    """(mean, standard deviation, samples) of mu_dr over the second half of the sliding."""
    t = np.asarray(curve["time"])
    mu = np.asarray(curve["mu_dr"])
    sel = t >= t_slide + 0.5 * (T - t_slide)
    if not sel.any():                      # a run stopped before its steady window
        return float("nan"), float("nan"), 0
    return float(np.mean(mu[sel])), float(np.std(mu[sel])), int(sel.sum())


class FrictionScene(SceneDef):
    """``mca-friction`` on the lifecycle (module docstring)."""

    name = "mca-friction"
    h5md_stem = "mca_friction"
    instability_hint = ("on the command line the time step is fixed by d; a slower loading is more steps (the "
                        "ramps are fractions of the run), --set steps= above {steps}")
    description = "MCA friction of two blocks: segment method (or explicit roughness), mu_dr vs time"
    params = _params()

    def check(self, v):
        _check_coefficients(v)
        from ..materials import get_material
        mats = [get_material(v.material), get_material(v.material_top)]
        strength = min((m.sigma_c if getattr(m, "sigma_c", None) else m.sigma_y) for m in mats)
        if v.stress >= strength:
            raise InputError("stress", self.given("stress", v.stress), f"a stress below the softer block's "
                             f"compressive or yield strength, {strength / units.GPa:g} GPa")
        vmax = 0.01 * min(math.sqrt(m.E / m.rho0) for m in mats)
        if v.V > vmax:
            raise InputError("V", self.given("V", v.V), f"a speed in (0, {vmax / units.m_s:.4g}] m/s "
                             "(1% of the slower block's bar wave speed sqrt(E/rho): a quasi-static slide)")
        L, H = v.size
        if L < 3:
            raise InputError("size", f"{L}x{H}", "a periodic length of at least 3 automaton sizes")

    def setup(self, v, stage):
        atoms, dyn, info = build_friction(v)
        return atoms, dyn, info

    def attach(self, v, stage, atoms, dyn, info):
        if v.method == "segment" and dyn.contact is None:
            raise InputError("--restart", "a run without segment contact", "a mca-friction checkpoint")
        curve = FrictionCurve(info["area"])
        return Stage(stage, atoms, dyn, v.steps, v.frames, info, on_frame=curve.add, analysis=curve)

    def finish(self, v, stage):
        c = stage.dyn.contact
        return {"curve": stage.analysis.get_state(), "t_slide": stage.info["t_slide"], "T": stage.info["T"],
                "n": int(stage.info["n"]), "dt": float(stage.info["dt"]), "t_run": stage.t_run,
                "summary": c.summary() if c is not None else {}}

    def analyse(self, v, summaries):
        sm = summaries[0]
        mu, sd, ns = steady_mu(sm["curve"], sm["t_slide"], sm["T"])
        ref = v.mu1 + v.K_av if v.method == "segment" else None
        cur = sm["curve"]
        q = {
            "mu_dr": Quantity(mu, "", reference=ref, spread=sd,
                              note=f"mean over the second half of the sliding ({ns} samples); reference mu1 + K_av"),
            "mu_dr_std": Quantity(sd, "", note="standard deviation of mu_dr over the same samples"),
            "sliding_distance": Quantity(cur["slide"][-1] / units.um, "um"),
            "friction_work": Quantity(cur["friction_work"][-1] * JM, "J/m",
                                      note="work of the segment friction law, per metre of thickness"),
            "damping_work": Quantity(cur["damping_work"][-1] * JM, "J/m"),
            "drive_work": Quantity(cur["drive_work"][-1] * JM, "J/m"),
        }
        s = sm["summary"]
        if s:
            q["contacts"] = Quantity(float(s["contacts"]), "", note="segment contacts at the end")
            q["K_mu_clips"] = Quantity(float(s["clips"]), "", note="contact-steps with K_mu clipped at 0")
        notes = [f"{sm['n']} automata, dt = {sm['dt'] / units.ns:.4g} ns, method {v.method}"]
        return q, notes, {"stepping_time_s": sm["t_run"], "n_automata": sm["n"]}

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        c = {k: np.asarray(x, float) for k, x in sm["curve"].items() if isinstance(x, list)}
        path = out / "mca_friction_mu.csv"
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["time_ns", "sliding_um", "mu_dr", "FN_N_per_A", "contacts", "mean_K_mu", "K_mu_clips",
                        "friction_work_J_per_m", "damping_work_J_per_m", "drive_work_J_per_m"])
            for row in zip(c["time"] / units.ns, c["slide"] / units.um, c["mu_dr"], c["FN"] / units.N,
                           c["contacts"], c["mean_K"], c["clips"], c["friction_work"] * JM,
                           c["damping_work"] * JM, c["drive_work"] * JM):
                w.writerow(row)
        png = friction_plot(c, v, out / "mca_friction_mu.png", sm["t_slide"])
        return [path, png]


def friction_plot(c, v, path, t_slide):
    """mu_dr against time and against sliding distance (two panels); the PNG's path."""
    from .common import matplotlib_agg
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 2, figsize=(9, 3.5))
    sel = c["time"] >= t_slide
    axs[0].plot(c["time"] / units.ns, c["mu_dr"], lw=1)
    axs[0].set_xlabel("time (ns)")
    axs[1].plot(c["slide"][sel] / units.um, c["mu_dr"][sel], lw=1)
    axs[1].set_xlabel("sliding distance (um)")
    for ax in axs:
        ax.set_ylabel("mu_dr = F_dr / F_N")
        if v.method == "segment":
            ax.axhline(v.mu1 + v.K_av, color="k", ls="--", lw=0.8, label="mu1 + K_av")
            ax.legend()
    fig.suptitle(f"MCA friction ({v.method}): V = {v.V / units.m_s:g} m/s, "
                 f"stress = {v.stress / units.GPa * 1e3:g} MPa")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


register_scene(FrictionScene())
