"""Scene ``shock``: a CD piston shock in a block of clusters (the README's main job).

A block of clusters, a crystal direction along x, periodic across, is driven
by a piston (a layer of clusters moving at u).  The front is tracked in
slabs; D comes from a straight-line fit of the front position against time,
and the state behind the front (u, rho, longitudinal stress P) from the slabs
between piston and front.  They are compared with the material's
experimental Hugoniot (Al: Al-1100, D = 5.392 + 1.341 u km/s).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from .. import units
from ..analysis.shock import ShockTracker
from ..analysis.stress import add_piece_virials
from ..build import along_axis, fcc_packing, parse_axis, repeat_lengths
from ..build.lattice import lattice_sound_speed
from ..build.two_phase import rest_volumes, two_phase
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError
from ..materials import cd_material_names, get_material, hugoniot
from ..md import DampedVerlet
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, register_scene
from ..md.histories import Table
from ..md.layer_drives import Piston
from .common import make_piston, matplotlib_agg, piston_layer, piston_thickness, run_frames, thermal_noise
from .lifecycle import LIVE, SceneDef, Setup, Stage, scene_params

#: the library materials with a cold curve (materials registered later are not in the choice list)
CD_MATERIALS = tuple(cd_material_names())

#: ``size=auto`` and ``fit_from=auto`` against the piston speed, measured on aluminium [100] (damping
#: off, 10 m/s noise, 6x6 cells across; ``benchmarks/shock_length.py`` (as of commit f17d607) replays long runs cut to
#: shorter lengths, docs/hugoniot.md "Steady at the defaults").  Rows: u (km/s), the front travel
#: (in [100] repeat cells, sqrt(2) r0 each) after which the start-up transient is over (the front
#: starts overdriven, relaxes, and settles there) and the fit window starts, and the sample length
#: (repeat cells): at least 1.2 times the shortest length that is steady with that window, chosen where
#: every longer cut was steady too.  Linear in u between rows; the last row is the top of the u range.
AUTO_RULE = (
    (0.5, 30, 100),
    (1.0, 30, 100),
    (1.5, 70, 300),
    (2.0, 70, 300),
    (3.0, 50, 120),
    (4.0, 50, 150),
    (5.0, 60, 160),
    (6.0, 70, 180),
    (7.0, 60, 160),
    (8.0, 40, 120),
    (10.0, 50, 140),
)
#: length of the rule's cells: the [100] repeat cell, sqrt(2) r0
AUTO_CELL_R0 = math.sqrt(2.0)
#: width of the ``auto`` cross-section: 6 repeat cells along [100] (6 sqrt(2) r0), whatever the direction
AUTO_WIDTH_R0 = 6 * AUTO_CELL_R0
#: top of the u range (km/s): the last row of AUTO_RULE, the fastest piston whose steady length was measured
U_MAX = AUTO_RULE[-1][0]


class SampleSize(Param):
    """The ``size`` parameter: ``auto`` (length and cross-section from u, :func:`shock_size`),
    ``autoxNYxNZ`` (length from u, cross-section given) or ``NXxNYxNZ`` repeat cells."""

    def __init__(self, doc):
        super().__init__("size", "auto", doc, kind="ints")

    def describe(self):
        return f"{self.name} = auto  -- {self.doc}"

    def _allowed(self):
        return "auto, autoxNYxNZ or NXxNYxNZ repeat cells (integers >= 1) like 120x6x6"

    def parse(self, value):
        if isinstance(value, str) and value.strip().lower().startswith("auto"):
            rest = value.strip().lower()[4:].strip("x, ")
            if not rest:
                return "auto"
            try:
                ny, nz = (int(x) for x in rest.replace(",", "x").split("x"))
            except ValueError:
                raise InputError(self.name, value, self._allowed()) from None
            if ny < 1 or nz < 1:
                raise InputError(self.name, value, self._allowed())
            return f"autox{ny}x{nz}"
        try:
            return Param(self.name, (1, 1, 1), self.doc, kind="ints").parse(value)
        except InputError:
            raise InputError(self.name, value, self._allowed()) from None


class AutoNumber(Param):
    """A plain number (>= 0) or ``auto``."""

    def describe(self):
        return f"{self.name} = auto  -- {self.doc}"

    def parse(self, value):
        if isinstance(value, str) and value.strip().lower() == "auto":
            return "auto"
        try:
            return Param(self.name, 0.0, self.doc, low=0.0).parse(value)
        except InputError:
            raise InputError(self.name, value, "auto or a number >= 0") from None


def _rule(u_km_s):
    """(transient, length) in r0 at ``u_km_s`` (AUTO_RULE, linear in u, constant beyond its ends)."""
    rows = np.array(AUTO_RULE, float)
    return (AUTO_CELL_R0 * float(np.interp(u_km_s, rows[:, 0], rows[:, 1])),
            AUTO_CELL_R0 * float(np.interp(u_km_s, rows[:, 0], rows[:, 2])))


def shock_size(u, size="auto", direction="100", fit_from="auto", r0=1.0, min_width=0.0):
    """Sample size and fit-window start of a shock at piston speed ``u`` (ASE units).

    ``size="auto"``: the sample length along the shock from :data:`AUTO_RULE`
    (measured on aluminium: the shortest sample that is steady at u, with a
    margin), rounded up to whole repeat cells, and a cross-section of at least
    :data:`AUTO_WIDTH_R0` and of ``min_width`` (in r0: two-phase samples ask
    for two inclusion diameters, so that an inclusion sits in a cross-section
    of its own size and more); ``"autoxNYxNZ"`` keeps the given cross-section; a
    tuple ``(nx, ny, nz)`` is used as given.  ``fit_from="auto"``: the front
    travel after which the fit window starts (the end of the start-up
    transient, :data:`AUTO_RULE`); a number is that travel in r0 (0: the window
    is the fraction window of :meth:`ShockTracker.result` alone).

    Returns
    -------
    ((nx, ny, nz), fit_from) with ``fit_from`` in the units of ``r0``.
    """
    uk = u / units.km_s
    transient, length = _rule(min(uk, U_MAX))
    rep = repeat_lengths(direction, 1.0)
    if isinstance(size, str):
        if size == "auto":
            across = tuple(int(math.ceil(max(AUTO_WIDTH_R0, min_width) / rep[k] - 1e-9)) for k in (1, 2))
        else:
            across = tuple(int(x) for x in size[5:].split("x"))
        size = (int(math.ceil(length / rep[0] - 1e-9)),) + across
    fit = transient if fit_from == "auto" else float(fit_from)
    return tuple(int(x) for x in size), fit * r0


def inclusion_width(inclusion, inclusion_diameter, r0):
    """The smallest cross-section (in r0) of ``size=auto`` for a sample with ``inclusion`` (None or
    "none": a one-phase sample, 0): two inclusion diameters."""
    return 0.0 if inclusion in (None, "none") else 2.0 * inclusion_diameter / r0


def suggest_size(u, size, direction="100"):
    """A sample size (text ``NXxNYxNZ``) that should make a run of ``size`` at ``u`` steady: the
    ``auto`` length when ``size`` is shorter, else twice the length (same cross-section)."""
    n_auto = shock_size(u, "auto", direction)[0][0]
    nx = n_auto if size[0] < n_auto else 2 * size[0]
    return f"{nx}x{size[1]}x{size[2]}"


PARAMS = [
    Param("material", "Al", "material of the block", kind="choice", choices=CD_MATERIALS),
    Param("u", 3.0, "piston speed (the top of the range is the fastest speed whose steady sample length "
          "was measured, AUTO_RULE)", unit="km/s", low=0.0, high=U_MAX, low_open=True),
    Param("u_history", None, "piston velocity history U(t): a CSV file with a time column (t_ns, t_us, ...) and "
          "a speed column (u_km_s, u_m_s, ...) or a vector (ux_,uy_,uz_), held at its ends; u then sizes the run "
          "(time step, run length, reference) and must be at least the table's largest speed", kind="str",
          optional=True),
    Param("direction", "100", "crystal direction along the shock", kind="choice",
          choices=("100", "110", "111")),
    SampleSize("repeat cells along the shock and across it (the first along the shock); auto: the sample "
               "length that is steady at u (100-300 [100] cells, measured on aluminium; shock_size), 6x6 cells "
               "across (two-phase: at least two inclusion diameters across); autoxNYxNZ: that length with the given cross-section"),
    AutoNumber("fit_from", "auto", "front travel (in r0) before the fit window of D and of the state behind "
               "the front starts; auto: the end of the start-up transient at u (shock_size); 0: from 20% of "
               "the sample"),
    Param("r0", 5.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("rc", 1.15, "cutoff as a multiple of r0", low=1.0, high=1.414, low_open=True),
    Param("J", None, "damping Gamma = c0/(J r0); none = off (shock Hugoniots run undamped)",
          low=0.0, low_open=True, optional=True),
    Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
    Param("seed", 1, "random seed of the initial noise", kind="int", low=0),
    Param("dt_factor", TIMESTEP_FACTOR, "time step as a fraction of r0/(c0 + u) (of r0/(c_s/2 + u) for "
          "stiff cold curves, c_s the sound speed at the shock's compression)", low=0.0,
          high=0.5, low_open=True),
    Param("axis", "x", "shock direction (the sample is free along it and periodic across)", kind="choice",
          choices=("x", "y", "z")),
    Param("frames", 60, "profiles recorded over the run", kind="int", low=5),
    Param("dt_retries", 2, "times the run starts again with half the time step when the dynamics' "
          "stiffness check stops it (0: stop with InstabilityError)", kind="int", low=0),
    Param("attraction", "all", "'initial': only pairs bonded at set-up attract, later contacts only repel "
          "(remedy for the soft response near 2 km/s, docs/theory.md 1.5)", kind="choice",
          choices=("all", "initial")),
    Param("inclusion", None, "material of spherical inclusions (two-phase sample; 'material' is the "
          "matrix)", kind="choice", choices=CD_MATERIALS, optional=True),
    Param("inclusion_fraction", 0.28, "mass fraction of the inclusions", low=0.0, high=1.0, low_open=True),
    Param("inclusion_diameter", 56.0, "diameter of the inclusions", unit="um", low=0.0, low_open=True),
]


@dataclass
class ShockSetup(Setup):
    """A built piston shock (ASE units): the sample and dynamics, and the facts its front tracker
    needs, which are also the checkpoint's payload (:class:`~clusterdyn.scenes.lifecycle.Setup`)."""

    piston_index: np.ndarray = None  #: indices of the piston's clusters
    nsteps: int = 0                  #: steps of the run
    slab: float = 0.0                #: slab width of the profiles
    length: float = 0.0              #: the sample's extent along the shock
    u: float = 0.0                   #: piston speed (the largest of a U(t) history)
    rho0: float = None               #: mean density at rest
    x0: float = 0.0                  #: start of the sample along the shock (the piston left out)
    rest_volume: np.ndarray = None   #: (N,) volume of each cluster at rest
    axis: int = 0                    #: shock direction (0, 1, 2)
    two_phase: dict = None           #: atoms.info['two_phase'] of a two-phase sample
    fit_from: float = None           #: front travel (Angstrom) before the fit window starts
    size: tuple = ()                 #: repeat cells (nx, ny, nz) of the sample (empty: not a repeat block)
    sample: dict = None              #: the builder's report on the sample (polycrystal, relaxation)
    material: object = field(default=None, repr=False, metadata=LIVE)   #: the Material (None when restored)

    @property
    def calc(self):
        return self.atoms.calc

    @property
    def piston_mask(self):
        mask = np.zeros(len(self.atoms), bool)
        mask[np.asarray(self.piston_index, dtype=np.int64)] = True
        return mask

    @property
    def piston(self):
        """The piston drive (the constraint with a ``force``)."""
        return next(c for c in self.atoms.constraints if hasattr(c, "force"))


