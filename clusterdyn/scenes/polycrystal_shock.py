"""Scene ``polycrystal-shock``: a piston shock in a relaxed Al polycrystal of given porosity (and a [100]
single crystal beside it): the D-u point against the experimental Hugoniot.

The block is built and relaxed as the plate-impact scene's plates
(:func:`~clusterdyn.scenes.plate_impact.relax_sample`); the front is tracked as in the ``shock`` scene
(:class:`~clusterdyn.scenes.shock.ShockSetup`, :func:`~clusterdyn.scenes.shock.shock_stage`).
"""

import math

import numpy as np

from .. import units
from ..analysis.shock import ShockTracker
from ..build import Plate, fcc_packing, polycrystal
from ..build.lattice import SQRT2
from ..calculators import ClusterDynamics
from ..errors import InputError
from ..materials import get_material, hugoniot
from ..md import DampedVerlet
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, register_scene
from .common import make_piston, matplotlib_agg, piston_thickness, thermal_noise
from .lifecycle import SceneDef, scene_params
from .plate_impact import _summary, relax_sample
from .shock import ShockSetup, shock_quantities, shock_stage, shock_summary


def polycrystal_shock_setup(u=1.0 * units.km_s, sample="polycrystal", material="Al", r0=10 * units.um,
                            length=80.0, width=16.0, grain_size=8.0, porosity=0.06, d_min=0.85, seed=1,
                            noise=10 * units.m_s, J=None, dt_factor=TIMESTEP_FACTOR, relax_cycles=12,
                            packing=None):
    """Piston shock set-up at ``u`` in a relaxed polycrystal (or a [100] single crystal).

    ``packing`` (polycrystal; :mod:`clusterdyn.scenes.packing`): grain size, porosity and boundaries
    from a preset or file (the boundary law's term attached to the dynamics).

    The block (``length`` x ``width`` x ``width`` r0, periodic across) is
    relaxed (:func:`relax_sample`) and a 1.5 r0 layer at x-min becomes the
    piston.  The density ahead of the front is the porous sample's own.

    Returns
    -------
    ShockSetup
        The set-up; its ``sample`` holds the sample report and the relaxation.
    """
    mat = get_material(material)
    a = SQRT2 * r0
    W = max(2, int(round(width / SQRT2))) * a
    spec = None
    if packing is not None and sample != "single":
        from .packing import resolve_packing
        spec = resolve_packing(packing)
        grain_size, porosity = spec["grain_size"], spec["porosity"]
    if sample == "single":
        atoms = fcc_packing(mat, r0, direction="100", shape=Plate(length * r0, W, axis=0),
                            pbc=(False, True, True))
        report = None
    else:
        atoms = polycrystal(mat, r0, Plate(length * r0, W, axis=0), grain_size=grain_size * r0, seed=seed,
                            pbc=(False, True, True), d_min=d_min, target_porosity=porosity)
        report = atoms.info["polycrystal"]
    atoms.set_cell([(length + 40) * r0, W, W])
    term = None
    if spec is not None:
        from .packing import prepare
        calc, term, relax = prepare(atoms, spec, 1.15, (lambda at, t: relax_sample(at, cycles=relax_cycles, term=t))
                                    if relax_cycles else None)
    else:
        calc = ClusterDynamics()
        atoms.calc = calc
        relax = relax_sample(atoms, cycles=relax_cycles) if sample != "single" and relax_cycles else None
    atoms.positions[:, 0] -= atoms.positions[:, 0].min() - 2 * r0
    calc.setup(atoms)
    pot = calc.potentials[0]
    mask, piston = make_piston(atoms, piston_thickness(r0), u)
    thermal_noise(atoms, noise, seed, exclude=mask)
    atoms.set_constraint(piston)
    atoms.set_momenta(atoms.get_momenta())
    dt = dt_factor * r0 / (pot.c0 + u)
    dyn = DampedVerlet(atoms, timestep=dt, J=J)
    if term is not None:
        dyn.attach_piece(term)
    L = np.ptp(atoms.positions[:, 0])
    rho0 = atoms.get_masses().sum() / ((L + a / 2) * W * W)
    try:
        d_guess = hugoniot("Al-1100").D(u) if mat.name == "Al" else pot.c0 + 1.3 * u
    except InputError:
        d_guess = pot.c0 + 1.3 * u
    nsteps = int(math.ceil(0.8 * L / d_guess / dt))
    return ShockSetup(atoms, dyn, piston_index=np.nonzero(mask)[0], nsteps=nsteps, slab=max(a, r0), length=L, u=u,
                      rho0=rho0, x0=float(atoms.positions[~mask, 0].min()), rest_volume=atoms.get_masses() / rho0,
                      sample={"report": report or {}, "relax": relax or {}}, material=mat.replace(rho0=rho0))


