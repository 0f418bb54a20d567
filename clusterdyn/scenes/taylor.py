"""Scene ``taylor``: a polycrystalline rod hits a rigid wall (the Taylor test), against 6061-T6 data.

A cylinder of length L0 and diameter D0 (a CD polycrystal, relaxed at rest)
flies along ``-axis`` at V onto a fixed harmonic wall
(:class:`~clusterdyn.md.wall.Wall`, frictionless by default, ``wall=sticking``
for no slip).  The run stops when the rod has stopped deforming:

* its centre-of-mass velocity toward the wall is below 1% of V, or reversed
  (a rebound), **and**
* its length changed by less than 0.1% of L0 over the last 5 us (in CD
  plastic work becomes cluster vibration, so the kinetic energy never falls
  to zero and cannot serve as the criterion), **or** the rod rebounded and has
  been off the wall (no cluster within the wall's reach) for the last 5 us: a
  free rod does no more plastic work, while its length keeps ringing
  elastically for a long time (amplitude ``L_ringing``, the spread of the
  length over the last 5 us, reported with the result),

checked every 0.5 us, or at ``t_max`` (default: ``2 rho0 V L0 / (0.3 GPa) +
20 L0/c0``, the time a rod of 0.3 GPa yield stress needs to stop plus ten
elastic round trips), whichever comes first; the result says which.

Measured on the final positions of the rod (its largest fragment; clusters
that broke away are counted and left out), ``clusterdyn.analysis.impact``:
the outline r(z) (per slab of width r0 along the axis, the 98th percentile
of the clusters' radial distances, plus the offset that makes the undeformed
rod's outline D0/2, measured on the relaxed rod before the impact), the
final length Lf (from the impact face to the rear face: the end clusters'
centres plus r0/2), the undeformed length X (rear part within 2% of D0/2),
the largest diameter Df, the diameter W at 0.2 L0 from the impact face and
Taylor's yield estimate; against the test of the same L0, D0 and V in
``clusterdyn/data/taylor_6061t6.csv`` (room temperature) and its outline.
Lengths along the axis are taken in the nominal rod's scale: the relaxed
rod (``L_init``, a little longer than L0: the as-built polycrystal expands
as it relaxes) is scaled to L0, so Lf/L0 is the ratio of the rod's
measured lengths after and before the impact (the same rule both times), as
is the outline's radius through its calibration.

**Packing.**  The default follows the CD paper's Taylor rods: a polycrystal of
about 14% porosity (the paper's 2.32 g/cm3 of 2.71) with grains of 1.14 mm
(the equal-volume diameter of 1363 grains in a 7.62 x 23.47 mm rod), or
3.2 r0 where that is larger (the smallest grain the builder takes, about
3 r0; at the default r0 = D0/12 the grains are 2.0 mm).  **Masses**: the
scene keeps the cluster masses (``mass=cluster``, as the paper's 2.32 g/cm3
rod): a porous rod carries 14% less momentum than the solid at the same V;
``mass=dense`` scales them to the full density (its waves are slower by
``1/sqrt(f)``, build.bodies).

**Resolution.**  ``r0`` (default D0/12, a coarse rod that runs in about a
minute to a few minutes on 2 cores; the reported tables use r0 <= D0/25).
Damping: J = 50 (the impact scenes' default, scenes.impact_common).
"""

import csv
import math

import numpy as np

from .. import units
from ..analysis.fragments import fragments
from ..analysis.impact import (axial_outline, find_taylor_test, outline_deviation, taylor_measures,
                               taylor_outline, taylor_yield)
from ..build import parse_axis
from ..build.bodies import rod
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError
from ..materials import cd_material_names, get_material
from ..md import DampedVerlet
from ..md.damped import TIMESTEP_FACTOR
from ..md.wall import Wall
from .base import Param, Quantity, register_scene
from .common import matplotlib_agg, thermal_noise
from .impact_common import IMPACT_J, announce_cost, ledger, ledger_quantities, retry_halved_dt
from .lifecycle import SceneDef, Stage, scene_params
from .plate_impact import relax_sample

#: default resolution: r0 = D0 / DEFAULT_ACROSS
DEFAULT_ACROSS = 12
#: smallest grain used by default, in r0 (the builder refuses grains below about 3 r0)
MIN_GRAIN_R0 = 3.2
#: stop criterion: centre-of-mass speed toward the wall below this fraction of V (or reversed) ...
STOP_SPEED = 0.01
#: ... and the length within this fraction of L0 over the last STOP_WINDOW
STOP_LENGTH = 0.001
STOP_WINDOW = 5.0 * units.us
#: analysis frames (stop check, histories) every FRAME_TIME
FRAME_TIME = 0.5 * units.us
#: outline percentile of the radial distances per slab
OUTLINE_Q = 98.0
#: yield stress of the default maximum time (a rod this weak stops by then)
T_MAX_YIELD = 0.3 * units.GPa