#: the time step follows r0/(c0 + u) until the sound speed at the shock's compression exceeds
#: STIFF_SLACK * c0; beyond, r0/(c_s/STIFF_SLACK + u) (docs/theory.md 3: dt ~ r0/c_max)
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
        return lattice_sound_speed(c0) + 1.3 * u


def piston_history(u_history, u):
    """The U(t) :class:`~clusterdyn.md.Table` of ``u_history`` (a CSV path or a Table), checked against ``u``.

    ``u`` sizes a shock run (time step, run length, the analysis' reference),
    so a history whose largest speed exceeds it is refused (InputError naming
    ``u_history``)."""
    if isinstance(u_history, Table):
        hist = u_history
    else:
        from .lifecycle import read_history_csv
        hist, _ = read_history_csv("u_history", u_history, kinds=("u",))
    top = hist.max_abs()
    if top > u * (1 + 1e-12):
        raise InputError("u_history", str(u_history), f"a history no faster than u = {u / units.km_s:g} km/s "
                         "(u sizes the time step and the run)",
                         hint=f"its largest speed is {top / units.km_s:g} km/s: set u >= that")
    return hist


def build_shock(material="Al", u=3 * units.km_s, direction="100", size="auto", r0=5 * units.um,
                rc=1.15, J=None, noise=10 * units.m_s, seed=1, dt_factor=TIMESTEP_FACTOR,
                run_fraction=0.8, attraction="all", inclusion=None, inclusion_fraction=0.28,
                inclusion_diameter=56 * units.um, r0_inclusion=None, axis=0, fit_from="auto", u_history=None):
    """Sample, calculator, piston and dynamics of a piston shock (ASE units).

    ``size`` and ``fit_from`` as in :func:`shock_size` (``"auto"``: from u).

    ``attraction="initial"`` marks the set-up bonds (before the noise) and
    lets only them attract.  With ``inclusion`` the sample is two-phase
    (:func:`clusterdyn.build.two_phase`: ``material`` is the matrix,
    ``inclusion_fraction`` the inclusions' mass fraction, placement seeded by
    ``seed``).  The time step is :func:`shock_timestep`
    (``dt_factor * r0/(c0 + u)`` but for stiff cold curves).  ``axis`` (0, 1,
    2 or x, y, z) is the shock direction: the sample is built with
    ``direction`` along x and turned so that x lies along ``axis``
    (:func:`clusterdyn.build.along_axis`); it is free along ``axis`` and periodic across.
    ``u_history`` (a CSV path or a :class:`~clusterdyn.md.Table`, speeds along
    ``axis`` or vectors): the piston follows U(t) (:func:`piston_history`);
    ``u``, at least its largest speed, sizes the time step and the run.
    """
    axis = parse_axis(axis)
    mat = get_material(material)
    if mat.curve is None:
        raise InputError("material", material, "a material with a cold curve: " + ", ".join(CD_MATERIALS))
    if not u > 0:
        raise InputError("u", u, "a positive piston speed")
    size, fit_from = shock_size(u, size, direction, fit_from, r0,
                                min_width=inclusion_width(inclusion, inclusion_diameter, r0))
    if attraction not in ("all", "initial"):
        raise InputError("attraction", attraction, "'all' or 'initial'")
    hist = None if u_history is None else piston_history(u_history, u)
    info = None
    if inclusion in (None, "none"):
        atoms = fcc_packing(mat, r0, size=size, direction=direction, pbc=(False, True, True))
    else:
        atoms = two_phase(mat, inclusion, inclusion_fraction, inclusion_diameter, r0=r0, size=size,
                          direction=direction, pbc=(False, True, True), seed=seed, r0_inclusion=r0_inclusion)
        info = atoms.info["two_phase"]
    along_axis(atoms, axis)
    calc = ClusterDynamics(rc=rc, attraction=attraction)
    if attraction == "initial":
        mark_initial_bonds(atoms, rc)
    atoms.calc = calc
    calc.setup(atoms)
    pot = calc.potentials[0]
    # piston: the first 1.5 r0 (at least two atomic planes in every orientation)
    if hist is None:
        mask, piston = make_piston(atoms, piston_thickness(r0), u, axis)
    else:
        mask = piston_layer(atoms, piston_thickness(r0), axis)
        piston = Piston(mask, hist, direction=np.eye(3)[axis])
    thermal_noise(atoms, noise, seed, exclude=mask)
    atoms.set_constraint(piston)
    atoms.set_momenta(atoms.get_momenta())            # applies the piston velocity
    dt = shock_timestep(calc, u, dt_factor)
    dyn = DampedVerlet(atoms, timestep=dt, J=J)
    length = np.ptp(atoms.positions[:, axis])
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
    return ShockSetup(atoms, dyn, piston_index=np.nonzero(mask)[0], nsteps=nsteps, slab=slab, length=length, u=u,
                      rho0=rho0, x0=float(atoms.positions[~mask, axis].min()), rest_volume=vrest, axis=axis,
                      two_phase=info, fit_from=fit_from, size=size, material=mat)


