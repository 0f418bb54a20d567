"""``clusterdyn study flow-stress``: the flow stress of a CD polycrystal against its packing.

The material-point test (:func:`material_point`)
------------------------------------------------

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
components).

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

The study (:func:`flow_stress_study`)
-------------------------------------

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

The point runner also takes the boundary pair law (``law_sigma_t``, ``law_G_c``, ``law_tau_c``,
``law_mu``, ``law_select``; docs/theory.md 1.11) and the kind of test (``test``: ``confined``,
the uniaxial strain above; ``unconfined``, uniaxial stress; ``tension``, stretched in uniaxial
strain: the spall strength).  :mod:`clusterdyn.studies.calibrate` maps the law's strength to the
unconfined flow stress, the spall strength, the confined flow stress and the moduli with them.
"""

import math
import time

import numpy as np

from .. import units
from ..analysis.stress import cell_stress, von_mises
from ..build import Box, fcc_packing, polycrystal
from ..build.lattice import SQRT2
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError
from ..materials import get_material
from ..md import DampedVerlet
from ..scenes.base import Param, Quantity, SceneResult
from ..scenes.common import matplotlib_agg, thermal_noise
from ..scenes.plate_impact import relax_sample
from ..scenes.shock import CD_MATERIALS
from .common import (ListParam, format_table, markdown_table, out_folder, parse_params, progress_bar,
                     StudyPoint, run_folder, run_scene, write_csv, write_json)

BOUNDARIES = ("bonded", "repulsive")
#: the material-point tests
TESTS = ("confined", "unconfined", "tension")


# --------------------------------------------------------------------------- the material-point test
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


