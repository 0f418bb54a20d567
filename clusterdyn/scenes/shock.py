"""Scene ``shock``: a CD piston shock in a block of clusters (the README's main job).

A block of clusters, a crystal direction along x, periodic across, is driven
by a piston (a layer of clusters moving at u).  The front is tracked in
slabs; D comes from a straight-line fit of the front position against time,
and the state behind the front (u, rho, longitudinal stress P) from the slabs
between piston and front.  They are compared with the material's
experimental Hugoniot (Al: Al-1100, D = 5.392 + 1.341 u km/s).
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from .. import units
from ..analysis.shock import ShockTracker
from ..build import fcc_packing, repeat_lengths
from ..build.two_phase import rest_volumes, two_phase
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError, InstabilityError
from ..io.checkpoint import load_run
from ..materials import get_material, hugoniot
from ..md import DampedVerlet, default_timestep
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, SceneResult, register
from .common import make_piston, matplotlib_agg, run_frames, thermal_noise

CD_MATERIALS = ("Al", "Pb", "B4C", "h-BN")

PARAMS = [
    Param("material", "Al", "material of the block", kind="choice", choices=CD_MATERIALS),
    Param("u", 3.0, "piston speed", unit="km/s", low=0.0, high=20.0, low_open=True),
    Param("direction", "100", "crystal direction along the shock (x)", kind="choice",
          choices=("100", "110", "111")),
    Param("size", (100, 8, 8), "repeat cells along x, y, z (x = shock direction)", kind="ints"),
    Param("r0", 5.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("rc", 1.15, "cutoff as a multiple of r0", low=1.0, high=1.414, low_open=True),
    Param("J", None, "damping Gamma = c0/(J r0); none = off (shock Hugoniots run undamped)",
          low=0.0, low_open=True, optional=True),
    Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
    Param("seed", 1, "random seed of the initial noise", kind="int", low=0),
    Param("dt_factor", TIMESTEP_FACTOR, "time step as a fraction of r0/(c0 + u) (of r0/(c_s/2 + u) for "
          "stiff cold curves, c_s the sound speed at the shock's compression)", low=0.0,
          high=0.5, low_open=True),
    Param("frames", 60, "profiles recorded over the run", kind="int", low=5),
    Param("h5md", True, "write an H5MD trajectory (with --out)", kind="bool"),
    Param("h5md_frames", 20, "trajectory frames written to the H5MD file", kind="int", low=1),
    Param("checkpoint_every", 10, "frames between checkpoints (with --out; 0 = none)", kind="int", low=0),
    Param("dt_retries", 2, "times the run starts again with half the time step when the dynamics' "
          "stiffness check stops it (0: stop with InstabilityError)", kind="int", low=0),
    Param("attraction", "all", "'initial': only pairs bonded at set-up attract, later contacts only repel "
          "(remedy for the soft response near 2 km/s, physics.md 1.5)", kind="choice",
          choices=("all", "initial")),
    Param("inclusion", None, "material of spherical inclusions (two-phase sample; 'material' is the "
          "matrix)", kind="choice", choices=CD_MATERIALS, optional=True),
    Param("inclusion_fraction", 0.28, "mass fraction of the inclusions", low=0.0, high=1.0, low_open=True),
    Param("inclusion_diameter", 56.0, "diameter of the inclusions", unit="um", low=0.0, low_open=True),
]


@dataclass
class ShockSetup:
    atoms: object
    calc: object
    dyn: object
    piston: object
    piston_mask: object
    nsteps: int
    slab: float
    length: float
    material: object
    u: float
    rest_volume: object = None      #: (N,) volume of each cluster at rest (two-phase samples)
    rho0: float = None              #: mean density at rest (default material.rho0)
    two_phase: dict = None          #: atoms.info['two_phase'] of a two-phase sample


#: the time step follows r0/(c0 + u) until the sound speed at the shock's compression exceeds
#: STIFF_SLACK * c0; beyond, r0/(c_s/STIFF_SLACK + u) (physics.md 3: dt ~ r0/c_max)
STIFF_SLACK = 2.0


def cold_shock_state(material, u):
    """Compression and sound speed where the cold curve meets the Rayleigh line of ``u``.

    ``P_x(delta) = rho0 D u`` with ``delta = D/(D - u)``, i.e.
    ``u^2 = P_x(delta) (1 - 1/delta) / rho0``; the sound speed is
    ``c_s = sqrt(P_x'(delta) / rho0)``.  A cold estimate of the shocked state
    (no thermal pressure), used to size the time step.

    Returns
    -------
    (delta, c_s) with c_s in ASE units.
    """
    from scipy.optimize import brentq
    mat = get_material(material)
    c = mat.curve
    if not u > 0:
        return 1.0, mat.c0

    def f(d):
        return math.sqrt(max(c.pressure(d), 0.0) * (1.0 - 1.0 / d) / mat.rho0) - u
    hi = 1.5
    while f(hi) < 0 and hi < 1e3:
        hi *= 1.5
    d = brentq(f, 1.0 + 1e-12, hi, xtol=1e-12)
    return d, math.sqrt(c.dpressure(d) / mat.rho0)


def _compression_at(material, P):
    """Compression where the cold curve reaches pressure ``P`` (ASE units)."""
    from scipy.optimize import brentq
    c = get_material(material).curve
    hi = 1.5
    while c.pressure(hi) < P and hi < 1e3:
        hi *= 1.5
    return brentq(lambda d: c.pressure(d) - P, 1.0, hi, xtol=1e-12)


def shock_timestep(calc, u, dt_factor=TIMESTEP_FACTOR):
    """Time step of a shock at piston speed ``u``: ``dt_factor * min r0/(c_eff + u)`` over the materials.

    One material: ``c_eff = max(c0, c_s/STIFF_SLACK)`` with ``c_s`` the sound
    speed at the cold shock compression (:func:`cold_shock_state`).  This is
    :func:`clusterdyn.md.default_timestep`'s ``r0/(c0 + u)`` for B4C at any u,
    aluminium up to 4 km/s and lead up to 2 km/s; it is 7% smaller for
    aluminium at 6-8 km/s, 7-17% for lead at 3-8 km/s and 13-54% for h-BN
    (n = 10.4: c_s = 8 c0 at 6 km/s) at 1-8 km/s, where ``r0/(c0 + u)``
    leaves no margin below the limit ``clusterdyn study stability`` measures.

    Several materials: each phase may be driven to the highest cold shock
    pressure of any phase at ``u`` (a soft matrix squeezed against stiff
    inclusions), and interfaces focus the compression, so ``c_eff =
    max(c0, c_s)`` with ``c_s`` at that pressure on the phase's own cold curve
    (h-BN with B4C spheres at 3 km/s: closest pairs at 0.75 r0 in the matrix).
    """
    states = [cold_shock_state(p.material, u) for p in calc.potentials]
    if len(calc.potentials) == 1:
        p = calc.potentials[0]
        return dt_factor * p.r0 / (max(p.c0, states[0][1] / STIFF_SLACK) + u)
    P_max = max(p.material.curve.pressure(d) for p, (d, _) in zip(calc.potentials, states))
    dt = math.inf
    for p in calc.potentials:
        d = _compression_at(p.material, P_max) if P_max > 0 else 1.0
        cs = math.sqrt(p.material.curve.dpressure(d) / p.material.rho0)
        dt = min(dt, dt_factor * p.r0 / (max(p.c0, cs) + u))
    return dt


def _d_guess(name, u, c0):
    try:
        return hugoniot(name).D(u)
    except InputError:
        return c0 * math.sqrt(1.5) + 1.3 * u


def build_shock(material="Al", u=3 * units.km_s, direction="100", size=(100, 8, 8), r0=5 * units.um,
                rc=1.15, J=None, noise=10 * units.m_s, seed=1, dt_factor=TIMESTEP_FACTOR,
                run_fraction=0.8, attraction="all", inclusion=None, inclusion_fraction=0.28,
                inclusion_diameter=56 * units.um, r0_inclusion=None):
    """Sample, calculator, piston and dynamics of a piston shock (ASE units).

    ``attraction="initial"`` marks the set-up bonds (before the noise) and
    lets only them attract.  With ``inclusion`` the sample is two-phase
    (:func:`clusterdyn.build.two_phase`: ``material`` is the matrix,
    ``inclusion_fraction`` the inclusions' mass fraction, placement seeded by
    ``seed``).  The time step is :func:`shock_timestep`
    (``dt_factor * r0/(c0 + u)`` but for stiff cold curves).
    """
    mat = get_material(material)
    if mat.curve is None:
        raise InputError("material", material, "a material with a cold curve: " + ", ".join(CD_MATERIALS))
    if not u > 0:
        raise InputError("u", u, "a positive piston speed")
    if attraction not in ("all", "initial"):
        raise InputError("attraction", attraction, "'all' or 'initial'")
    info = None
    if inclusion in (None, "none"):
        atoms = fcc_packing(mat, r0, size=size, direction=direction, pbc=(False, True, True))
    else:
        atoms = two_phase(mat, inclusion, inclusion_fraction, inclusion_diameter, r0=r0, size=size,
                          direction=direction, pbc=(False, True, True), seed=seed, r0_inclusion=r0_inclusion)
        info = atoms.info["two_phase"]
    calc = ClusterDynamics(rc=rc, attraction=attraction)
    if attraction == "initial":
        mark_initial_bonds(atoms, rc)
    atoms.calc = calc
    calc.setup(atoms)
    pot = calc.potentials[0]
    # piston: the first 1.5 r0 (at least two atomic planes in every orientation)
    mask, piston = make_piston(atoms, 1.5 * r0 - 1e-6 * r0, u)
    thermal_noise(atoms, noise, seed, exclude=mask)
    atoms.set_constraint(piston)
    atoms.set_momenta(atoms.get_momenta())            # applies the piston velocity
    dt = shock_timestep(calc, u, dt_factor)
    dyn = DampedVerlet(atoms, timestep=dt, J=J)
    length = atoms.positions[:, 0].max() - atoms.positions[:, 0].min()
    vrest = rest_volumes(atoms)
    rho0 = float(atoms.get_masses().sum() / vrest.sum())
    if info is None:
        d_guess = _d_guess(mat.name, u, pot.c0)
    else:   # the equal-u mixture rule on rough phase Hugoniots; the slower phase sets the run time
        phi = info["volume_fraction"]
        d_guess = 1.0 / ((1 - phi) / _d_guess(mat.name, u, pot.c0)
                         + phi / _d_guess(calc.potentials[1].material.name, u, calc.potentials[1].c0))
    t_end = run_fraction * length / d_guess
    nsteps = int(math.ceil(t_end / dt))
    # slab width: one repeat length along x for [100] (two planes), at least r0
    slab = max(float(repeat_lengths(direction, r0)[0]), r0)
    return ShockSetup(atoms, calc, dyn, piston, mask, nsteps, slab, length, mat, u, vrest, rho0, info)


def run_shock(setup, frames=60, progress=True, on_frame=None, desc="shock", checkpoint=None,
              checkpoint_every=0, tracker=None, params=None):
    """Run a built shock, tracking the front; returns (ShockTracker, ShockState, stepping wall time).

    With ``checkpoint`` the state (and the tracker's frames) is saved every
    ``checkpoint_every`` frames; pass the restored ``tracker`` to resume.
    """
    atoms, calc = setup.atoms, setup.calc
    if tracker is None:
        x0 = atoms.positions[~setup.piston_mask, 0].min()
        rho0 = setup.material.rho0 if setup.rho0 is None else setup.rho0
        tracker = ShockTracker(rho0, setup.u, setup.slab, axis=0, lo=x0,
                               hi=x0 + setup.length + setup.slab, rest_volume=setup.rest_volume)

    def frame(dyn):
        out = calc.compute(atoms, per_particle=True)
        pist = atoms.positions[setup.piston_mask, 0].max()
        tracker.add(dyn.get_time(), atoms, out["virials"], pist, exclude=setup.piston_mask)
        if on_frame is not None:
            on_frame(dyn)

    def extra():
        return {"tracker": tracker.get_state(), "params": params or {}, "nsteps_total": setup.nsteps,
                "slab": setup.slab, "length": setup.length}

    t_run = run_frames(setup.dyn, setup.nsteps, frames, frame, progress=progress, desc=desc,
                       checkpoint=checkpoint, checkpoint_every=checkpoint_every, get_extra=extra)
    return tracker, tracker.result(), t_run


def restore_shock(path):
    """Rebuild a ShockSetup and its tracker from a shock checkpoint."""
    atoms, dyn, extra = load_run(path)
    try:
        p = extra["params"]
        tracker = ShockTracker.from_state(extra["tracker"])
    except (KeyError, TypeError):
        raise InputError("--restart", str(path), "a checkpoint written by the shock scene") from None
    piston = atoms.constraints[0]
    mask = np.zeros(len(atoms), bool)
    mask[piston.index] = True
    setup = ShockSetup(atoms, atoms.calc, dyn, piston, mask, int(extra["nsteps_total"]),
                       float(extra["slab"]), float(extra["length"]), get_material(p["material"]),
                       float(np.linalg.norm(piston.velocity)))
    return setup, tracker, p


def plot_shock(tracker, state, path, title=""):
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 3, figsize=(14, 4.2))
    t = np.array([f["t"] for f in tracker.frames]) / units.ns
    xf = np.array([f["front"] for f in tracker.frames]) / units.um
    xp = np.array([f["piston"] for f in tracker.frames]) / units.um
    axs[0].plot(t, xf, "o", ms=3, label="front")
    axs[0].plot(t, xp, "-", label="piston")
    if np.isfinite(state.D_fit):
        tt = np.linspace(t.min(), t.max(), 10)
        # refit line for display
        ok = np.isfinite(xf)
        A = np.polyfit(t[ok], xf[ok], 1)
        axs[0].plot(tt, np.polyval(A, tt), "k--", lw=0.8,
                    label=f"D = {state.D_fit / units.km_s:.3f} km/s")
    axs[0].set_xlabel("t (ns)")
    axs[0].set_ylabel("x (um)")
    axs[0].legend()
    axs[0].set_title("x-t diagram")
    for f in tracker.frames[:: max(1, len(tracker.frames) // 6)]:
        p = f["profile"]
        axs[1].plot(p["x"] / units.um, p["velocity"][:, 0] / units.km_s, lw=1)
        axs[2].plot(p["x"] / units.um, -p["stress"][:, 0] / units.GPa, lw=1)
    axs[1].set_xlabel("x (um)")
    axs[1].set_ylabel("particle velocity u_x (km/s)")
    axs[2].set_xlabel("x (um)")
    axs[2].set_ylabel("longitudinal stress -sigma_xx (GPa)")
    axs[1].set_title("velocity profiles")
    axs[2].set_title("stress profiles")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def shock_quantities(state, mat, u, reference=True):
    """Quantities of a shock state against the experimental Hugoniot (if the material has one).

    Besides D, u, P and rho against the experiment: ``D_mass`` (mass
    conservation) against the fitted D, ``P_momentum`` (rho0 D u) against the
    measured ``-sigma_xx``, and the von Mises intensity ``sigma_u`` behind the
    front.  ``reference=False`` (two-phase samples) compares with nothing.
    """
    ref = None
    if reference:
        try:
            ref = hugoniot(mat.name)
        except InputError:
            pass
    refD = ref.D(u) / units.km_s if ref else None
    rho0_ref = ref.rho0_g_cm3 if ref else None
    q = {
        "D": Quantity(state.D_fit / units.km_s, "km/s", refD, spread=state.D_fit_err / units.km_s,
                      note=f"front position fit, rms residual {state.fit_rms / state.width:.3f} slabs"
                      if np.isfinite(state.width) else "front position fit"),
        "u": Quantity(state.u / units.km_s, "km/s", u / units.km_s, spread=state.u_spread / units.km_s,
                      note="mean particle velocity behind the front vs piston"),
        "P": Quantity(state.P / units.GPa, "GPa",
                      (rho0_ref * units.g_cm3 * ref.D(u) * u / units.GPa) if ref else None,
                      spread=state.P_spread / units.GPa, note="-sigma_xx behind the front"),
        "rho": Quantity(state.rho / units.g_cm3, "g/cm3",
                        (ref.density(u) / units.g_cm3) if ref else None,
                        spread=state.rho_spread / units.g_cm3, note="from the Lagrangian compression dx/dX"),
        "D_mass": Quantity(state.D_mass / units.km_s, "km/s", state.D_fit / units.km_s,
                           spread=state.D_mass_spread / units.km_s,
                           note="u/(1 - rho0/rho) (mass conservation) vs the fitted D"),
        "P_momentum": Quantity(state.P_momentum / units.GPa, "GPa", state.P / units.GPa,
                               note="rho0 D u (momentum conservation) vs the measured -sigma_xx"),
        "sigma_u": Quantity(state.sigma_u / units.GPa, "GPa", spread=state.sigma_u_spread / units.GPa,
                            note="von Mises intensity (CD eq. 4) behind the front"),
    }
    return q, ref


def _shock_attempt(v, dt_factor, out, progress, restart):
    """Build (or restore) and run one shock; returns (setup, tracker, state, t_run, files, v)."""
    tracker = None
    if restart is not None:
        setup, tracker, stored = restore_shock(restart)
        v = {**v, **{k: (tuple(x) if isinstance(x, list) else x) for k, x in stored.items()}}
    else:
        setup = build_shock(v["material"], v["u"], v["direction"], v["size"], v["r0"], v["rc"], v["J"],
                            v["noise"], v["seed"], dt_factor, attraction=v.get("attraction", "all"),
                            inclusion=v.get("inclusion"),
                            inclusion_fraction=v.get("inclusion_fraction", 0.28),
                            inclusion_diameter=v.get("inclusion_diameter", 56 * units.um))
    writer = None
    files = []
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)       # checkpoints go there even without H5MD
    if out is not None and v["h5md"]:
        try:
            from ..io import H5MDWriter
        except ImportError:
            H5MDWriter = None
        if H5MDWriter is not None:
            path = out / "shock.h5md"
            # the reaction of the sample on the piston (x component), and the pressure it implies
            area = setup.atoms.cell[1, 1] * setup.atoms.cell[2, 2]
            obs = {"piston_force": (lambda a: -setup.piston.force[0] / units.N, "N"),
                   "piston_pressure": (lambda a: -setup.piston.force[0] / area / units.GPa, "GPa")}
            if restart is not None and path.exists():
                writer = H5MDWriter(str(path), setup.atoms, mode="a", dyn=setup.dyn, parameters=v,
                                    restart_step=setup.dyn.nsteps, observables=obs)
            else:
                writer = H5MDWriter(str(path), setup.atoms, dyn=setup.dyn, parameters=v, observables=obs)
            setup.dyn.attach(writer, interval=max(1, setup.nsteps // v["h5md_frames"]))
            files.append(path)
    try:
        ckpt = (out / "checkpoint.h5") if (out is not None and v["checkpoint_every"]) else None
        tracker, state, t_run = run_shock(setup, v["frames"], progress, checkpoint=ckpt,
                                          checkpoint_every=v["checkpoint_every"], tracker=tracker,
                                          params=v)
    finally:
        if writer is not None:
            writer.close()
    return setup, tracker, state, t_run, files, v


@register("shock", "CD piston shock in a block of clusters; D, u, P, rho vs the experimental Hugoniot",
          PARAMS)
def shock_scene(v, out=None, progress=True, restart=None):
    t0 = time.perf_counter()
    retried = []
    factor = v["dt_factor"]
    attempts = 1 if restart is not None else 1 + int(v.get("dt_retries", 0))
    for attempt in range(attempts):
        try:
            setup, tracker, state, t_run, files, v = _shock_attempt(v, factor, out, progress, restart)
            break
        except InstabilityError as exc:
            if exc.quantity != "timestep" or attempt == attempts - 1:
                raise
            retried.append(f"dt factor {factor:g}: stopped at step {exc.step} by the stiffness check "
                           f"(closest pair {exc.particles}, timestep {exc.value:.4g} > limit {exc.limit:.4g})")
            factor *= 0.5
    two = setup.two_phase
    q, ref = shock_quantities(state, setup.material, setup.u, reference=two is None)
    n = len(setup.atoms)
    pot = setup.calc.potentials[0]
    notes = list(state.notes)
    for r in retried:
        notes.append(f"time step halved after a stop: {r}")
    notes.append(f"{n} clusters, {setup.nsteps} steps of {setup.dyn.dt / (pot.r0 / pot.c0):.4f} r0/c0, "
                 f"{n * setup.nsteps / max(t_run, 1e-9):.3g} particle-steps/s, "
                 f"{setup.calc.nl.nbuilds} neighbour-list builds")
    notes.append(f"front fit: rms residual {state.fit_rms / units.um:.3g} um = {state.fit_rms / state.width:.3f} "
                 f"slabs; D over the two halves of the fit {state.D_halves[0] / units.km_s:.4g}, "
                 f"{state.D_halves[1] / units.km_s:.4g} km/s")
    if ref is not None:
        notes.append(f"reference: {ref.name} Hugoniot, {ref.source}")
    if two is not None:
        notes.append(f"two-phase: {two['matrix']} matrix with {two['n_spheres']} {two['inclusion']} spheres, "
                     f"inclusion mass fraction {two['mass_fraction']:.4f} (target {two['mass_fraction_target']:g}), "
                     f"volume fraction {two['volume_fraction']:.4f}; no experimental reference")
    extra = {"steady": state.steady, "steady_reasons": list(state.steady_reasons),
             "fit_rms_um": state.fit_rms / units.um, "fit_rms_slabs": state.fit_rms / state.width,
             "D_halves_km_s": [h / units.km_s for h in state.D_halves],
             "mass_check": state.mass_check, "momentum_check": state.momentum_check,
             "ejecta_fraction": state.ejecta,
             "rho_bins_g_cm3": state.rho_bins / units.g_cm3, "rho0_g_cm3": setup.rho0 / units.g_cm3
             if setup.rho0 else setup.material.rho0 / units.g_cm3,
             "n_particles": n, "n_steps": setup.nsteps, "particle_steps": n * setup.nsteps,
             "timestep_r0_c0": setup.dyn.dt / (pot.r0 / pot.c0), "dt_factor_used": factor,
             "dt_retries_used": len(retried),
             "stepping_time_s": t_run,
             "particle_steps_per_s": n * setup.nsteps / max(t_run, 1e-9)}
    if two is not None:
        extra["two_phase"] = {k: v_ for k, v_ in two.items() if k not in ("centres", "diameters")}
        extra["two_phase"]["rho0"] = two["rho0"] / units.g_cm3
    res = SceneResult("shock", q, time.perf_counter() - t0, files=files, notes=notes, extra=extra)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        png = out / "shock.png"
        plot_shock(tracker, state, png, f"{setup.material.name} [{v['direction']}] u = "
                   f"{setup.u / units.km_s:g} km/s")
        files.append(png)
        import csv
        with open(out / "shock_front.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_ns", "front_um", "piston_um"])
            for f in tracker.frames:
                w.writerow([f["t"] / units.ns, f["front"] / units.um, f["piston"] / units.um])
        files.append(out / "shock_front.csv")
    res.wall_time_s = time.perf_counter() - t0
    return res