def run_shock(setup, frames=60, progress=True, on_frame=None, desc="shock", tracker=None):
    """Run a built shock, tracking the front; returns (ShockTracker, ShockState, stepping wall time).

    The library form of the ``shock`` scene's run (no files, no checkpoints: the
    scene's lifecycle adds those).
    """
    if tracker is None:
        tracker = shock_tracker(setup)
    t_run = run_frames(setup.dyn, setup.nsteps, frames, shock_frame(setup, tracker, on_frame), progress=progress,
                       desc=desc)
    return tracker, tracker.result(), t_run


def shock_tracker(setup):
    """The front tracker of a shock set-up, its slabs from the sample's start ``setup.x0`` on."""
    rho0 = setup.material.rho0 if setup.rho0 is None else setup.rho0
    x0 = setup.x0
    return ShockTracker(rho0, setup.u, setup.slab, axis=setup.axis, lo=x0,
                        hi=x0 + setup.length + setup.slab, rest_volume=setup.rest_volume, fit_from=setup.fit_from)


def shock_frame(setup, tracker, on_frame=None):
    """The per-frame call of a shock run: the particles' virials, then one tracker frame (the piston
    left out); ``on_frame(dyn)`` after it."""
    atoms, calc, mask, ax = setup.atoms, setup.calc, setup.piston_mask, setup.axis

    def frame(dyn):
        W = add_piece_virials(calc.compute(atoms, per_particle=True, forces=False)["virials"], dyn)
        tracker.add(dyn.get_time(), atoms, W, atoms.positions[mask, ax].max(), exclude=mask)
        if on_frame is not None:
            on_frame(dyn)
    return frame