def material_point(material="Al", r0=100 * units.um, size=24.0, sample="polycrystal", grain_size=11.0,
                   porosity=0.14, d_min=0.85, rc=1.15, boundaries="bonded", strains=(0.05, 0.10, 0.15),
                   rate=1e-3, hold=30.0, average=10.0, dt=0.1, J=50.0, noise=10 * units.m_s, seed=1,
                   relax_cycles=12, axis=0, record_every=0.5, window=0.01, progress=False, law=None, tension=False,
                   lateral_free=False):
    """Uniaxial-strain test of a periodic cube of clusters (the module docstring has the steps).

    Parameters
    ----------
    material : str or Material
        A material with a cold curve.
    r0 : float
        Cluster size, Angstrom.  Stresses do not depend on it (times scale with r0/c0).
    size : float
        Cube edge, in r0 (a single crystal: rounded to whole [100] cells of sqrt(2) r0).
    sample : "polycrystal" or "single"
    grain_size : float
        Mean grain diameter (equal-volume sphere), in r0.
    porosity : float or None
        Target porosity (``d_min`` chosen by bisection); None: use ``d_min``.
    d_min : float
        Boundary distance in r0 when ``porosity`` is None.
    rc : float
        Cutoff, multiple of r0.
    boundaries : "bonded" or "repulsive"
        ``repulsive``: set-up bonds inside grains only (``attraction="initial"``),
        so pairs across a grain boundary never attract.
    strains : sequence of float
        Increasing compressive strains (fractions in (0, 0.5)) at which the
        curve is read; the ramp runs to the last one and the hold is there.
    rate : float
        Strain rate of the ramp, per r0/c0.
    hold, average, dt, record_every : float
        In r0/c0: hold at the final strain, averaging window at the end of
        the hold, time step, stress sampling interval.
    window : float
        Strain window around each strain of ``strains`` (one-sided at the
        last): the ramp's stress is read there from a straight-line fit of
        each component against the strain over the window.
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
    progress : bool
        A tqdm bar over the steps.
    law : dict or BoundaryLaw, optional
        The boundary pair law (:mod:`clusterdyn.md.boundary`; a dict in display units:
        sigma_t and tau_c in GPa, G_c in J/m^2, mu, select); replaces ``boundaries``.
    lateral_free : bool
        Uniaxial stress instead of strain: after every reading the lateral cell axes are
        rescaled by ``1 - sigma_lateral/(10 K0)`` toward zero lateral stress (``unconfined``
        yield: the relaxed intensity is then the unconfined flow stress).
    tension : bool
        Stretch instead of compress (uniaxial strain); ``spall_strength`` is then the largest
        tensile ``sigma_axial`` (the material point's spall strength at this rate).

    Returns
    -------
    dict
        JSON-ready, stresses in GPa (the axial and lateral ones compression
        positive, Voigt ones tension positive):

        - ``curve``: per strain of ``strains``, ``strain``, ``sigma_u``,
          ``sigma_axial``, ``sigma_lateral`` (mean of the two lateral
          components) on the ramp;
        - ``sigma_u_ramp_end``, ``sigma_u_max`` (over ramp and hold);
        - ``relaxed``: the mean stress over the last ``average`` of the hold:
          ``sigma_u`` (its intensity), ``sigma_u_std`` (fluctuation of the
          intensity in the window), ``sigma_axial``, ``sigma_lateral``,
          ``stress`` (Voigt);
        - ``flow_stress``: ``relaxed["sigma_u"]``;
        - ``rest_stress`` (Voigt, before the ramp), ``series`` (``t_tau``,
          ``strain``, ``stress`` (n, 6)), ``sample`` (the polycrystal report),
          ``relax`` (the quench's last mean stress and nearest pair),
          ``n_clusters``, ``n_steps``, ``tau_ns`` (r0/c0), ``wall_time_s``.

    Raises
    ------
    InputError
        Bad input, before any work (and from the builder, e.g. an unreachable porosity).
    InstabilityError
        A run that goes unstable.
    """
    t_start = time.perf_counter()
    mat = get_material(material)
    if mat.curve is None:
        raise InputError("material", material, "a material with a cold curve (CD)")
    if sample not in ("polycrystal", "single"):
        raise InputError("sample", sample, "polycrystal or single")
    if boundaries not in BOUNDARIES:
        raise InputError("boundaries", boundaries, " or ".join(BOUNDARIES))
    if axis not in (0, 1, 2):
        raise InputError("axis", axis, "0, 1 or 2 (x, y, z)")
    strains = tuple(float(e) for e in np.atleast_1d(strains))
    if not strains or any(not 0 < e < 0.5 for e in strains) or any(b <= a for a, b in zip(strains, strains[1:])):
        raise InputError("strains", strains, "increasing compressive strains in (0, 0.5)")
    for name, val in (("rate", rate), ("hold", hold), ("average", average), ("dt", dt),
                      ("record_every", record_every), ("size", size), ("window", window)):
        if not (val > 0 and math.isfinite(val)):
            raise InputError(name, val, "a positive number")
    if average > hold:
        raise InputError("average", average, f"at most the hold ({hold:g} r0/c0)")
    if sample == "polycrystal" and math.pi / 6 * grain_size ** 3 > size ** 3:
        raise InputError("grain_size", grain_size, f"a grain no larger than the cube ({size:g} r0)")

    atoms, report = _sample(mat, r0, size, sample, grain_size, porosity, d_min, seed)
    term = None
    if law is not None:
        from ..md.boundary import BoundaryLaw
        if not isinstance(law, BoundaryLaw):
            law = BoundaryLaw.fromdict(law, display=True)
        # the law on the packing as built, quenched with its bonds held elastic (no damage), then
        # released: a bond whose quenched tension exceeds its strength fails in the first steps
        from ..md.boundary import apply_boundary_law
        calc, term = apply_boundary_law(atoms, law, rc=rc)
        term.hold = True
    elif sample == "polycrystal" and boundaries == "repulsive":
        mark_initial_bonds(atoms, rc=rc, within="grain")
        calc = ClusterDynamics(rc=rc, attraction="initial")
    else:
        calc = ClusterDynamics(rc=rc)
    atoms.calc = calc
    calc.setup(atoms)
    pot = calc.potentials[0]
    relaxed_bonds = None

    tau = pot.r0 / pot.c0
    K0 = pot.material.curve.K0
    relax = {}
    if sample == "polycrystal" and relax_cycles:
        rr = relax_sample(atoms, cycles=relax_cycles, axes=(0, 1, 2), term=term)
        relax = {"stress": (np.asarray(rr["stress"]) / units.GPa).tolist(),
                 "min_r_over_r0": rr["min_r_over_r0"], "steps": rr["steps"]}
    if law is not None:
        term.hold = False
        f = np.zeros((len(atoms), 3))
        term.accumulate(atoms, f)            # the damage of the quenched openings (not dissipated)
        relax["boundary"] = term.summary()
        if sample == "polycrystal" and relax_cycles:
            # released: quenched again with the law as it is (bonds may fail), toward zero stress
            rr = relax_sample(atoms, cycles=max(2, relax_cycles // 3), axes=(0, 1, 2), term=term)
            relax["stress_released"] = (np.asarray(rr["stress"]) / units.GPa).tolist()
            relax["boundary_released"] = term.summary()
        report = dict(report, porosity_quenched=float(1 - len(atoms) * pot.r0 ** 3 / (SQRT2 * atoms.get_volume())))
    atoms.set_momenta(np.zeros((len(atoms), 3)))
    thermal_noise(atoms, noise, seed)
    dyn = DampedVerlet(atoms, timestep=dt * tau, J=J)
    if term is not None:
        dyn.attach_piece(term)
    every = max(1, int(round(record_every / dt)))
    L0 = atoms.cell[axis, axis]
    eps_max = strains[-1]
    n_ramp = max(1, int(round(eps_max / rate / dt)))
    n_hold = int(round(hold / dt))
    t_series, e_series, s_series = [], [], []
    eps_now = 0.0

    def record():
        t_series.append(dyn.get_time() / tau)
        e_series.append(eps_now)
        W = None
        if term is not None:
            from ..analysis.stress import particle_virials
            if dyn.forces is None:
                dyn._refresh_properties()
            W = particle_virials(atoms)
            W[0] += term.virial            # the bonds' virial (its sum is what the cell stress needs)
        s_series.append(cell_stress(atoms, W) / units.GPa)
        if lateral_free:                      # toward zero lateral stress (uniaxial stress)
            g = np.ones(3)
            for d in range(3):
                if d != axis:
                    g[d] = 1.0 - s_series[-1][d] * units.GPa / (10.0 * K0)
            atoms.set_cell(atoms.cell.array * g[:, None], scale_atoms=True)
            dyn.forces = None

    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=n_ramp + n_hold, desc="material point", unit="step", leave=False, dynamic_ncols=True)
    record()
    for i in range(1, n_ramp + 1):
        eps_now = eps_max * i / n_ramp
        f = np.ones(3)
        f[axis] = L0 * (1.0 + eps_now if tension else 1.0 - eps_now) / atoms.cell[axis, axis]
        atoms.set_cell(atoms.cell.array * f[:, None], scale_atoms=True)
        dyn.forces = None                 # positions moved outside the step
        dyn.run(1)
        if i % every == 0 or i == n_ramp:
            record()
        if bar is not None and i % 50 == 0:
            bar.update(50)
    n_ramp_records = len(s_series)
    for i in range(1, n_hold + 1):
        dyn.run(1)
        if i % every == 0:
            record()
    if bar is not None:
        bar.close()
    S = np.array(s_series)
    E = np.array(e_series)
    T = np.array(t_series)
    vm = von_mises(S)
    lat = [d for d in range(3) if d != axis]

    def summary(mean):
        return {"sigma_u": float(von_mises(mean)), "sigma_axial": float(-mean[axis]),
                "sigma_lateral": float(-0.5 * (mean[lat[0]] + mean[lat[1]]))}

    curve = []
    on_ramp = np.arange(len(S)) < n_ramp_records
    for e in strains:
        sel = on_ramp & (np.abs(E - e) <= 0.5 * window + 1e-12)
        if sel.sum() >= 3:                    # straight line through the window, read at e (unbiased at the end)
            coef = np.polyfit(E[sel] - e, S[sel], 1)
            at_e = coef[1]
        else:
            at_e = S[sel].mean(axis=0) if sel.any() else S[np.argmin(np.abs(E - e))]
        curve.append({"strain": e, **summary(at_e)})
    win = (~on_ramp) & (T >= T[-1] - average - 1e-9)
    if not win.any():
        win = np.arange(len(S)) == len(S) - 1
    relaxed = summary(S[win].mean(axis=0))
    relaxed.update({"sigma_u_std": float(vm[win].std()), "stress": S[win].mean(axis=0).tolist()})
    return {"curve": curve, "sigma_u_ramp_end": float(vm[n_ramp_records - 1]), "sigma_u_max": float(vm.max()),
            "relaxed": relaxed, "flow_stress": relaxed["sigma_u"], "strain": eps_max,
            "rest_stress": S[0].tolist(),
            "series": {"t_tau": T.tolist(), "strain": E.tolist(), "stress": S.tolist()},
            "sample": report, "relax": relax, "n_clusters": len(atoms), "n_steps": int(dyn.nsteps),
            "tau_ns": tau / units.ns, "axis": axis, "wall_time_s": time.perf_counter() - t_start,
            "tension": bool(tension), "lateral_free": bool(lateral_free), "spall_strength": float(S[:, axis].max()) if tension else None,
            "modulus_axial": _modulus(E[on_ramp], S[on_ramp][:, axis], tension),
            "boundary": term.summary() if term is not None else None}


def _modulus(eps, s_axial, tension, upto=0.005):
    """Slope (GPa) of the axial stress against the strain over the first ``upto`` of the ramp
    (compression positive for a compressive test): the longitudinal modulus in uniaxial strain,
    Young's modulus in uniaxial stress."""
    sel = eps <= upto + 1e-12
    if sel.sum() < 3:
        return None
    y = s_axial[sel] if tension else -s_axial[sel]
    return float(np.polyfit(eps[sel], y, 1)[0])


# --------------------------------------------------------------------------- one run, as a cached "scene"
#: parameters of one material-point run (the study passes them in these display units)
POINT_PARAMS = [
    Param("material", "Al", "material", kind="choice", choices=CD_MATERIALS),
    Param("r0", 100.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("size", 24.0, "cube edge, in r0", low=4.0),
    Param("sample", "polycrystal", "polycrystal or a [100] single crystal", kind="choice",
          choices=("polycrystal", "single")),
    Param("grain_size", 11.0, "mean grain diameter, in r0", low=3.0),
    Param("porosity", 0.14, "target porosity", low=0.0, high=0.5),
    Param("rc", 1.15, "cutoff (multiple of r0)", low=1.0, high=1.414, low_open=True),
    Param("boundaries", "bonded", "grain-boundary pairs attract (bonded) or only repel (repulsive)",
          kind="choice", choices=BOUNDARIES),
    ListParam("strains", (0.05, 0.10, 0.15), "strains at which the curve is read; the ramp runs to the last",
              low=0.0, high=0.49, low_open=True),
    Param("rate", 1e-3, "strain rate of the ramp, per r0/c0", low=0.0, low_open=True),
    Param("hold", 30.0, "hold at the final strain, in r0/c0", low=0.0, low_open=True),
    Param("average", 10.0, "window at the end of the hold, in r0/c0", low=0.0, low_open=True),
    Param("dt", 0.1, "time step, in r0/c0", low=0.0, high=0.5, low_open=True),
    Param("J", 50.0, "pair damping Gamma = c0/(J r0)", low=0.0, low_open=True, optional=True),
    Param("noise", 10.0, "random velocity after the quench", unit="m/s", low=0.0),
    Param("seed", 1, "random seed (grains, orientations, noise)", kind="int", low=0),
    Param("relax_cycles", 12, "quench cycles of 100 damped steps", kind="int", low=0),
    Param("test", "confined", "confined (uniaxial strain), unconfined (uniaxial stress) or tension (uniaxial "
          "strain, stretched: the spall strength)", kind="choice", choices=TESTS),
    Param("law_sigma_t", None, "boundary law: tensile strength (none = no law)", unit="GPa", low=0.0,
          low_open=True, optional=True),
    Param("law_G_c", 1e5, "boundary law: fracture energy per area, J/m^2", low=0.0, low_open=True),
    Param("law_tau_c", 0.0, "boundary law: cohesive shear strength", unit="GPa", low=0.0),
    Param("law_mu", 0.0, "boundary law: Coulomb friction", low=0.0),
    Param("law_select", "boundary", "boundary law on the pairs across grain boundaries or on all pairs",
          kind="choice", choices=("boundary", "all")),
]

#: material-point runs actually computed in this process (runs read back from a study folder are not counted)
RUNS = [0]


def point_law(v):
    """The boundary law of a point's values (display units) or None."""
    if v.get("law_sigma_t") is None:
        return None
    return {"sigma_t": v["law_sigma_t"] / units.GPa, "G_c": v["law_G_c"],
            "tau_c": v["law_tau_c"] / units.GPa, "mu": v["law_mu"], "select": v["law_select"]}


def _point_runner(v, out=None, progress=False):
    RUNS[0] += 1
    law = point_law(v)
    test = v.get("test", "confined")
    r = material_point(law=law, tension=test == "tension", lateral_free=test == "unconfined",
                       material=v["material"], r0=v["r0"], size=v["size"], sample=v["sample"],
                       grain_size=v["grain_size"], porosity=v["porosity"], rc=v["rc"], boundaries=v["boundaries"],
                       strains=v["strains"], rate=v["rate"], hold=v["hold"], average=v["average"], dt=v["dt"],
                       J=v["J"], noise=v["noise"], seed=v["seed"], relax_cycles=v["relax_cycles"], progress=progress)
    rel = r["relaxed"]
    q = {"flow_stress": Quantity(r["flow_stress"], "GPa", note="relaxed von Mises intensity at the final strain"),
         "sigma_u_ramp_end": Quantity(r["sigma_u_ramp_end"], "GPa"),
         "sigma_u_max": Quantity(r["sigma_u_max"], "GPa"),
         "sigma_axial": Quantity(rel["sigma_axial"], "GPa", note="-sigma_xx, relaxed"),
         "sigma_lateral": Quantity(rel["sigma_lateral"], "GPa", note="-(sigma_yy + sigma_zz)/2, relaxed"),
         "n_clusters": Quantity(r["n_clusters"], "")}
    if r["sample"]:
        q["porosity"] = Quantity(r["sample"]["porosity"], "")
    if r["spall_strength"] is not None:
        q["spall_strength"] = Quantity(r["spall_strength"], "GPa", note="largest tensile sigma_axial")
    return SceneResult("flow-stress-point", q, r["wall_time_s"], extra=r)


#: the cached unit of the study (not a registered scene: ``clusterdyn run`` does not list it)
POINT = StudyPoint("flow-stress-point", "one uniaxial-strain material-point test", POINT_PARAMS, _point_runner)


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


def flow_stress_study(overrides=None, out=None, progress=True, quiet=None):
    """Run the flow-stress study (see the module docstring); returns a JSON-ready dict.

    The dict holds ``rows`` (one per point: means and spreads over seeds),
    ``runs`` (every run), ``default`` (the default packing's row),
    ``single`` (the single crystal's row or None), ``advice`` (closest
    packing to ``target``), ``runs_computed`` and ``runs_reused`` (runs read
    back from ``OUT/runs``), ``markdown``, ``files`` and ``wall_time_s``.

    With ``combine``, when no packing reaches the target, one more point is
    run: every factor at the end of its sweep that lowers the flow stress
    (the floor of the swept ranges).
    """
    t_start = time.perf_counter()
    quiet = (not progress) if quiet is None else quiet
    v, _ = parse_params(PARAMS, overrides, study="flow-stress")
    kinds = _check(v)
    points = plan_points(v, kinds)
    seeds = list(range(1, v["seeds"] + 1))
    jobs = [(n, seed, _overrides(v, p, seed)) for n, (_, p) in enumerate(points) for seed in seeds]
    if v["single"]:
        jobs.append(("single", 1, _overrides(v, {"rc": v["rc"], "rate": v["rate"]}, 1, sample="single")))
    for _, _, ov in jobs:
        POINT.parse(ov)                       # every run's parameters checked before any work
    folder = out_folder(out, "flow-stress", v["material"])
    cache = folder / "runs"
    n0 = RUNS[0]
    results, run_rows = {}, []
    _run_jobs(jobs, cache, v, progress, results, run_rows)
    strains = v["strains"]
    rows = [_point_row(t, p, results[n], strains) for n, (t, p) in enumerate(points)]
    advice = advise(rows, v)
    if v["combine"] and not advice["reached"] and len(advice["directions"]) >= 2:
        combo = {**points[0][1], **{d["factor"]: d["to"] for d in advice["directions"]}}
        key = tuple(combo[k] for k in (*FACTORS, "rate"))
        if key not in {tuple(p[k] for k in (*FACTORS, "rate")) for _, p in points}:
            points.append((["combined"], combo))
            n = len(points) - 1
            more = [(n, seed, _overrides(v, combo, seed)) for seed in seeds]
            jobs += more
            _run_jobs(more, cache, v, progress, results, run_rows)
            rows.append(_point_row(["combined"], combo, results[n], strains))
            advice = advise(rows, v)
    computed = RUNS[0] - n0
    single = None
    if v["single"]:
        single = _point_row(["reference"], {"rc": v["rc"], "rate": v["rate"]}, results["single"], strains,
                            sample="single")
        single["sample"] = "single [100]"
    default = rows[0]
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
    text.append(f"runs: {computed} computed, {len(jobs) - computed} read back from {cache}")
    md = markdown_table(table_rows, cols)
    files = [write_csv(folder / "flow_stress.csv", table_rows),
             write_csv(folder / "flow_stress_runs.csv", run_rows)]
    (folder / "flow_stress.md").write_text(md + "\n")
    files.append(folder / "flow_stress.md")
    if v["plots"]:
        files.append(_plot(folder / "flow_stress.png", rows, single, v, results))
    result = {"study": "flow-stress", "material": v["material"], "rows": rows, "single": single,
              "default": default, "runs": run_rows, "advice": {k: x for k, x in advice.items() if k != "lines"},
              "advice_text": advice["lines"], "runs_computed": computed, "runs_reused": len(jobs) - computed,
              "markdown": md, "definition": f"flow stress = von Mises intensity of the cell's mean stress over the "
              f"last {v['average']:g} r0/c0 of a {v['hold']:g} r0/c0 hold at {last}% uniaxial strain, reached at "
              f"{v['rate']:g} per r0/c0", "wall_time_s": time.perf_counter() - t_start}
    files.append(write_json(folder / "flow_stress.json", result))
    result["files"] = [str(f) for f in files]
    text.append("wrote " + ", ".join(str(f) for f in files))
    if not quiet:
        print("\n\n".join(text))
    return result


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