SHOCK_PARAMS = [
    Param("u", 1.0, "piston speed", unit="km/s", low=0.0, high=10.0, low_open=True),
    Param("porosity", 0.06, "target porosity of the polycrystal", low=0.0, high=0.5),
    Param("grain_size", 8.0, "mean grain diameter, in r0", low=3.0),
    Param("r0", 10.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("length", 80.0, "block length along the shock, in r0", low=10.0),
    Param("width", 16.0, "periodic width across, in r0", low=3.0),
    Param("seed", 1, "random seed", kind="int", low=0),
    Param("single", True, "also run a [100] single crystal for comparison", kind="bool"),
    Param("frames", 40, "profiles recorded over the run", kind="int", low=5),
    Param("packing", None, "a packing preset or JSON file (clusterdyn.scenes.packing: grain size, porosity, "
          "boundaries); none = porosity and grain_size above", kind="str", optional=True),
]


class PolycrystalShockScene(SceneDef):
    """The ``polycrystal-shock`` scene on the lifecycle (stages: pc, then sc)."""

    name = "polycrystal-shock"
    description = ("piston shock in a relaxed Al polycrystal of given porosity: D-u point beside the single "
                   "crystal and the experimental Hugoniot")
    params = scene_params(SHOCK_PARAMS)
    setup_class = ShockSetup

    def plan(self, v):
        return ["pc", "sc"] if v.single else ["pc"]

    def setup(self, v, stage):
        return polycrystal_shock_setup(v.u, "polycrystal" if stage == "pc" else "single", r0=v.r0,
                                       length=v.length, width=v.width, grain_size=v.grain_size,
                                       porosity=v.porosity, seed=v.seed, packing=v.packing)

    def attach(self, v, stage, setup):
        return shock_stage(stage, setup, v.frames)

    def finish(self, v, stage):
        sm = shock_summary(stage)
        sm.update({"name": stage.name, "report": stage.setup.sample["report"], "relax": stage.setup.sample["relax"]})
        return sm

    def analyse(self, v, summaries):
        u = v.u
        mat = get_material("Al")
        ref = hugoniot("Al-1100")
        q, notes, states = {}, [], []
        for sm in summaries:
            key = sm["name"]
            state = ShockTracker.from_state(sm["tracker"]).result()
            states.append(state)
            qq, _ = shock_quantities(state, mat, u)
            for name in ("D", "u", "P", "rho"):
                q[f"{key}_{name}"] = qq[name]
            notes.append(f"{key}: {sm['n']} clusters, rho0 {sm['rho0'] / units.g_cm3:.4f} g/cm3, "
                         f"{sm['nsteps']} steps, {' '.join(state.notes) or 'steady'}")
            if key == "pc" and sm["report"]:
                notes.append("polycrystal: " + _summary(sm["report"]))
                q["pc_porosity"] = Quantity(sm["report"]["porosity"], "", v.porosity)
        notes.append(f"reference: Al-1100 D = {ref.D(u) / units.km_s:.3f} km/s at u = {u / units.km_s:g} km/s "
                     "(dense metal; a porous sample's own Hugoniot lies lower)")
        return q, notes, {}, states

    def report(self, v, summaries, result, out):
        import csv
        ref = hugoniot("Al-1100")
        plt = matplotlib_agg()
        fig, ax = plt.subplots(figsize=(6, 4.5))
        uu = np.linspace(0, 3, 50)
        ax.plot(uu, ref.D(uu * units.km_s) / units.km_s, "k-", label="Al-1100 (experiment)")
        rows = []
        for sm, state in zip(summaries, result.data):
            lab = {"pc": "CD polycrystal", "sc": "CD single crystal [100]"}[sm["name"]]
            if sm["name"] == "pc" and sm["report"]:
                lab += f" (porosity {100 * sm['report']['porosity']:.1f}%)"
            ax.errorbar([state.u / units.km_s], [state.D_fit / units.km_s], yerr=[state.D_fit_err / units.km_s],
                        fmt="o", label=lab)
            rows.append([sm["name"], state.u / units.km_s, state.D_fit / units.km_s, state.D_fit_err / units.km_s,
                         sm["rho0"] / units.g_cm3])
        ax.set_xlabel("u (km/s)")
        ax.set_ylabel("D (km/s)")
        ax.legend()
        ax.set_title("D-u point")
        fig.tight_layout()
        png = out / "polycrystal_shock_Du.png"
        fig.savefig(png, dpi=110)
        plt.close(fig)
        path = out / "polycrystal_shock_Du.csv"
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["sample", "u_km_s", "D_km_s", "D_err_km_s", "rho0_g_cm3"])
            w.writerows(rows)
        return [png, path]


register_scene(PolycrystalShockScene())