def plot_shock(tracker, state, path, title="", u=None, P_ref=None):
    """x-t diagram and velocity and stress profiles (legend: the frames' times; dashed: u and the
    reference rho0 D u when given)."""
    plt = matplotlib_agg()
    fig, axs = plt.subplots(1, 3, figsize=(14, 4.2))
    t = np.array([f["t"] for f in tracker.frames]) / units.ns
    xf = np.array([f["front"] for f in tracker.frames]) / units.um
    xp = np.array([f["piston"] for f in tracker.frames]) / units.um
    axs[0].plot(t, xf, "o", ms=3, label="front")
    axs[0].plot(t, xp, "-", label="piston")
    if np.isfinite(state.D_fit):
        # the fitted line over the fit window (the frames the analysis used)
        a, b = tracker.fit_window()
        ok = np.isfinite(xf) & (xf > a / units.um) & (xf < b / units.um)
        if ok.sum() < 3:
            ok = np.isfinite(xf)
        tt = np.linspace(t[ok].min(), t[ok].max(), 10)
        A = np.polyfit(t[ok], xf[ok], 1)
        axs[0].plot(tt, np.polyval(A, tt), "k--", lw=0.8,
                    label=f"D = {state.D_fit / units.km_s:.3f} km/s (fit window)")
    axs[0].set_xlabel("t (ns)")
    axs[0].set_ylabel(f"{'xyz'[tracker.axis]} (um)")
    axs[0].legend()
    axs[0].set_title("x-t diagram")
    ax = tracker.axis
    for f in tracker.frames[:: max(1, len(tracker.frames) // 6)]:
        p = f["profile"]
        lab = f"t = {f['t'] / units.ns:.3g} ns"
        axs[1].plot(p["x"] / units.um, p["velocity"][:, ax] / units.km_s, lw=1, label=lab)
        axs[2].plot(p["x"] / units.um, -p["stress"][:, ax] / units.GPa, lw=1, label=lab)
    if u is not None:
        axs[1].axhline(u / units.km_s, color="k", ls="--", lw=0.8, label=f"piston u = {u / units.km_s:g} km/s")
    if P_ref is not None:
        axs[2].axhline(P_ref, color="k", ls="--", lw=0.8, label=f"rho0 D u (experiment) = {P_ref:.3g} GPa")
    axs[1].legend(fontsize=7)
    axs[2].legend(fontsize=7)
    c = "xyz"[ax]
    axs[1].set_xlabel(f"{c} (um)")
    axs[1].set_ylabel(f"particle velocity u_{c} (km/s)")
    axs[2].set_xlabel(f"{c} (um)")
    axs[2].set_ylabel(f"longitudinal stress -sigma_{c}{c} (GPa)")
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
    note = (f"front position fit, rms residual {state.fit_rms / state.width:.3f} slabs"
            if np.isfinite(state.width) else "front position fit")
    if ref is not None and u > ref.u_max * (1 + 1e-9):
        note += (f"; reference extrapolated: {ref.name} is measured to u = {ref.u_max / units.km_s:g} km/s")
    q = {
        "D": Quantity(state.D_fit / units.km_s, "km/s", refD, spread=state.D_fit_err / units.km_s, note=note),
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




#: fewest repeat cells along the shock: the front must cross enough slabs for a fit
MIN_CELLS = 10


def shock_stage(name, setup, frames):
    """The lifecycle stage of a piston shock: front tracker every frame, the piston's force as observables."""
    atoms, ax = setup.atoms, setup.axis
    tracker = shock_tracker(setup)
    others = [k for k in range(3) if k != ax]
    area = atoms.cell[others[0], others[0]] * atoms.cell[others[1], others[1]]
    piston = setup.piston
    obs = {"piston_force": (lambda a: -piston.force[ax] / units.N, "N"),
           "piston_pressure": (lambda a: -piston.force[ax] / area / units.GPa, "GPa")}
    return Stage(name, atoms, setup.dyn, setup.nsteps, frames, on_frame=shock_frame(setup, tracker),
                 analysis=tracker, observables=obs, setup=setup)


def shock_summary(stage):
    """Encodable summary of a finished shock stage (tracker frames and run figures)."""
    s = stage.setup
    pot = s.calc.potentials[0]
    return {"tracker": stage.analysis.get_state(), "n": len(s.atoms), "nsteps": s.nsteps, "t_run": stage.t_run,
            "nbuilds": s.calc.nl.nbuilds, "dt_r0_c0": stage.dyn.dt / (pot.r0 / pot.c0),
            "rho0": s.rho0, "u": s.u, "two_phase": s.two_phase, "size": list(s.size or ()),
            "fit_from_r0": (s.fit_from or 0.0) / pot.r0, "slab_r0": s.slab / pot.r0}


class ShockScene(SceneDef):
    """The ``shock`` scene on the lifecycle (module docstring)."""

    name = "shock"
    description = "CD piston shock in a block of clusters; D, u, P, rho vs the experimental Hugoniot"
    params = scene_params(PARAMS)
    setup_class = ShockSetup

    def check(self, v):
        mat = get_material(v.material)
        if mat.curve is None:
            raise InputError("material", v.material, "a material with a cold curve: " + ", ".join(CD_MATERIALS))
        size = self.size(v)
        text = v.size if isinstance(v.size, str) else "x".join(map(str, size))
        if size[0] < MIN_CELLS:
            raise InputError("size", text,
                             f"at least {MIN_CELLS} repeat cells along the shock (the front is fitted over "
                             f"slabs); e.g. {MIN_CELLS}x{size[1]}x{size[2]}")
        rep = repeat_lengths(v.direction, v.r0)
        need = 2.0 * v.rc * v.r0
        for k in (1, 2):
            if rep[k] * size[k] < need:
                nmin = int(math.ceil(need / rep[k]))
                raise InputError("size", text,
                                 f"a periodic cross-section at least 2 rc r0 wide ({nmin} cells across for "
                                 f"[{v.direction}], rc = {v.rc:g}) so that no cluster meets its own image")
        if v.u_history is not None:
            piston_history(v.u_history, v.u)
        if v.fit_from != "auto":
            travel = 0.8 * size[0] * repeat_lengths(v.direction, 1.0)[0]     # the run stops there (in r0)
            if float(v.fit_from) >= travel:
                raise InputError("fit_from", v.fit_from, f"auto or a front travel below {travel:.4g} r0 (the run "
                                 f"ends when the front has crossed 0.8 of the {text} sample)")

    @staticmethod
    def size(v):
        """The sample's repeat cells (``size=auto`` resolved, :func:`shock_size`)."""
        return shock_size(v.u, tuple(v.size) if isinstance(v.size, list) else v.size, v.direction,
                          min_width=inclusion_width(v.inclusion, v.inclusion_diameter, v.r0))[0]

    def setup(self, v, stage):
        size = v.size if isinstance(v.size, str) else tuple(v.size)
        s = build_shock(v.material, v.u, v.direction, size, v.r0, v.rc, v.J, v.noise,
                        v.seed, v.dt_factor, attraction=v.attraction, inclusion=v.inclusion,
                        inclusion_fraction=v.inclusion_fraction,
                        inclusion_diameter=v.inclusion_diameter, axis=v.axis, u_history=v.u_history,
                        fit_from=v.fit_from)
        return s

    def attach(self, v, stage, setup):
        return shock_stage(stage, setup, v.frames)

    def finish(self, v, stage):
        return shock_summary(stage)

    def retry(self, v, stage, exc, attempt):
        if exc.quantity != "timestep" or attempt > v.dt_retries:
            return None
        note = (f"dt factor {v.dt_factor:g}: stopped at step {exc.step} by the stiffness check (closest pair "
                f"{exc.particles}, timestep {exc.value:.4g} > limit {exc.limit:.4g})")
        return v.replace(dt_factor=0.5 * v.dt_factor, retried=v.retried + (note,))

    def analyse(self, v, summaries):
        sm = summaries[0]
        tracker = ShockTracker.from_state(sm["tracker"])
        state = tracker.result()
        two = sm["two_phase"] or None
        mat = get_material(v.material)
        q, ref = shock_quantities(state, mat, sm["u"], reference=two is None)
        n, nsteps, t_run = sm["n"], sm["nsteps"], sm["t_run"]
        notes = list(state.notes)
        for r in v.retried:
            notes.append(f"time step halved after a stop: {r}")
        notes.append(f"{n} clusters, {nsteps} steps of {sm['dt_r0_c0']:.4f} r0/c0, "
                     f"{n * nsteps / max(t_run, 1e-9):.3g} particle-steps/s, {sm['nbuilds']} neighbour-list builds")
        size = sm.get("size") or list(self.size(v))
        a, b = tracker.fit_window()
        x0 = tracker.frames[0]["profile"]["edges"][0]
        notes.append(f"sample {'x'.join(map(str, size))} repeat cells"
                     + (" (size=auto: the length steady at this u)" if isinstance(v.size, str) else "")
                     + f"; front fitted from {(a - x0) / state.width:.0f} to {(b - x0) / state.width:.0f} slabs "
                     f"({state.n_frames} frames)")
        notes.append(f"front fit: rms residual {state.fit_rms / units.um:.3g} um = {state.fit_rms / state.width:.3f} "
                     f"slabs; D over the two halves of the fit {state.D_halves[0] / units.km_s:.4g}, "
                     f"{state.D_halves[1] / units.km_s:.4g} km/s")
        if ref is not None:
            notes.append(f"reference: {ref.name} Hugoniot, {ref.source}"
                         + (f" (measured to u = {ref.u_max / units.km_s:g} km/s: extrapolated here)"
                            if sm["u"] > ref.u_max * (1 + 1e-9) else ""))
        if two is not None:
            notes.append(f"two-phase: {two['matrix']} matrix with {two['n_spheres']} {two['inclusion']} spheres, "
                         f"inclusion mass fraction {two['mass_fraction']:.4f} (target {two['mass_fraction_target']:g}), "
                         f"volume fraction {two['volume_fraction']:.4f}; no experimental reference")
        extra = {"steady": state.steady, "steady_reasons": list(state.steady_reasons),
                 "fit_rms_um": state.fit_rms / units.um, "fit_rms_slabs": state.fit_rms / state.width,
                 "D_halves_km_s": [h / units.km_s for h in state.D_halves],
                 "mass_check": state.mass_check, "momentum_check": state.momentum_check,
                 "ejecta_fraction": state.ejecta, "rho_bins_g_cm3": state.rho_bins / units.g_cm3,
                 "rho0_g_cm3": sm["rho0"] / units.g_cm3, "size_used": list(size),
                 "fit_window_slabs": [(a - x0) / state.width, (b - x0) / state.width],
                 "n_fit_frames": state.n_frames, "n_particles": n, "n_steps": nsteps,
                 "particle_steps": n * nsteps, "timestep_r0_c0": sm["dt_r0_c0"], "dt_factor_used": v.dt_factor,
                 "dt_retries_used": len(v.retried), "stepping_time_s": t_run,
                 "particle_steps_per_s": n * nsteps / max(t_run, 1e-9)}
        if two is not None:
            extra["two_phase"] = {k: x for k, x in two.items() if k not in ("centres", "diameters")}
            extra["two_phase"]["rho0"] = two["rho0"] / units.g_cm3
        return q, notes, extra, (tracker, state)

    def verdict(self, v, summaries, result):
        """``result.steady`` from the front fit; an unsteady run warns with the reasons and a size that
        should settle it (:func:`suggest_size`)."""
        x = result.extra
        result.steady = bool(x["steady"])
        if not result.steady:
            size = x["size_used"]
            result.warnings.append(
                f"shock not steady on {'x'.join(map(str, size))} cells ({'; '.join(x['steady_reasons'])}): D = "
                f"{result.quantities['D'].value:.4g} km/s is not the steady value; rerun with --set size="
                f"{suggest_size(v.u, size, v.direction)}")

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        tracker, state = result.data
        mat = get_material(v.material)
        ref_P = result.quantities["P"].reference
        png = out / "shock.png"
        plot_shock(tracker, state, png, f"{mat.name} [{v.direction}] along {v.axis}, u = "
                   f"{sm['u'] / units.km_s:g} km/s", u=sm["u"], P_ref=ref_P)
        import csv
        front = out / "shock_front.csv"
        with open(front, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_ns", "front_um", "piston_um"])
            for f in tracker.frames:
                w.writerow([f["t"] / units.ns, f["front"] / units.um, f["piston"] / units.um])
        prof = out / "shock_profiles.csv"
        ax = tracker.axis
        with open(prof, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_ns", "x_um", "density_g_cm3", "u_km_s", "minus_sigma_long_GPa", "von_mises_GPa"])
            for f in tracker.frames:
                p = f["profile"]
                for k in range(len(p["x"])):
                    w.writerow([f"{f['t'] / units.ns:.6g}", f"{p['x'][k] / units.um:.6g}",
                                f"{p['density'][k] / units.g_cm3:.6g}", f"{p['velocity'][k, ax] / units.km_s:.6g}",
                                f"{-p['stress'][k, ax] / units.GPa:.6g}", f"{p['von_mises'][k] / units.GPa:.6g}"])
        return [png, front, prof]


register_scene(ShockScene())
