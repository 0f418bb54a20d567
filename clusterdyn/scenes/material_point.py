"""The material-point test of a CD packing: a periodic cube strained affinely (:func:`material_point`).

A periodic cube of clusters (a polycrystal of Voronoi grains,
:func:`clusterdyn.build.polycrystal`, or a [100] single crystal) is

1. quenched (:func:`clusterdyn.scenes.plate_impact.relax_sample`: cycles of
   damped dynamics with the velocities zeroed after each, all three cell axes
   rescaled toward zero mean stress), then given ``noise`` of random
   velocity;
2. compressed in uniaxial strain along ``axis``: every step the cell and the
   positions are scaled affinely along that axis, at the strain rate
   ``rate`` (per r0/c0), up to the last strain of ``strains``; then held at
   fixed shape for ``hold`` (pair damping ``J`` on throughout);
3. read every ``record_every``: the cell's stress, virial plus kinetic about
   the cell's mean velocity, over the cell's volume
   (:func:`clusterdyn.analysis.stress.cell_stress`).

It reports the von Mises intensity (CD eq. 4) on the ramp at each strain of
``strains``, at the end of the ramp, its largest value, and the *relaxed*
state: the mean stress over the last ``average`` of the hold, its
intensity, -sigma_axial and -sigma_lateral (the mean of the two lateral
components).  In uniaxial strain an ideally plastic isotropic solid that has
yielded carries ``sigma_axial - sigma_lateral = Y``, so the relaxed intensity
is its yield stress (``clusterdyn study flow-stress`` calls it the flow
stress); an elastic solid instead carries ``(C11 - C12) eps``.

Variants: the boundary pair law (``law``, docs/theory.md 1.11), uniaxial
stress (``lateral_free``: the lateral axes rescaled toward zero stress after
every reading) and tension (``tension``: stretched; ``spall_strength`` is the
largest tensile axial stress).  The settings are a frozen :class:`PointTest`.
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from .. import units
from ..analysis.stress import cell_stress, particle_virials, von_mises
from ..build import Box, fcc_packing, polycrystal
from ..build.lattice import SQRT2
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError
from ..materials import get_material
from ..md import DampedVerlet
from .common import thermal_noise
from .plate_impact import relax_sample

BOUNDARIES = ("bonded", "repulsive")


@dataclass(frozen=True)
class PointTest:
    """The settings of one material-point test (ASE units unless a unit is named).

    Attributes
    ----------
    material : str or Material
        A material with a cold curve.
    r0 : float
        Cluster size, Angstrom (stresses do not depend on it: times scale with r0/c0).
    size : float
        Cube edge, in r0 (a single crystal: rounded to whole [100] cells of sqrt(2) r0).
    sample : str
        "polycrystal" or "single".
    grain_size : float
        Mean grain diameter (equal-volume sphere), in r0.
    porosity : float or None
        Target porosity (``d_min`` chosen by bisection); None: use ``d_min``.
    d_min : float
        Boundary distance in r0 when ``porosity`` is None.
    rc : float
        Cutoff, multiple of r0.
    boundaries : str
        "bonded" or "repulsive" (set-up bonds inside grains only, ``attraction="initial"``: pairs
        across a grain boundary never attract).
    strains : tuple of float
        Increasing compressive strains in (0, 0.5) at which the curve is read; the ramp runs to the
        last one and the hold is there.
    rate : float
        Strain rate of the ramp, per r0/c0.
    hold, average, dt, record_every : float
        In r0/c0: hold at the final strain, averaging window at the end of the hold, time step,
        stress sampling interval.
    J : float or None
        Pair damping Gamma = c0/(J r0) during the test (None: off).
    noise : float
        rms random velocity added after the quench (ASE velocity).
    seed : int
        Grains, orientations and noise.
    relax_cycles : int
        Quench cycles of 100 damped steps (polycrystal only; 0 = none).
    axis : int
        Compression axis (0, 1, 2).
    window : float
        Strain window around each strain of ``strains`` (one-sided at the last): the ramp's stress
        is read there from a straight-line fit of each component against the strain.
    law : dict or BoundaryLaw or None
        The boundary pair law (:mod:`clusterdyn.md.boundary`; a dict in display units: sigma_t and
        tau_c in GPa, G_c in J/m^2, mu, select); replaces ``boundaries``.
    tension : bool
        Stretch instead of compress (uniaxial strain).
    lateral_free : bool
        Uniaxial stress: after every reading the lateral cell axes are rescaled by
        ``1 - sigma_lateral/(10 K0)`` toward zero lateral stress.
    """

    material: object = "Al"
    r0: float = 100 * units.um
    size: float = 24.0
    sample: str = "polycrystal"
    grain_size: float = 11.0
    porosity: object = 0.14
    d_min: float = 0.85
    rc: float = 1.15
    boundaries: str = "bonded"
    strains: tuple = (0.05, 0.10, 0.15)
    rate: float = 1e-3
    hold: float = 30.0
    average: float = 10.0
    dt: float = 0.1
    J: object = 50.0
    noise: float = 10 * units.m_s
    seed: int = 1
    relax_cycles: int = 12
    axis: int = 0
    record_every: float = 0.5
    window: float = 0.01
    law: object = None
    tension: bool = False
    lateral_free: bool = False

    def check(self):
        """Refuse bad settings (one-line InputError, before any work); returns (Material, strains)."""
        mat = get_material(self.material)
        if mat.curve is None:
            raise InputError("material", self.material, "a material with a cold curve (CD)")
        if self.sample not in ("polycrystal", "single"):
            raise InputError("sample", self.sample, "polycrystal or single")
        if self.boundaries not in BOUNDARIES:
            raise InputError("boundaries", self.boundaries, " or ".join(BOUNDARIES))
        if self.axis not in (0, 1, 2):
            raise InputError("axis", self.axis, "0, 1 or 2 (x, y, z)")
        strains = tuple(float(e) for e in np.atleast_1d(self.strains))
        if not strains or any(not 0 < e < 0.5 for e in strains) or any(b <= a for a, b in zip(strains, strains[1:])):
            raise InputError("strains", strains, "increasing compressive strains in (0, 0.5)")
        for name in ("rate", "hold", "average", "dt", "record_every", "size", "window"):
            val = getattr(self, name)
            if not (val > 0 and math.isfinite(val)):
                raise InputError(name, val, "a positive number")
        if self.average > self.hold:
            raise InputError("average", self.average, f"at most the hold ({self.hold:g} r0/c0)")
        if self.sample == "polycrystal" and math.pi / 6 * self.grain_size ** 3 > self.size ** 3:
            raise InputError("grain_size", self.grain_size, f"a grain no larger than the cube ({self.size:g} r0)")
        return mat, strains


def _sample(mat, r0, size, sample, grain_size, porosity, d_min, seed):
    """The periodic cube (Atoms) and its report (dict, empty for a single crystal)."""
    if sample == "single":
        n = max(2, int(round(size / SQRT2)))
        atoms = fcc_packing(mat, r0, size=(n, n, n), direction="100", pbc=True)
        return atoms, {}
    L = size * r0
    kw = {"target_porosity": porosity} if porosity is not None else {"d_min": d_min}
    atoms = polycrystal(mat, r0, Box((0, 0, 0), (L, L, L)), grain_size=grain_size * r0, seed=seed, pbc=True,
                        **kw)
    return atoms, dict(atoms.info["polycrystal"])


def _attach_calculator(atoms, p):
    """The cube's calculator (set up); returns the boundary law's term (held elastic) or None."""
    term = None
    if p.law is not None:
        from ..md.boundary import BoundaryLaw, apply_boundary_law
        law = p.law if isinstance(p.law, BoundaryLaw) else BoundaryLaw.fromdict(p.law, display=True)
        # the law on the packing as built, quenched with its bonds held elastic (no damage), then
        # released: a bond whose quenched tension exceeds its strength fails in the first steps
        calc, term = apply_boundary_law(atoms, law, rc=p.rc)
        term.hold = True
    elif p.sample == "polycrystal" and p.boundaries == "repulsive":
        mark_initial_bonds(atoms, rc=p.rc, within="grain")
        calc = ClusterDynamics(rc=p.rc, attraction="initial")
    else:
        calc = ClusterDynamics(rc=p.rc)
    atoms.calc = calc
    calc.setup(atoms)
    return term


def _quench(atoms, p, term, pot, report):
    """Quench the cube toward zero stress (and release the law's bonds); returns (relax, report)."""
    relax = {}
    if p.sample == "polycrystal" and p.relax_cycles:
        rr = relax_sample(atoms, cycles=p.relax_cycles, axes=(0, 1, 2), term=term)
        relax = {"stress": (np.asarray(rr["stress"]) / units.GPa).tolist(),
                 "min_r_over_r0": rr["min_r_over_r0"], "steps": rr["steps"]}
    if term is not None:
        term.hold = False
        f = np.zeros((len(atoms), 3))
        term.accumulate(atoms, f)            # the damage of the quenched openings (not dissipated)
        relax["boundary"] = term.summary()
        if p.sample == "polycrystal" and p.relax_cycles:
            # released: quenched again with the law as it is (bonds may fail), toward zero stress
            rr = relax_sample(atoms, cycles=max(2, p.relax_cycles // 3), axes=(0, 1, 2), term=term)
            relax["stress_released"] = (np.asarray(rr["stress"]) / units.GPa).tolist()
            relax["boundary_released"] = term.summary()
        report = dict(report, porosity_quenched=float(1 - len(atoms) * pot.r0 ** 3 / (SQRT2 * atoms.get_volume())))
    return relax, report


class _Readings:
    """The cell's stress (GPa, Voigt) read at the current strain; rescales the lateral axes when
    ``lateral_free`` (toward zero lateral stress: uniaxial stress)."""

    def __init__(self, atoms, dyn, term, p, tau, K0):
        self.atoms, self.dyn, self.term, self.p, self.tau, self.K0 = atoms, dyn, term, p, tau, K0
        self.t, self.e, self.s = [], [], []
        self.eps = 0.0

    def __call__(self):
        atoms, dyn, term = self.atoms, self.dyn, self.term
        self.t.append(dyn.get_time() / self.tau)
        self.e.append(self.eps)
        W = None
        if term is not None:
            if dyn.forces is None:
                dyn._refresh_properties()
            W = particle_virials(atoms)
            W[0] += term.virial            # the bonds' virial (its sum is what the cell stress needs)
        self.s.append(cell_stress(atoms, W) / units.GPa)
        if self.p.lateral_free:
            g = np.ones(3)
            for d in range(3):
                if d != self.p.axis:
                    g[d] = 1.0 - self.s[-1][d] * units.GPa / (10.0 * self.K0)
            atoms.set_cell(atoms.cell.array * g[:, None], scale_atoms=True)
            dyn.forces = None


def _ramp_and_hold(atoms, dyn, read, p, eps_max, progress):
    """The affine ramp to ``eps_max`` then the hold; returns the number of readings on the ramp."""
    axis = p.axis
    every = max(1, int(round(p.record_every / p.dt)))
    L0 = atoms.cell[axis, axis]
    n_ramp = max(1, int(round(eps_max / p.rate / p.dt)))
    n_hold = int(round(p.hold / p.dt))
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=n_ramp + n_hold, desc="material point", unit="step", leave=False, dynamic_ncols=True)
    read()
    for i in range(1, n_ramp + 1):
        read.eps = eps_max * i / n_ramp
        f = np.ones(3)
        f[axis] = L0 * (1.0 + read.eps if p.tension else 1.0 - read.eps) / atoms.cell[axis, axis]
        atoms.set_cell(atoms.cell.array * f[:, None], scale_atoms=True)
        dyn.forces = None                 # positions moved outside the step
        dyn.run(1)
        if i % every == 0 or i == n_ramp:
            read()
        if bar is not None and i % 50 == 0:
            bar.update(50)
    n_ramp_records = len(read.s)
    for i in range(1, n_hold + 1):
        dyn.run(1)
        if i % every == 0:
            read()
    if bar is not None:
        bar.close()
    return n_ramp_records


def _curve(S, E, T, n_ramp_records, strains, p):
    """The ramp's stress at each strain, the relaxed state and the readings' summary numbers."""
    vm = von_mises(S)
    lat = [d for d in range(3) if d != p.axis]

    def summary(mean):
        return {"sigma_u": float(von_mises(mean)), "sigma_axial": float(-mean[p.axis]),
                "sigma_lateral": float(-0.5 * (mean[lat[0]] + mean[lat[1]]))}

    curve = []
    on_ramp = np.arange(len(S)) < n_ramp_records
    for e in strains:
        sel = on_ramp & (np.abs(E - e) <= 0.5 * p.window + 1e-12)
        if sel.sum() >= 3:                    # straight line through the window, read at e (unbiased at the end)
            coef = np.polyfit(E[sel] - e, S[sel], 1)
            at_e = coef[1]
        else:
            at_e = S[sel].mean(axis=0) if sel.any() else S[np.argmin(np.abs(E - e))]
        curve.append({"strain": e, **summary(at_e)})
    win = (~on_ramp) & (T >= T[-1] - p.average - 1e-9)
    if not win.any():
        win = np.arange(len(S)) == len(S) - 1
    relaxed = summary(S[win].mean(axis=0))
    relaxed.update({"sigma_u_std": float(vm[win].std()), "stress": S[win].mean(axis=0).tolist()})
    return {"curve": curve, "sigma_u_ramp_end": float(vm[n_ramp_records - 1]), "sigma_u_max": float(vm.max()),
            "relaxed": relaxed, "flow_stress": relaxed["sigma_u"], "strain": strains[-1]}, on_ramp


def _modulus(eps, s_axial, tension, upto=0.005):
    """Slope (GPa) of the axial stress against the strain over the first ``upto`` of the ramp
    (compression positive for a compressive test): the longitudinal modulus in uniaxial strain,
    Young's modulus in uniaxial stress."""
    sel = eps <= upto + 1e-12
    if sel.sum() < 3:
        return None
    y = s_axial[sel] if tension else -s_axial[sel]
    return float(np.polyfit(eps[sel], y, 1)[0])


def material_point(material="Al", *, progress=False, **settings):
    """Uniaxial-strain test of a periodic cube of clusters (the module docstring has the steps).

    ``material`` and ``settings`` are the fields of :class:`PointTest` (its docstring gives units and
    meaning);
    ``progress`` shows a tqdm bar over the steps.

    Returns
    -------
    dict
        JSON-ready, stresses in GPa (the axial and lateral ones compression positive, Voigt ones
        tension positive): ``curve`` (per strain of ``strains``: ``strain``, ``sigma_u``,
        ``sigma_axial``, ``sigma_lateral`` on the ramp); ``sigma_u_ramp_end``, ``sigma_u_max``;
        ``relaxed`` (the mean stress over the last ``average`` of the hold: ``sigma_u``,
        ``sigma_u_std``, ``sigma_axial``, ``sigma_lateral``, ``stress``); ``flow_stress``
        (``relaxed["sigma_u"]``); ``rest_stress`` (before the ramp); ``series`` (``t_tau``,
        ``strain``, ``stress`` (n, 6)); ``sample`` (the polycrystal report); ``relax`` (the quench's
        last mean stress and nearest pair); ``n_clusters``, ``n_steps``, ``tau_ns`` (r0/c0),
        ``spall_strength`` (tension: the largest tensile sigma_axial), ``modulus_axial``,
        ``boundary`` (the law's summary), ``wall_time_s``.

    Raises
    ------
    InputError
        Bad input, before any work (and from the builder, e.g. an unreachable porosity).
    InstabilityError
        A run that goes unstable.
    """
    t_start = time.perf_counter()
    p = PointTest(material=material, **settings)
    mat, strains = p.check()
    atoms, report = _sample(mat, p.r0, p.size, p.sample, p.grain_size, p.porosity, p.d_min, p.seed)
    term = _attach_calculator(atoms, p)
    pot = atoms.calc.potentials[0]
    tau = pot.r0 / pot.c0
    relax, report = _quench(atoms, p, term, pot, report)
    atoms.set_momenta(np.zeros((len(atoms), 3)))
    thermal_noise(atoms, p.noise, p.seed)
    dyn = DampedVerlet(atoms, timestep=p.dt * tau, J=p.J)
    if term is not None:
        dyn.attach_piece(term)
    read = _Readings(atoms, dyn, term, p, tau, pot.material.curve.K0)
    n_ramp_records = _ramp_and_hold(atoms, dyn, read, p, strains[-1], progress)
    S, E, T = np.array(read.s), np.array(read.e), np.array(read.t)
    out, on_ramp = _curve(S, E, T, n_ramp_records, strains, p)
    out.update({"rest_stress": S[0].tolist(),
                "series": {"t_tau": T.tolist(), "strain": E.tolist(), "stress": S.tolist()},
                "sample": report, "relax": relax, "n_clusters": len(atoms), "n_steps": int(dyn.nsteps),
                "tau_ns": tau / units.ns, "axis": p.axis, "wall_time_s": time.perf_counter() - t_start,
                "tension": bool(p.tension), "lateral_free": bool(p.lateral_free),
                "spall_strength": float(S[:, p.axis].max()) if p.tension else None,
                "modulus_axial": _modulus(E[on_ramp], S[on_ramp][:, p.axis], p.tension),
                "boundary": term.summary() if term is not None else None})
    return out