#: Packings of the rod: porosity (target, 1 - rho/rho0), grain size (equal-volume diameter, Angstrom),
#: cutoff rc (in r0), grain boundaries ("bonded": boundary pairs attract like any pair; "repulsive":
#: set-up bonds inside grains only, pairs across a boundary only repel).  "paper": the CD paper's
#: Taylor rods (module docstring).
#: FLOW-STRESS PICK: the packing the flow-stress study picks for 6061-T6 (0.3-0.4 GPa) is to be added
#: here as PACKINGS["flow"] = {"porosity": ..., "grain_size": ... * units.mm, "rc": ..., "boundaries": ...}
#: once that study is merged; the scene's `packing` choice lists every key of this dict.
PACKINGS = {
    "paper": {"porosity": 0.14, "grain_size": 1.14 * units.mm, "rc": 1.15, "boundaries": "bonded"},
}

CD_MATERIALS = tuple(cd_material_names())

PARAMS = [
    Param("L0", 46.94, "initial length of the rod", unit="mm", low=0.0, low_open=True),
    Param("D0", 7.62, "initial diameter of the rod", unit="mm", low=0.0, low_open=True),
    Param("V", 275.0, "impact speed", unit="m/s", low=0.0, high=5000.0, low_open=True),
    Param("material", "Al-6061-T6", "material of the rod", kind="choice", choices=CD_MATERIALS),
    Param("r0", None, "cluster size (none = D0/12; the reported tables use <= D0/25)", unit="mm", low=0.0,
          low_open=True, optional=True),
    Param("packing", "paper", "packing of the polycrystal (porosity, grain size, rc, boundaries): paper, a "
          "preset of clusterdyn.scenes.packing (e.g. 6061-T6, the boundary law) or a JSON file of its keys; the "
          "parameters porosity, grain_size, rc override it", kind="str"),
    Param("porosity", None, "target porosity 1 - rho/rho0 (none = the packing's)", low=0.0, high=0.5,
          optional=True),
    Param("grain_size", None, "grain size, the equal-volume diameter (none = the packing's or 3.2 r0 if "
          "larger)", unit="mm", low=0.0, low_open=True, optional=True),
    Param("rc", None, "cutoff as a multiple of r0 (none = the packing's)", low=1.0, high=1.414, low_open=True,
          optional=True),
    Param("boundaries", None, "grain boundaries: bonded (attract like any pair) or repulsive (set-up bonds "
          "inside grains only); none = the packing's", kind="choice", choices=("bonded", "repulsive"),
          optional=True),
    Param("mass", "cluster", "cluster masses: 'cluster' keeps the material's (a porous rod is lighter), "
          "'dense' scales them to the full-density rod", kind="choice", choices=("cluster", "dense")),
    Param("wall", "frictionless", "the rigid wall: frictionless or sticking (no slip while touching)",
          kind="choice", choices=("frictionless", "sticking")),
    Param("J", IMPACT_J, "damping Gamma = c0/(J r0); none = off (default 50: free surfaces, fragments)",
          low=0.0, low_open=True, optional=True),
    Param("seed", 1, "random seed of the grains (and of the noise)", kind="int", low=0),
    Param("noise", 0.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
    Param("relax_cycles", 12, "quench cycles of 100 steps (J = 2, velocities zeroed) before the impact (at least "
          "1: the packing as built has pairs at 0.64 r0 across its grain boundaries, and the rod flies apart)",
          kind="int", low=1),
    Param("t_max", None, "longest run (none = 2 rho0 V L0/(0.3 GPa) + 20 L0/c0); the run stops earlier "
          "once the rod has stopped deforming", unit="us", low=0.0, low_open=True, optional=True),
    Param("dt_factor", TIMESTEP_FACTOR, "time step as a fraction of r0/(c0 + V)", low=0.0, high=0.5,
          low_open=True),
    Param("dt_retries", 2, "times the run starts again with half the time step after a stiffness stop",
          kind="int", low=0),
    Param("axis", "z", "the rod's axis; it flies along -axis onto the wall", kind="choice",
          choices=("x", "y", "z")),
    Param("method", "cd", "cd: the CD polycrystal (the paper's model); mca: Movable Cellular Automata with "
          "J2 / Johnson-Cook flow and large-strain switching (fcc automata of size r0, default D0/8)",
          kind="choice", choices=("cd", "mca")),
    Param("mca_material", "Al6061-T6", "MCA material (method=mca); Al6061-T6-thermal adds Johnson-Cook's "
          "thermal term (adiabatic heating of each automaton)", kind="choice",
          choices=("Al6061-T6", "Al6061-T6-thermal", "Al6061", "copper")),
    Param("mca_damping", 0.05, "MCA pair damping, fraction of critical (method=mca)", low=0.0),
    Param("remesh_strain", 0.1, "MCA: pair strain that triggers a re-tessellation (method=mca)", low=0.0,
          high=0.5, low_open=True),
]

#: MCA default resolution: automaton size D0 / MCA_ACROSS
MCA_ACROSS = 8


# --------------------------------------------------------------------------- set-up
def taylor_packing(v, r0):
    """(porosity, grain size, rc, boundaries, notes) of a parameter set at cluster size ``r0``."""
    if v.packing in PACKINGS:
        pk = PACKINGS[v.packing]
    else:                       # a preset or file of clusterdyn.scenes.packing (grain size in r0)
        from .packing import resolve_packing
        spec = resolve_packing(v.packing)
        pk = {"porosity": spec["porosity"], "grain_size": spec["grain_size"] * r0, "rc": spec["rc"],
              "boundaries": spec["boundaries"]}
    por = pk["porosity"] if v.porosity is None else v.porosity
    rc = pk["rc"] if v.rc is None else v.rc
    bnd = pk["boundaries"] if v.get("boundaries") is None else v.boundaries
    notes = []
    if v.grain_size is None:
        g = pk["grain_size"]
        if g < MIN_GRAIN_R0 * r0:
            notes.append(f"grain size {g / units.mm:.3g} mm of the '{v.packing}' packing is below "
                         f"{MIN_GRAIN_R0:g} r0 at r0 = {r0 / units.mm:.4g} mm: grains of {MIN_GRAIN_R0:g} r0 = "
                         f"{MIN_GRAIN_R0 * r0 / units.mm:.3g} mm used")
            g = MIN_GRAIN_R0 * r0
    else:
        g = v.grain_size
    return por, g, rc, bnd, notes


def taylor_r0(v):
    if v.r0 is not None:
        return v.r0
    return v.D0 / (MCA_ACROSS if v.get("method") == "mca" else DEFAULT_ACROSS)


def build_taylor_mca(v):
    """The MCA rod (fcc automata of size r0 in the cylinder), its wall and dynamics (method=mca).

    Johnson-Cook 6061-T6 by default (``mca_material``); the wall's stiffness and reach are the
    MCA defaults (:meth:`clusterdyn.mca.MCA.wall_defaults`); the dynamics switches partners
    (``remesh_strain``) and damps pair velocities at ``mca_damping``.  Nothing is relaxed: an
    MCA packing is at rest in its set-up state.
    """
    from ..build.mca import mca_packing
    from ..build.shapes import Cylinder
    from ..mca import MCA, MCADynamics
    from ..mca.dynamics import COURANT, default_timestep, wave_speeds
    mat = get_material(v.mca_material)
    D0, L0, V = v.D0, v.L0, v.V
    d = taylor_r0(v)
    ax = parse_axis(v.axis)
    center = np.full(3, 0.5 * D0 + d)
    center[ax] = 0.0
    atoms = mca_packing(mat, d, Cylinder(center=tuple(center), radius=0.5 * D0, length=L0, axis=ax), "fcc")
    atoms.calc = MCA()
    z = atoms.positions[:, ax]
    L_init, offset, noise_outline = _rest_outline(atoms, ax, d, D0)
    vel = np.zeros(3)
    vel[ax] = -V
    atoms.set_velocities(np.broadcast_to(vel, (len(atoms), 3)).copy())
    normal = np.zeros(3)
    normal[ax] = 1.0
    point = np.zeros(3)
    point[ax] = z.min() - 0.5 * d - 0.01 * d        # d_c = d/2: the end automata just touch
    wall = Wall(point, normal, sticking=v.wall == "sticking")
    atoms.set_constraint(wall)
    cl = wave_speeds(mat)[0]
    dt = default_timestep(atoms) * (v.dt_factor / TIMESTEP_FACTOR) * cl / (cl + V)
    dyn = MCADynamics(atoms, timestep=dt, damping=v.mca_damping, remesh_strain=v.remesh_strain)
    rho = float(atoms.get_masses().sum() / (math.pi * 0.25 * D0 ** 2 * L0))
    t_max = v.t_max
    if t_max is None:
        t_max = 2.0 * rho * V * L0 / T_MAX_YIELD + 20.0 * L0 / cl
    announce_cost("taylor", len(atoms), int(math.ceil(t_max / dt)))
    info = {"method": "mca", "r0": d, "L0": L0, "D0": D0, "V": V, "axis": ax, "dt": dt,
            "nsteps": int(math.ceil(t_max / dt)), "t_max": t_max, "wall_z": float(point[ax]), "L_init": L_init,
            "offset": offset, "outline_noise": noise_outline, "rho": rho, "rho0": float(mat.rho0), "c0": cl,
            "courant": COURANT * float(v.dt_factor / TIMESTEP_FACTOR), "material": mat.name,
            "notes": [], "n_automata": len(atoms)}
    return atoms, dyn, info


def mca_ledger(dyn):
    """The MCA energy ledger (:meth:`MCADynamics.ledger`) in joules, with the keys of :func:`ledger`."""
    led = dyn.ledger()
    J = units.J
    out = {"kinetic0": float(led["initial"]) / J, "potential0": 0.0,
           "kinetic": float(led["kinetic"] + led["rotational"]) / J, "potential": float(led["elastic"]) / J,
           "damping_loss": float(led["damping"]) / J, "wall_dissipated": 0.0, "drive_work": 0.0,
           "wall_work": 0.0, "removed": 0.0, "removed_count": 0, "residual": float(led["residual"]) / J}
    walls = [c for c in dyn.atoms.constraints if isinstance(c, Wall)]
    out["wall_dissipated"] = float(sum(w.dissipated for w in walls)) / J
    out["potential"] += float(sum(w.energy for w in walls)) / J
    for k in ("plastic", "switching", "splitting", "volume"):
        out[k] = float(led[k]) / J
    out["switches"] = int(dyn.remesh_count)
    st = dyn.state
    if st.T_n.size:        # Johnson-Cook's thermal term: the heat is part of the plastic work, not extra
        from ..mca.response.plastic import heat_energy
        out["heat"] = heat_energy(st, dyn.atoms) / J
        out["T_max"] = float(st.T_n.max())
    return out


def _rest_outline(atoms, ax, size, D0):
    """The rod at rest: its length (end to end plus one particle), the outline's calibration offset
    (the test's D0/2 less the median measured radius, ends left out) and the largest outline
    deviation left after it, relative to D0/2."""
    L_init = float(np.ptp(atoms.positions[:, ax]) + size)
    out = axial_outline(atoms.positions, ax, size, q=OUTLINE_Q)
    inner = np.isfinite(out["r"])
    inner[:2] = inner[-2:] = False
    if inner.sum() < 2:
        inner = np.isfinite(out["r"])
    offset = 0.5 * D0 - float(np.median(out["r"][inner]))
    noise_outline = float(np.max(np.abs(out["r"][inner] + offset - 0.5 * D0)) / (0.5 * D0))
    return L_init, offset, noise_outline


def build_taylor(v):
    """The relaxed rod, its wall and dynamics; returns ``(atoms, dyn, info)`` (lifecycle set-up)."""
    mat = get_material(v.material)
    D0, L0, V = v.D0, v.L0, v.V
    r0 = taylor_r0(v)
    ax = parse_axis(v.axis)
    por, grain, rc, bnd, notes = taylor_packing(v, r0)
    center = np.zeros(3)
    center[ax] = 0.5 * L0
    atoms = rod(mat, r0, L0, D0, axis=ax, center=center, grain_size=grain, seed=v.seed,
                target_porosity=por, mass=v.mass)
    body = dict(atoms.info["bodies"][0])
    term = None
    if bnd == "law":            # the boundary law (clusterdyn.scenes.packing), quenched with its bonds held
        from .packing import prepare, resolve_packing
        calc, term, relax = prepare(atoms, resolve_packing(v.packing), rc,
                                    (lambda a, t: relax_sample(a, cycles=v.relax_cycles, lateral=False, term=t))
                                    if v.relax_cycles else None)
    elif bnd == "repulsive":
        mark_initial_bonds(atoms, rc=rc, within="grain")
        calc = ClusterDynamics(rc=rc, attraction="initial")
    else:
        calc = ClusterDynamics(rc=rc)
    atoms.calc = calc
    if term is None:
        relax = relax_sample(atoms, cycles=v.relax_cycles, lateral=False) if v.relax_cycles else None
    if relax is None:
        atoms.get_forces()            # relax_cycles=0: the calculator's set-up (its potentials) all the same
    atoms.set_momenta(np.zeros((len(atoms), 3)))
    pot = calc.potentials[0]
    # the relaxed rod at rest: its length and the outline's calibration offset
    z = atoms.positions[:, ax]
    L_init, offset, noise_outline = _rest_outline(atoms, ax, r0, D0)
    # velocity and wall
    vel = np.zeros(3)
    vel[ax] = -V
    atoms.set_velocities(np.broadcast_to(vel, (len(atoms), 3)).copy())
    thermal_noise(atoms, v.noise, v.seed)
    normal = np.zeros(3)
    normal[ax] = 1.0
    point = np.zeros(3)
    point[ax] = z.min() - 0.5 * r0 - 0.01 * r0       # d_c = r0/2: the end clusters just touch
    wall = Wall(point, normal, sticking=v.wall == "sticking")
    atoms.set_constraint(wall)
    dt = v.dt_factor * r0 / (pot.c0 + V)
    dyn = DampedVerlet(atoms, timestep=dt, J=v.J)
    if term is not None:
        dyn.attach_piece(term)
    dyn.start_ledger()
    rho = float(atoms.get_masses().sum() / (math.pi * 0.25 * D0 ** 2 * L0))
    t_max = v.t_max
    if t_max is None:
        t_max = 2.0 * rho * V * L0 / T_MAX_YIELD + 20.0 * L0 / pot.c0
    announce_cost("taylor", len(atoms), int(math.ceil(t_max / dt)))
    info = {"r0": r0, "L0": L0, "D0": D0, "V": V, "axis": ax, "dt": dt, "nsteps": int(math.ceil(t_max / dt)),
            "t_max": t_max, "wall_z": float(point[ax]), "L_init": L_init, "offset": offset,
            "outline_noise": noise_outline, "rho": rho, "rho0": float(mat.rho0), "c0": float(pot.c0),
            "porosity_target": por, "grain_size": grain, "rc": rc, "boundaries": bnd, "notes": notes,
            "body": {k: b for k, b in body.items() if k in ("n_clusters", "porosity", "n_grains", "d_min_r0",
                                                           "mass_choice", "mass_factor", "density_g_cm3")},
            "relax_min_r": None if relax is None else float(relax["min_r_over_r0"]),
            "relax_steps": 0 if relax is None else int(relax["steps"])}
    if term is not None:
        info["boundary"] = relax["boundary"]
    return atoms, dyn, info


# --------------------------------------------------------------------------- run record
class TaylorRecord:
    """Histories (length, centre-of-mass velocity, kinetic energy) and the stop criterion."""

    def __init__(self, atoms, dyn, info):
        self.atoms, self.dyn = atoms, dyn
        self.ax = int(info["axis"])
        self.r0, self.V, self.L0 = info["r0"], info["V"], info["L_init"]
        self.m = atoms.get_masses()
        self.wall_z, self.reach = info["wall_z"], 0.5 * self.r0
        self.t, self.L, self.vz, self.ek, self.contact = [], [], [], [], []
        self.reason = ""

    def frame(self, d):
        z = self.atoms.positions[:, self.ax]
        p = self.atoms.get_momenta()[:, self.ax]
        self.t.append(d.get_time())
        self.L.append(float(np.ptp(z) + self.r0))
        self.vz.append(float(p.sum() / self.m.sum()))
        self.ek.append(float(d.get_kinetic_energy() if hasattr(d, "get_kinetic_energy")
                             else self.atoms.get_kinetic_energy()))
        self.contact.append(bool(z.min() - self.wall_z < self.reach))

    def expected_steps(self, d):
        """The step the run is expected to stop at, for the progress bar's time left (None until the
        rod decelerates): the centre of mass brought to rest at its present deceleration, plus the stop
        window.  Only an estimate for the bar: the stop itself is :meth:`stop`'s."""
        t, v = self.t, self.vz
        if len(t) < 3:
            return None
        if v[-1] >= 0:
            want = t[-1] + STOP_WINDOW
        else:
            a = (v[-1] - v[-3]) / (t[-1] - t[-3])
            if a <= 0:
                return None
            want = t[-1] - v[-1] / a + STOP_WINDOW
        return int(want / d.dt)

    def stop(self, d):
        t = np.asarray(self.t)
        if len(t) < 2 or t[-1] < STOP_WINDOW:
            return False
        slow = -self.vz[-1] < STOP_SPEED * self.V
        win = t >= t[-1] - STOP_WINDOW - 1e-9 * t[-1]
        recent = np.asarray(self.L)[win]
        steady = np.ptp(recent) < STOP_LENGTH * self.L0
        free = self.vz[-1] > 0 and not np.any(np.asarray(self.contact)[win])
        if slow and (steady or free):
            why = (f"length within {100 * np.ptp(recent) / self.L0:.3g}% over the last "
                   f"{STOP_WINDOW / units.us:g} us" if steady else
                   f"rebounded, off the wall for the last {STOP_WINDOW / units.us:g} us (length ringing "
                   f"{100 * np.ptp(recent) / self.L0:.3g}%)")
            self.reason = (f"stopped deforming at {t[-1] / units.us:.4g} us: centre-of-mass velocity "
                           f"{-self.vz[-1] / units.m_s:+.3g} m/s toward the wall, {why}")
            return True
        return False

    def get_state(self):
        return {"t": list(self.t), "L": list(self.L), "vz": list(self.vz), "ek": list(self.ek),
                "contact": list(self.contact), "reason": self.reason}

    def set_state(self, st):
        for k in ("t", "L", "vz", "ek"):
            setattr(self, k, [float(x) for x in st[k]])
        self.contact = [bool(x) for x in st["contact"]]
        self.reason = str(st.get("reason", ""))


# --------------------------------------------------------------------------- analysis
def analyse_rod(sm):
    """Measures of the final rod from a stage summary (ASE units)."""
    info = sm["info"]
    ax, r0, D0, L0 = info["axis"], info["r0"], info["D0"], info["L0"]
    pos = np.asarray(sm["positions"])
    keep = np.asarray(sm["main"], bool)
    p = pos[keep]
    face = p[:, ax].min() - 0.5 * r0               # the impact face (the rod may have rebounded)
    out = axial_outline(p, ax, r0, q=OUTLINE_Q, lo=face)
    r = out["r"] + info["offset"]
    # lengths in the nominal rod's scale: the relaxed rod is L_init long (its radius is calibrated by the offset)
    scale = L0 / info["L_init"]
    z = (out["z"] - face) * scale
    top = (p[:, ax].max() + 0.5 * r0 - face) * scale
    m = taylor_measures(z, r, L0, D0, top=top)
    m["Lf_over_L0"] = m["Lf"] / L0           # = final / initial measured length (end clusters' centres + r0)
    m["z"], m["r"] = z, r
    m["Y"] = taylor_yield(info["rho"], info["V"], L0, m["Lf"], m["X"])
    return m


def _unmeasured(q, m):
    """Drop the rod measures that could not be taken (no undeformed rear: X = 0, so no Taylor estimate);
    return one note each saying why."""
    notes = []
    if not m["X"] > 0:
        del q["X_over_L0"], q["Y_taylor"]
        notes.append("X_over_L0, Y_taylor: not measured: no part of the rod's rear keeps its radius within 2% of "
                     "D0/2 (X = 0), and Taylor's estimate needs ln(L0/X)")
    elif not math.isfinite(m["Y"]):
        del q["Y_taylor"]
        notes.append("Y_taylor: not measured: Taylor's estimate is undefined for this rod (Lf = L0 or X = L0)")
    return notes


class TaylorScene(SceneDef):
    """The ``taylor`` scene on the lifecycle (module docstring)."""

    name = "taylor"
    description = ("polycrystalline rod on a rigid wall (Taylor test): Lf/L0, X, Df, W, outline and Taylor's "
                   "yield estimate vs the 6061-T6 tests")
    params = scene_params(PARAMS, h5md_frames=20, checkpoint_every=40)

    def check(self, v):
        r0 = taylor_r0(v)
        if v.method == "mca":
            if v.D0 < 4.0 * r0:
                raise InputError("r0", f"{r0 / units.mm:g}mm", f"at most D0/4 = {v.D0 / 4 / units.mm:g} mm "
                                 "(a rod a few automata across)")
            if v.L0 < 4.0 * r0:
                raise InputError("L0", f"{v.L0 / units.mm:g}mm", f"at least 4 r0 = {4 * r0 / units.mm:g} mm")
            return
        if v.D0 < 4.0 * r0:
            raise InputError("r0", f"{r0 / units.mm:g}mm", f"at most D0/4 = {v.D0 / 4 / units.mm:g} mm "
                             "(a rod a few clusters across)")
        if v.L0 < 4.0 * r0:
            raise InputError("L0", f"{v.L0 / units.mm:g}mm", f"at least 4 r0 = {4 * r0 / units.mm:g} mm")
        por, g, rc, bnd, _ = taylor_packing(v, r0)
        if g < 3.0 * r0:
            raise InputError("grain_size", f"{g / units.mm:g}mm", f"at least 3 r0 = {3 * r0 / units.mm:.4g} mm "
                             "(the smallest grain of the polycrystal builder)")
        if g > min(v.D0, v.L0):
            raise InputError("grain_size", f"{g / units.mm:g}mm", f"at most the rod's diameter and length, "
                             f"{min(v.D0, v.L0) / units.mm:g} mm")

    def setup(self, v, stage):
        return build_taylor_mca(v) if v.method == "mca" else build_taylor(v)

    def attach(self, v, stage, atoms, dyn, info):
        rec = TaylorRecord(atoms, dyn, info)
        nframes = max(1, int(round(info["nsteps"] * info["dt"] / FRAME_TIME)))
        return Stage(stage, atoms, dyn, int(info["nsteps"]), nframes, info, on_frame=rec.frame, analysis=rec,
                     stop=rec.stop)

    def retry(self, v, stage, exc, attempt):
        return retry_halved_dt(v, exc, attempt)

    def finish(self, v, stage):
        atoms, dyn, rec = stage.atoms, stage.dyn, stage.analysis
        info = stage.info
        mca = info.get("method") == "mca"
        fr = fragments(atoms, pairs=dyn.state) if mca else fragments(atoms)
        main = fr.labels == fr.largest
        wall = [c for c in atoms.constraints if isinstance(c, Wall)][0]
        return {"info": info, "positions": atoms.get_positions(), "main": main,
                "n_broken": int(len(atoms) - main.sum()), "n_fragments": int(fr.n_fragments),
                "history": rec.get_state(), "reason": rec.reason, "ledger": mca_ledger(dyn) if mca else ledger(dyn),
                "impulse_N_s": (np.asarray(wall.impulse) / (units.N * units.s)).tolist(),
                "steps": int(dyn.nsteps), "t_run": stage.t_run, "n": len(atoms),
                "v_end": float(rec.vz[-1]) if rec.vz else 0.0}

    def analyse(self, v, summaries):
        sm = summaries[0]
        info = sm["info"]
        m = analyse_rod(sm)
        L0, D0, V = info["L0"], info["D0"], info["V"]
        test = find_taylor_test(L0, D0, V)
        ref = {k: None for k in ("Lf", "X", "Df", "W", "Y")}
        if test is not None:
            ref["Lf"] = test["Lf_mm"] / test["L0_mm"]
            ref["X"] = None if test["X_mm"] is None else test["X_mm"] / test["L0_mm"]
            ref["Df"] = None if test["Df_mm"] is None else test["Df_mm"] / test["D0_mm"]
            ref["W"] = None if test["W_mm"] is None else test["W_mm"] / test["D0_mm"]
            if test["X_mm"] is not None:
                ref["Y"] = taylor_yield(test["rho0_kg_m3"] * units.kg / units.m ** 3, test["V_m_s"] * units.m_s,
                                        test["L0_mm"], test["Lf_mm"], test["X_mm"]) / units.GPa
        q = {
            "Lf_over_L0": Quantity(m["Lf_over_L0"], "", ref["Lf"], note="final / initial length of the rod"),
            "X_over_L0": Quantity(m["X"] / L0, "", ref["X"], note="undeformed rear length (within 2% of D0/2)"),
            "Df_over_D0": Quantity(m["Df"] / D0, "", ref["Df"], note="largest (mushroom) diameter"),
            "W_over_D0": Quantity(m["W"] / D0, "", ref["W"], note="diameter at 0.2 L0 from the impact face"),
            "Y_taylor": Quantity(m["Y"] / units.GPa, "GPa", ref["Y"],
                                 note="Taylor's estimate rho V^2 (L0-X)/(2 (L0-Lf) ln(L0/X)), rho of the rod"),
        }
        outline = taylor_outline(test["name"]) if test is not None and test["has_outline"] else None
        if outline is not None:
            q["outline_deviation"] = Quantity(outline_deviation(m["z"], m["r"], outline[0], outline[1], D0), "",
                                              note="mean |r_CD - r_exp| over the experimental outline / (D0/2)")
        hist = sm["history"]
        t_end = hist["t"][-1] if hist["t"] else 0.0
        q["t_end"] = Quantity(t_end / units.us, "us", note="time the run ended")
        tt = np.asarray(hist["t"])
        ring = np.asarray(hist["L"])[tt >= t_end - STOP_WINDOW] if len(tt) else np.zeros(1)
        q["L_ringing"] = Quantity(float(np.ptp(ring)) / info["L_init"], "", note="spread of the length over the "
                                  "last 5 us / L0 (elastic ringing: the uncertainty of Lf from final positions)")
        q["v_com_end"] = Quantity(-sm["v_end"] / units.m_s, "m/s", note="centre-of-mass velocity toward the wall "
                                  "at the end (negative: rebound)")
        lq, lnote = ledger_quantities(sm["ledger"])
        q.update(lq)
        notes = _unmeasured(q, m)
        notes += list(info["notes"])
        mca = info.get("method") == "mca"
        if mca:
            led = sm["ledger"]
            for k, txt in (("plastic", "plastic work of the radial returns"),
                           ("switching", "elastic energy released by the switches (re-tessellations)"),
                           ("splitting", "O(dt) work difference of the response corrections"),
                           ("volume", "elastic energy change of the exact-volume syncs")):
                q[f"E_{k}"] = Quantity(led[k], "J", note=txt)
            q["residual_over_plastic"] = Quantity(led["residual"] / max(abs(led["plastic"]), 1e-300), "",
                                                  note="energy ledger residual / plastic work")
            if "heat" in led:
                q["E_heat"] = Quantity(led["heat"], "J", note="heat of the automata, sum m c_p (T - T_room): "
                                       "the Taylor-Quinney share of E_plastic, not extra energy")
                q["T_max"] = Quantity(led["T_max"], "K", note="hottest automaton (adiabatic heating)")
        notes.append(sm["reason"] or f"NOT stopped by t_max = {info['t_max'] / units.us:.4g} us (criterion: "
                     f"velocity below {100 * STOP_SPEED:g}% of V or reversed and length within "
                     f"{100 * STOP_LENGTH:g}% over {STOP_WINDOW / units.us:g} us)")
        if mca:
            notes.append(f"MCA rod: {sm['n']} automata of {info['r0'] / units.mm:.4g} mm = D0/{D0 / info['r0']:.3g} "
                         f"(fcc), {info['material']}, pair damping {v.mca_damping:g}, switching at pair strain "
                         f"{v.remesh_strain:g} ({sm['ledger']['switches']} switches), wall {v.wall} "
                         f"(MCA default stiffness); the CD packing parameters do not apply")
        else:
            body = info["body"]
            notes.append(f"rod: {sm['n']} clusters, r0 = {info['r0'] / units.mm:.4g} mm = D0/{D0 / info['r0']:.3g}, "
                     f"{body['n_grains']} grains of {info['grain_size'] / units.mm:.3g} mm = "
                     f"{info['grain_size'] / info['r0']:.3g} r0, porosity {100 * body['porosity']:.1f}% "
                     f"(d_min {body['d_min_r0']:.3f} r0), rc {info['rc']:g}, {info.get('boundaries', 'bonded')} grain "
                     f"boundaries, masses '{body['mass_choice']}' "
                     f"(density {info['rho'] / units.g_cm3:.3f} g/cm3), wall {v.wall}, J {v.J}")
        if not mca:
            notes.append(f"relaxed at rest ({info['relax_steps']} steps): length {info['L_init'] / units.mm:.4g} mm "
                     f"(nominal {L0 / units.mm:g}); outline offset {info['offset'] / info['r0']:+.3f} r0, outline "
                     f"noise on the undeformed rod {100 * info['outline_noise']:.2f}% of D0/2")
        notes.append(f"{sm['steps']} steps of {info['dt'] / units.ns:.4g} ns, {sm['t_run']:.1f} s stepping; "
                     f"{sm['n_broken']} clusters broke away ({sm['n_fragments'] - 1} fragments), left out")
        if test is not None:
            notes.append(f"reference: {test['source']}, L0 {test['L0_mm']} mm, D0 {test['D0_mm']} mm, "
                         f"V {test['V_m_s']:g} m/s, T0 {test['T0_K']:g} K" + (", with outline" if outline else ""))
        else:
            notes.append("no room-temperature test with this L0, D0 and V in the data: no reference")
        notes.append(lnote)
        for r in v.retried:
            notes.append(f"time step halved after a stop: {r}")
        extra = {"Lf_mm": m["Lf"] / units.mm, "X_mm": m["X"] / units.mm, "Df_mm": m["Df"] / units.mm,
                 "W_mm": m["W"] / units.mm, "test": None if test is None else test["name"],
                 "ledger_J": sm["ledger"], "wall_impulse_N_s": sm["impulse_N_s"], "n_clusters": sm["n"],
                 "steps": sm["steps"], "stepping_time_s": sm["t_run"], "stopped": bool(sm["reason"])}
        return q, notes, extra, m

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        info = sm["info"]
        m = result.data
        test = find_taylor_test(info["L0"], info["D0"], info["V"])
        outline = taylor_outline(test["name"]) if test is not None and test["has_outline"] else None
        files = write_outline(out, m, info, outline, test)
        files += write_history(out, sm)
        final = out / "taylor_final.npz"             # the final rod, for analyses after the run
        np.savez_compressed(final, positions_A=np.asarray(sm["positions"], dtype=np.float32),
                            main=np.asarray(sm["main"], bool), axis=info["axis"], r0_A=info["r0"],
                            L_init_A=info["L_init"], offset_A=info["offset"], L0_A=info["L0"], D0_A=info["D0"],
                            V_ase=info["V"], rho_ase=info["rho"])
        return files + [final]


def write_outline(out, m, info, outline, test):
    """taylor_outline.png and .csv: the CD outline (both sides) beside the experimental one."""
    plt = matplotlib_agg()
    mm = units.mm
    fig, ax = plt.subplots(figsize=(5.0, 6.5))
    z, r = m["z"] / mm, m["r"] / mm
    ok = np.isfinite(r)
    label = str(info.get("method", "cd")).upper()
    ax.plot(r[ok], z[ok], "b-", label=label)
    ax.plot(-r[ok], z[ok], "b-")
    L0, D0 = info["L0"] / mm, info["D0"] / mm
    ax.plot([-D0 / 2, -D0 / 2, D0 / 2, D0 / 2], [0, L0, L0, 0], "k:", lw=0.8, label="initial rod")
    if outline is not None:
        ze, re_ = outline[0] / mm, outline[1] / mm
        ax.plot(re_, ze, "ro", ms=3, label="experiment")
        ax.plot(-re_, ze, "ro", ms=3)
    elif test is not None:
        ax.axhline(test["Lf_mm"], color="r", ls="--", label="experiment Lf")
    ax.set_xlabel("r (mm)")
    ax.set_ylabel("z from the impact face (mm)")
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_title(f"V = {info['V'] / units.m_s:g} m/s, L0 = {L0:g} mm, Lf/L0 = {m['Lf_over_L0']:.3f}", fontsize=9)
    fig.tight_layout()
    png = out / "taylor_outline.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    path = out / "taylor_outline.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["source", "z_mm", "r_mm"])
        for a, b in zip(z[ok], r[ok]):
            w.writerow([label, f"{a:.5g}", f"{b:.5g}"])
        if outline is not None:
            for a, b in zip(outline[0] / mm, outline[1] / mm):
                w.writerow(["experiment", f"{a:.5g}", f"{b:.5g}"])
    return [png, path]


def write_history(out, sm):
    """taylor_history.png and .csv: length and centre-of-mass velocity against time."""
    plt = matplotlib_agg()
    h = sm["history"]
    t = np.asarray(h["t"]) / units.us
    L = np.asarray(h["L"]) / units.mm
    vz = -np.asarray(h["vz"]) / units.m_s
    ek = np.asarray(h["ek"]) / units.J
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(6, 5), sharex=True)
    a1.plot(t, L)
    a1.set_ylabel("length (mm)")
    a2.plot(t, vz)
    a2.axhline(0, color="k", lw=0.5)
    a2.set_ylabel("c.o.m. velocity toward the wall (m/s)")
    a2.set_xlabel("t (us)")
    fig.tight_layout()
    png = out / "taylor_history.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    path = out / "taylor_history.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_us", "length_mm", "v_com_toward_wall_m_s", "kinetic_J"])
        for row in zip(t, L, vz, ek):
            w.writerow([f"{x:.6g}" for x in row])
    return [png, path]


register_scene(TaylorScene())
