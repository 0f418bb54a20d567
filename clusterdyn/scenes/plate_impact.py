"""Scene ``plate-impact`` (docs/theory.md 1.4, 1.7) and the polycrystal relaxation the
``polycrystal-shock`` scene (:mod:`clusterdyn.scenes.polycrystal_shock`) shares.

``plate-impact``: two aluminium plates, free along x and periodic across,
collide at a relative speed ``v`` (each moves at v/2 toward the other, the
centre-of-mass frame).  The sample is a [100] single crystal, a polycrystal
(:func:`clusterdyn.build.polycrystal`, relaxed before the impact) or both.
Recorded: slab profiles of sigma_xx, sigma_yy, sigma_zz and the von Mises
intensity (CD eq. 3-4) at chosen times, the x-t history of the intensity, and
the free-surface velocity of the rear face of the target (the VISAR trace,
in the target's rest frame).  Measured: the intensity at the front and its
plateau behind it, -sigma_xx behind the front (against rho0 D u of the
Al-1100 Hugoniot at u = v/2), the speeds of the elastic precursor and of
the main wave (in the target's frame), the free-surface plateau (against
v) and the pullback after it.

Relaxation of a polycrystal (:func:`relax_sample`): grain-boundary clusters
left at ``d_min`` repel strongly, so the sample is quenched first: cycles of
damped dynamics (J = 2) after which all velocities are zeroed and the
periodic cross-section is rescaled toward zero lateral stress.
"""

import csv
import math
from dataclasses import dataclass

import numpy as np

from .. import units
from ..analysis.profiles import ProfileRecorder, write_profiles_csv
from ..analysis.stress import add_piece_virials, particle_virials
from ..build import Plate, fcc_packing, polycrystal
from ..build.lattice import SQRT2, lattice_sound_speed
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError
from ..materials import get_material, hugoniot
from ..md import DampedVerlet
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, register_scene
from .common import matplotlib_agg, thermal_noise
from .lifecycle import SceneDef, Setup, Stage, scene_params

#: gap between the plates' surfaces at the start, in r0 (just beyond the cutoff)
GAP = 1.25
#: damping of the quench relaxation (Gamma = c0/(J r0))
RELAX_J = 2.0


# --------------------------------------------------------------------------- samples
def _concat(parts):
    from ..build import make_cluster_atoms
    pos = np.vstack([p.positions for p in parts])
    atoms = make_cluster_atoms(pos, parts[0].info["cd_materials"], parts[0].info["cd_r0"])
    grain = [p.arrays.get("grain", np.full(len(p), -1)) for p in parts]
    off = 0
    gs = []
    for g in grain:
        gs.append(np.where(g >= 0, g + off, -1))
        off += max(0, int(g.max()) + 1)
    atoms.new_array("grain", np.concatenate(gs).astype(np.int64))
    atoms.new_array("plate", np.concatenate([np.full(len(p), k, np.int64) for k, p in enumerate(parts)]))
    return atoms


def make_plate(sample, material, r0, thickness, width, grain_size=8.0, seed=1, d_min=0.85,
               porosity=None):
    """One plate (x from 0 to ``thickness``), periodic across with ``width`` (Angstrom).

    ``sample``: "single" ([100] fcc, width rounded to whole repeat cells by the
    caller) or "polycrystal" (grains of mean diameter ``grain_size`` r0).
    """
    if sample == "single":
        shape = Plate(thickness, width, axis=0)
        return fcc_packing(material, r0, direction="100", shape=shape, pbc=(False, True, True))
    if sample == "polycrystal":
        return polycrystal(material, r0, Plate(thickness, width, axis=0), grain_size=grain_size * r0,
                           seed=seed, pbc=(False, True, True), d_min=d_min, target_porosity=porosity)
    raise InputError("sample", sample, "single or polycrystal")


def relax_sample(atoms, cycles=12, steps=100, lateral=True, progress=False, axes=None, term=None):
    """Quench a sample (in place): damped dynamics, velocities zeroed every ``steps``.

    After each cycle the cell axes in ``axes`` are rescaled by
    ``1 - s_aa/(1.5 K0)`` (affinely, atoms with them), which drives the mean
    stress along them toward zero.  ``axes`` defaults to the cross-section
    (y, z) of a plate when ``lateral`` and to none otherwise; a periodic cube
    (a material-point sample) passes ``axes=(0, 1, 2)``.  Only periodic axes
    may be rescaled.  The mean stress is the summed virials over the
    sample's volume: the cell length along periodic axes, the extent of the
    positions plus ``r0/sqrt(2)`` along free ones.

    ``term``: a boundary law's term (:mod:`clusterdyn.md.boundary`), attached during the quench
    (its bonds' virial counted in the stress).

    Returns
    -------
    dict
        ``stress``: final mean stress (Voigt, eV/A^3); ``min_r_over_r0``:
        the smallest pair distance (r0); ``steps``: damped steps run.
    """
    if axes is None:
        axes = (1, 2) if lateral else ()
    axes = tuple(int(a) for a in axes)
    pbc = np.asarray(atoms.pbc, bool)
    for a in axes:
        if a not in (0, 1, 2) or not pbc[a]:
            raise InputError("axes", axes, f"periodic cell axes (pbc = {pbc.tolist()})")
    calc = atoms.calc
    calc.setup(atoms)
    pot = calc.potentials[0]
    K0 = pot.material.curve.K0
    dyn = DampedVerlet(atoms, J=RELAX_J)
    if term is not None:
        dyn.attach_piece(term)
    s = np.zeros(6)
    for _ in range(cycles):
        dyn.run(steps)
        atoms.set_momenta(np.zeros((len(atoms), 3)))
        ext = [atoms.cell[d, d] if pbc[d] else np.ptp(atoms.positions[:, d]) + pot.r0 / SQRT2 for d in range(3)]
        s = (particle_virials(atoms).sum(axis=0) + (term.virial if term is not None else 0.0)) / float(np.prod(ext))
        if axes:
            f = np.ones(3)
            for a in axes:
                f[a] = 1.0 - s[a] / (1.5 * K0)     # tension (s > 0): shrink the axis
            atoms.set_cell(atoms.cell.array * f[:, None], scale_atoms=True)
        dyn.forces = None                     # positions or momenta changed outside the step
    return {"stress": s, "min_r_over_r0": calc.last_stats["min_r_over_r0"], "steps": cycles * steps}


def build_impact(sample="single", material="Al", v=500 * units.m_s, r0=10 * units.um, flyer=25.0,
                 target=50.0, width=16.0, grain_size=8.0, d_min=0.85, porosity=None, seed=1,
                 noise=10 * units.m_s, J=50.0, dt_factor=TIMESTEP_FACTOR, relax_cycles=12,
                 boundaries="bonded", packing=None):
    """Two plates ready to collide; returns a dict with atoms, dynamics and bookkeeping.

    Lengths ``flyer``, ``target``, ``width`` are in r0.  The width is rounded
    to whole [100] repeat cells (sqrt 2 r0) so both samples have the same cross-section.
    ``boundaries="repulsive"`` (polycrystal): only pairs within one grain attract
    (``attraction="initial"`` with set-up bonds inside grains); pairs across a
    grain boundary only repel, so grains can slide apart and over each other.
    ``packing`` (polycrystal; a name or file, :mod:`clusterdyn.scenes.packing`): grain size,
    porosity and boundaries from the packing (its rc is not used: the scene's calculator keeps
    rc = 1.15); with the boundary law the term is attached to the dynamics (``"term"``).
    """
    spec = None
    if packing is not None and sample == "polycrystal":
        from .packing import resolve_packing
        spec = resolve_packing(packing)
        grain_size, porosity, boundaries = spec["grain_size"], spec["porosity"], spec["boundaries"]
    if boundaries not in ("bonded", "repulsive") and spec is None:
        raise InputError("boundaries", boundaries, "bonded or repulsive")
    mat = get_material(material)
    if mat.curve is None:
        raise InputError("material", material, "a material with a cold curve (CD)")
    a = SQRT2 * r0
    W = max(2, int(round(width / SQRT2))) * a
    if sample == "polycrystal" and grain_size * r0 > min(flyer, target) * r0 * 2:
        raise InputError("grain_size", grain_size, f"at most twice the thinner plate ({min(flyer, target):g} r0)")
    pf = make_plate(sample, mat, r0, flyer * r0, W, grain_size, seed, d_min, porosity)
    pt = make_plate(sample, mat, r0, target * r0, W, grain_size, seed + 1, d_min, porosity)
    reports = [p.info.get("polycrystal") for p in (pf, pt)]
    # relax both plates in one periodic cell, far apart
    pt.positions += np.array([flyer * r0 + 10 * r0, 0, 0])
    atoms = _concat([pf, pt])
    Lx = (flyer + target + 30) * r0
    atoms.set_cell([Lx, W, W])
    atoms.pbc = (False, True, True)
    term = None
    if spec is not None:
        from .packing import prepare
        calc, term, relax = prepare(atoms, spec, 1.15, (lambda a, t: relax_sample(a, cycles=relax_cycles, term=t))
                                    if relax_cycles else None)
    elif sample == "polycrystal" and boundaries == "repulsive":
        mark_initial_bonds(atoms, within="grain")
        calc = ClusterDynamics(attraction="initial")
    else:
        calc = ClusterDynamics()
    atoms.calc = calc
    relax = None if spec is None else relax
    if sample == "polycrystal" and relax_cycles and spec is None:
        relax = relax_sample(atoms, cycles=relax_cycles)
    plate = atoms.arrays["plate"]
    fl, tg = plate == 0, plate == 1
    shift = atoms.positions[fl, 0].max() + GAP * r0 - atoms.positions[tg, 0].min()
    atoms.positions[tg, 0] += shift
    atoms.positions[:, 0] -= atoms.positions[:, 0].min() - 5 * r0
    calc.setup(atoms)
    pot = calc.potentials[0]
    vel = np.zeros((len(atoms), 3))
    vel[fl, 0] = 0.5 * v
    vel[tg, 0] = -0.5 * v
    atoms.set_velocities(vel)
    thermal_noise(atoms, noise, seed)
    dt = dt_factor * r0 / (pot.c0 + v)
    dyn = DampedVerlet(atoms, timestep=dt, J=J)
    if term is not None:
        dyn.attach_piece(term)
    x_rear = atoms.positions[tg, 0].max()
    rear = tg & (atoms.positions[:, 0] > x_rear - 1.5 * r0)
    x_impact = 0.5 * (atoms.positions[fl, 0].max() + atoms.positions[tg, 0].min())
    return {"atoms": atoms, "calc": calc, "dyn": dyn, "material": mat, "r0": r0, "v": v, "dt": dt,
            "rear": rear, "x_impact": x_impact, "x_rear": x_rear, "flyer": flyer * r0,
            "target": target * r0, "width": W, "reports": reports, "relax": relax, "sample": sample,
            "c0": pot.c0}


# --------------------------------------------------------------------------- run + analysis
class ImpactRecord:
    """Analysis state of an impact run: slab profiles every frame and the rear free-surface velocity."""

    def __init__(self, setup):
        atoms, dyn = setup.atoms, setup.dyn
        r0, self.v = setup.r0, setup.v
        x = atoms.positions[:, 0]
        self.rec = ProfileRecorder(2.0 * r0, axis=0, lo=x.min() - 10 * r0, hi=x.max() + 10 * r0)
        self.rear = np.asarray(setup.rear, dtype=np.int64)
        self.m_rear = atoms.get_masses()[self.rear]
        self.atoms, self.dyn = atoms, dyn
        self.fsv_t, self.fsv_v = [], []

    def fsv(self):
        u = (self.m_rear * self.atoms.get_velocities()[self.rear, 0]).sum() / self.m_rear.sum()
        self.fsv_t.append(self.dyn.get_time())
        self.fsv_v.append(u + 0.5 * self.v)                 # target rest frame

    def frame(self, d):
        """Profile the current frame; returns the particles' potential virials (N, 6), eV."""
        W = add_piece_virials(self.atoms.calc.compute(self.atoms, per_particle=True, forces=False)["virials"], self.dyn)
        self.rec.add(self.atoms, W, d.get_time())
        return W

    def get_state(self):
        return {"profiles": self.rec.get_state(), "fsv_t": list(self.fsv_t), "fsv_v": list(self.fsv_v)}

    def set_state(self, st):
        self.rec.set_state(st["profiles"])
        self.fsv_t = [float(x) for x in st["fsv_t"]]
        self.fsv_v = [float(x) for x in st["fsv_v"]]


@dataclass
class ImpactSetup(Setup):
    """A built plate impact (ASE units): the two plates with their dynamics, and what the analysis
    needs (the checkpoint's payload, :class:`~clusterdyn.scenes.lifecycle.Setup`)."""

    r0: float = 0.0
    v: float = 0.0                 #: impact speed (flyer against the target at rest, lab frame: +-v/2)
    dt: float = 0.0
    x_impact: float = 0.0          #: the plates' contact plane at set-up
    x_rear: float = 0.0            #: the target's rear face at set-up
    flyer: float = 0.0             #: plate thicknesses
    target: float = 0.0
    width: float = 0.0             #: periodic width across
    sample: str = "single"
    c0: float = 0.0
    rear: np.ndarray = None        #: rows of the target's rear layer (the VISAR probe)
    reports: list = None           #: the builder's report on each plate ({} for a single crystal)
    relax: dict = None             #: the relaxation's record ({} when none ran)
    nsteps: int = 0

    @classmethod
    def built(cls, s, **more):
        """The set-up of a :func:`build_impact` dict ``s`` (``more``: a subclass's fields)."""
        return cls(s["atoms"], s["dyn"], **{k: s[k] for k in ("r0", "v", "dt", "x_impact", "x_rear", "flyer",
                                                                 "target", "width", "sample", "c0")},
                   rear=np.nonzero(s["rear"])[0], reports=[r if r is not None else {} for r in s["reports"]],
                   relax=s["relax"] if s["relax"] is not None else {}, **more)


def impact_duration(info, duration=None):
    """Run time: ``duration`` or the time the waves need to cross the target and the flyer's release."""
    if duration is not None:
        return duration
    cL = lattice_sound_speed(info["c0"])              # [100] longitudinal speed of the lattice
    slow = 1.0 if info["sample"] == "single" else 1.6      # waves in a porous polycrystal are slower
    return slow * (info["target"] + 3.0 * info["flyer"]) / cL


def _fronts(prof, x_impact, x_rear, p_threshold_main=0.5, floor=0.15 * units.GPa):
    """Per frame: -sigma_xx plateau in the target, main-front and precursor positions.

    Main front: the furthest slab where -sigma_xx reaches half the plateau
    (90th percentile over the target).  Precursor: the furthest slab above
    ``max(floor, 4% of the plateau, 3 x the scatter of -sigma_xx in the target
    before the impact)``, so residual stresses of a polycrystal are not taken
    for a wave.
    """
    x = prof["x"]
    nf = len(prof["t"])
    main, pre, plateau = np.full(nf, np.nan), np.full(nf, np.nan), np.full(nf, np.nan)
    w = x[1] - x[0]
    in_target = (x > x_impact) & (x < x_rear + 5.0 * w)
    ok0 = in_target & (prof["count"][0] > 0)
    if ok0.sum() > 3:
        floor = max(floor, 3.0 * float(np.std(prof["stress"][0, ok0, 0])))
    for f in range(nf):
        p = -prof["stress"][f, :, 0]
        sel = in_target & (prof["count"][f] > 0)
        if sel.sum() < 4:
            continue
        pt = p[sel]
        xs = x[sel]
        peak = np.percentile(pt, 90)
        if peak < 2 * floor:
            continue
        plateau[f] = peak
        above = np.nonzero(pt >= p_threshold_main * peak)[0]
        main[f] = xs[above.max()]
        above = np.nonzero(pt >= max(floor, 0.04 * peak))[0]
        pre[f] = xs[above.max()]
    return main, pre, plateau


def _speed(t, x, lo, hi):
    """Slope of x(t) over the frames with lo < x < hi, up to the first frame that reaches hi
    or the furthest position (the wave has reflected after it)."""
    ok = np.isfinite(x) & (x > lo) & (x < hi)
    if not np.isfinite(x).any():
        return np.nan
    stop = int(np.nanargmax(x))
    reached = np.nonzero(np.isfinite(x) & (x >= hi))[0]
    if len(reached):
        stop = min(stop, int(reached[0]))
    ok[stop + 1:] = False
    if ok.sum() < 3:
        return np.nan
    return float(np.polyfit(t[ok], x[ok], 1)[0])


def analyse_impact(setup, run):
    """Plateaus, front and precursor speeds, intensity, free-surface plateau and pullback (ASE units)."""
    prof = run["profiles"]
    v = setup["v"]
    xi, xr = setup["x_impact"], setup["x_rear"]
    w = prof["x"][1] - prof["x"][0]
    main, pre, plateau = _fronts(prof, xi, xr)
    t = prof["t"]
    # fit while the fronts run through the middle of the target (its own frame moves at -v/2)
    lo, hi = xi + 0.15 * (xr - xi), xr - 3 * w
    D_main = _speed(t, main, lo, hi) + 0.5 * v
    D_pre = _speed(t, pre, lo, hi) + 0.5 * v
    # state behind the main front: the frame where it first passes 75% of the target
    x = prof["x"]
    target_pos = xi + 0.75 * (xr - xi)
    reached = np.nonzero(np.isfinite(main) & (main >= target_pos))[0]
    if len(reached):
        f = int(reached[0])                   # first frame with the front past 75% of the target
    elif np.isfinite(main).any():
        f = int(np.nanargmax(main))
    else:
        f = len(t) - 1
    behind = (x > xi + 1.5 * w) & (x < main[f] - 2.5 * w) & (prof["count"][f] > 0)
    front = (x > main[f] - 3 * w) & (x < main[f] + 2 * w)
    vm = prof["von_mises"][f]
    # the target at rest (frame 0, before contact): residual stress of the sample, the floor
    # under any plateau (a polycrystal's few grains per slab leave a few tenths of a GPa)
    rest = (x > xi + 1.5 * w) & (x < xr - 1.5 * w) & (prof["count"][0] > 0)
    vm_rest = float(np.median(prof["von_mises"][0, rest])) if rest.any() else np.nan
    vm_plateau = float(np.median(vm[behind])) if behind.any() else np.nan
    vm_front = float(vm[front].max()) if front.any() else np.nan
    sxx = float(np.median(-prof["stress"][f, behind, 0])) if behind.any() else np.nan
    u_behind = float(np.median(prof["velocity"][f, behind, 0])) + 0.5 * v if behind.any() else np.nan
    precursor_amp = np.nan
    ahead = (x > main[f] + 2 * w) & (x < pre[f] + w) & (prof["count"][f] > 0)
    if np.isfinite(pre[f]) and ahead.any():
        precursor_amp = float(np.median(-prof["stress"][f, ahead, 0]))
    # free-surface velocity (target rest frame)
    ft, fv = run["fsv_t"], run["fsv_v"]
    arrive = np.nonzero(fv > 0.1 * v)[0]
    fsv_plateau = pullback = t_arrival = fsv_min = np.nan
    cL = lattice_sound_speed(setup["c0"])
    tau = 2.0 * setup["flyer"] / cL
    if len(arrive):
        t_arrival = ft[arrive[0]]
        win = (ft > t_arrival + 0.25 * tau) & (ft < t_arrival + 0.8 * tau)
        if win.any():
            fsv_plateau = float(np.median(fv[win]))
            after = ft > t_arrival + 0.8 * tau
            if after.any():
                fsv_min = float(fv[after].min())
                pullback = fsv_plateau - fsv_min
    return {"frame": f, "t_state": t[f], "main": main, "pre": pre, "plateau": plateau,
            "D_main": D_main, "D_pre": D_pre, "vm_plateau": vm_plateau, "vm_front": vm_front, "vm_rest": vm_rest,
            "sxx_plateau": sxx, "u_behind": u_behind, "precursor_amp": precursor_amp,
            "fsv_plateau": fsv_plateau, "fsv_min": fsv_min, "pullback": pullback, "t_arrival": t_arrival,
            "separated": bool(run["separated"]), "tau": tau}


def _separated(atoms, r0):
    """True if the target has split (a gap wider than 1.5 r0 across its thickness) or left the flyer."""
    x = np.sort(atoms.positions[:, 0])
    gaps = np.diff(x)
    return bool(gaps.max() > 1.5 * r0)


# --------------------------------------------------------------------------- output
def _pick_frames(prof, times):
    t = prof["t"]
    return sorted({int(np.argmin(np.abs(t - tt))) for tt in times})


def plot_impact(results, path, times_by_sample):
    plt = matplotlib_agg()
    n = len(results)
    fig, axs = plt.subplots(n, 3, figsize=(16, 4.2 * n), squeeze=False)
    for row, (name, (setup, run, an)) in enumerate(results.items()):
        prof = run["profiles"]
        x = prof["x"] / units.um
        frames = _pick_frames(prof, times_by_sample[name])
        cols = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for k, f in enumerate(frames):
            ok = prof["count"][f] > 0
            c = cols[k % len(cols)]
            lab = f"t = {prof['t'][f] / units.ns:.0f} ns"
            axs[row, 0].plot(x[ok], prof["stress"][f, ok, 0] / units.GPa, "-", color=c, lw=1.3, label=lab + " xx")
            axs[row, 0].plot(x[ok], prof["stress"][f, ok, 1] / units.GPa, "--", color=c, lw=0.9)
            axs[row, 0].plot(x[ok], prof["stress"][f, ok, 2] / units.GPa, ":", color=c, lw=0.9)
            axs[row, 1].plot(x[ok], prof["von_mises"][f, ok] / units.GPa, "-", color=c, lw=1.2, label=lab)
        axs[row, 0].set_ylabel("stress (GPa): xx solid, yy dashed, zz dotted")
        axs[row, 1].set_ylabel("von Mises intensity (GPa)")
        axs[row, 1].axhline(an["vm_plateau"] / units.GPa, color="k", lw=0.7, ls="--",
                            label=f"plateau {an['vm_plateau'] / units.GPa:.3f} GPa")
        for c in (0, 1):
            axs[row, c].set_xlabel("x (um)")
            axs[row, c].legend(fontsize=7)
            axs[row, c].axvline(setup["x_impact"] / units.um, color="gray", lw=0.5)
        axs[row, 0].set_title(f"{name}: stress profiles (target at right)")
        axs[row, 1].set_title(f"{name}: intensity, front peak {an['vm_front'] / units.GPa:.2f} GPa")
        vm = np.where(prof["count"] > 0, prof["von_mises"], np.nan) / units.GPa
        im = axs[row, 2].imshow(vm, aspect="auto", origin="lower", cmap="viridis",
                                extent=[x[0], x[-1], prof["t"][0] / units.ns, prof["t"][-1] / units.ns],
                                vmin=0, vmax=np.nanpercentile(vm, 99))
        tt = prof["t"] / units.ns
        axs[row, 2].plot(an["main"] / units.um, tt, "w.", ms=3,
                         label=f"main wave {an['D_main'] / units.km_s:.2f} km/s")
        axs[row, 2].plot(an["pre"] / units.um, tt, "r.", ms=2,
                         label=f"precursor {an['D_pre'] / units.km_s:.2f} km/s")
        axs[row, 2].set_xlim(x[0], x[-1])
        axs[row, 2].set_xlabel("x (um)")
        axs[row, 2].set_ylabel("t (ns)")
        axs[row, 2].legend(fontsize=7, loc="upper left")
        axs[row, 2].set_title(f"{name}: x-t map of the intensity (GPa)")
        fig.colorbar(im, ax=axs[row, 2])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_visar(results, path):
    plt = matplotlib_agg()
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    v = None
    for name, (setup, run, an) in results.items():
        v = setup["v"]
        ax.plot(run["fsv_t"] / units.ns, run["fsv_v"] / units.m_s, lw=1.2,
                label=f"{name}: plateau {an['fsv_plateau'] / units.m_s:.0f} m/s, pullback "
                      f"{an['pullback'] / units.m_s:.0f} m/s")
    if v is not None:
        ax.axhline(v / units.m_s, color="k", ls="--", lw=0.8, label=f"impact speed {v / units.m_s:.0f} m/s")
    ax.set_xlabel("t (ns)")
    ax.set_ylabel("rear free-surface velocity (m/s, target frame)")
    ax.set_title("VISAR trace of the target's rear face")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_visar_csv(path, run):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_ns", "free_surface_velocity_m_s"])
        for t, u in zip(run["fsv_t"], run["fsv_v"]):
            w.writerow([f"{t / units.ns:.6g}", f"{u / units.m_s:.6g}"])
    return path


# --------------------------------------------------------------------------- scene: plate impact
PARAMS = [
    Param("sample", "both", "single crystal ([100]), polycrystal, or both", kind="choice",
          choices=("single", "polycrystal", "both")),
    Param("v", 500.0, "relative impact speed (each plate moves at v/2)", unit="m/s", low=0.0,
          high=5000.0, low_open=True),
    Param("r0", 10.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("flyer", 25.0, "flyer thickness, in r0", low=4.0),
    Param("target", 50.0, "target thickness, in r0", low=4.0),
    Param("width", 16.0, "periodic width across (y, z), in r0 (rounded to sqrt(2) r0 cells)", low=3.0),
    Param("grain_size", 8.0, "polycrystal: mean grain diameter, in r0", low=3.0),
    Param("d_min", 0.85, "polycrystal: minimum distance at grain boundaries, in r0", low=0.6, high=1.1),
    Param("porosity", None, "polycrystal: target porosity (sets d_min by bisection)", low=0.0,
          high=0.5, optional=True),
    Param("J", 50.0, "pair damping Gamma = c0/(J r0) (free surfaces: damped); none = off", low=0.0,
          low_open=True, optional=True),
    Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
    Param("seed", 1, "random seed (grains, orientations, noise)", kind="int", low=0),
    Param("duration", None, "run time; none = (target + 3 flyer)/c_L (x1.6 for a polycrystal)",
          unit="ns", low=0.0,
          low_open=True, optional=True),
    Param("profile_times", "auto", "profile times in ns, comma separated, or auto (5 times "
          "while the wave crosses the target)", kind="str"),
    Param("frames", 60, "profiles recorded over the run", kind="int", low=5),
    Param("relax_cycles", 12, "polycrystal: quench cycles of 100 steps before the impact", kind="int", low=0),
    Param("packing", None, "polycrystal: a packing preset or JSON file (clusterdyn.scenes.packing; sets grain "
          "size, porosity and boundaries, e.g. the boundary law); none = the parameters above", kind="str",
          optional=True),
    Param("boundaries", "bonded", "polycrystal: grain-boundary pairs attract like any pair (bonded) or only "
          "repel (repulsive: set-up bonds inside grains only)", kind="choice", choices=("bonded", "repulsive")),
]


def _profile_times(text, setup):
    if str(text).strip().lower() == "auto":
        cL = lattice_sound_speed(setup["c0"])
        transit = setup["target"] / cL
        return [f * transit for f in (0.2, 0.4, 0.6, 0.8, 1.0)]
    items = [s.strip() for s in str(text).split(",")]
    try:
        ts = [float(s) * units.ns for s in items]
    except ValueError:
        raise InputError("profile_times", text, "auto or times in ns like 20,40,60") from None
    if not ts or not all(math.isfinite(t) and t >= 0 for t in ts):
        raise InputError("profile_times", text, "auto or times in ns >= 0 like 20,40,60")
    return ts


def impact_quantities(name, setup, an, mat):
    v = setup["v"]
    p = "sc_" if name == "single" else "pc_"
    ref = hugoniot(mat.hugoniot or "Al-1100") if mat.name == "Al" else None
    u = 0.5 * v
    Pref = ref.rho0_g_cm3 * units.g_cm3 * ref.D(u) * u / units.GPa if ref else None
    q = {
        p + "sigma_u_plateau": Quantity(an["vm_plateau"] / units.GPa, "GPa",
                                        note="von Mises intensity behind the front (median of slabs)"),
        p + "sigma_u_front": Quantity(an["vm_front"] / units.GPa, "GPa", note="intensity peak at the front"),
        p + "sigma_u_rest": Quantity(an["vm_rest"] / units.GPa, "GPa",
                                     note="intensity in the target before the impact (residual stress)"),
        p + "sigma_xx_plateau": Quantity(an["sxx_plateau"] / units.GPa, "GPa", Pref,
                                         note="-sigma_xx behind the front vs rho0 D u (Al-1100, u = v/2)"),
        p + "u_behind": Quantity(an["u_behind"] / units.m_s, "m/s", u / units.m_s,
                                 note="particle velocity behind the front, target frame"),
        p + "D_main": Quantity(an["D_main"] / units.km_s, "km/s", ref.D(u) / units.km_s if ref else None,
                               note="main wave speed in the target's frame vs the Hugoniot"),
        p + "D_precursor": Quantity(an["D_pre"] / units.km_s, "km/s",
                                    note="speed of the leading edge (4% of the plateau or 0.15 GPa)"),
        p + "precursor_amp": Quantity(an["precursor_amp"] / units.GPa, "GPa",
                                      note="-sigma_xx between precursor and main front"),
        p + "fsv_plateau": Quantity(an["fsv_plateau"] / units.m_s, "m/s", v / units.m_s,
                                    note="rear free-surface velocity plateau vs the impact speed"),
        p + "pullback": Quantity(an["pullback"] / units.m_s, "m/s",
                                 note="free-surface plateau minus the minimum after it"),
    }
    if setup["reports"][0]:
        por = np.mean([r["porosity"] for r in setup["reports"]])
        q[p + "porosity"] = Quantity(por, "", note="1 - rho/rho0 of the plates as built")
    return q, ref


class PlateImpactScene(SceneDef):
    """The ``plate-impact`` scene on the lifecycle (one stage per sample)."""

    name = "plate-impact"
    description = ("two Al plates colliding: stress and von Mises profiles, precursor, VISAR trace; "
                   "single crystal vs polycrystal")
    params = scene_params(PARAMS)
    setup_class = ImpactSetup

    def check(self, v):
        if v.sample != "single" and v.grain_size > 2 * min(v.flyer, v.target):
            raise InputError("grain_size", v.grain_size, f"at most twice the thinner plate "
                             f"({min(v.flyer, v.target):g} r0)")
        _profile_times(v.profile_times, {"c0": 1.0, "target": 1.0})
        if v.packing is not None:
            from .packing import resolve_packing
            resolve_packing(v.packing)            # checked before any work

    def plan(self, v):
        return ["single", "polycrystal"] if v.sample == "both" else [v.sample]

    def setup(self, v, stage):
        s = build_impact(stage, "Al", v.v, v.r0, v.flyer, v.target, v.width, v.grain_size,
                         v.d_min, v.porosity, v.seed, v.noise, v.J, relax_cycles=v.relax_cycles,
                         boundaries=v.boundaries, packing=v.packing)
        setup = ImpactSetup.built(s)
        setup.nsteps = int(math.ceil(impact_duration(setup, v.duration) / s["dt"]))
        return setup

    def attach(self, v, stage, setup):
        end = impact_duration(setup, v.duration)
        late = [t for t in _profile_times(v.profile_times, setup) if t > end * (1 + 1e-9)]
        if late:
            raise InputError("profile_times", v.profile_times, f"times within the run, 0-{end / units.ns:.4g} ns "
                             "(set duration to run longer)")
        rec = ImpactRecord(setup)
        return Stage(stage, setup.atoms, setup.dyn, int(setup.nsteps), v.frames, on_frame=rec.frame, analysis=rec,
                     observers=[(rec.fsv, 5)])

    def finish(self, v, stage):
        rec = stage.analysis
        return {"name": stage.name, "info": stage.info, "profiles": rec.rec.arrays(),
                "fsv_t": np.array(rec.fsv_t), "fsv_v": np.array(rec.fsv_v), "nsteps": stage.nsteps,
                "t_run": stage.t_run, "separated": _separated(stage.atoms, stage.info["r0"]), "n": len(stage.atoms)}

    def _results(self, summaries):
        return {sm["name"]: (sm["info"], sm, analyse_impact(sm["info"], sm)) for sm in summaries}

    def analyse(self, v, summaries):
        results = self._results(summaries)
        quantities, notes = {}, []
        mat = get_material("Al")
        for name, (info, run, an) in results.items():
            q, ref = impact_quantities(name, info, an, mat)
            quantities.update(q)
            notes.append(f"{name}: {run['n']} clusters, {run['nsteps']} steps, {run['t_run']:.1f} s stepping, "
                         f"{'target split or separated' if an['separated'] else 'no separation'}")
            if info["reports"][0]:
                notes.append("polycrystal flyer: " + _summary(info["reports"][0]))
            if info["relax"]:
                st = np.asarray(info["relax"]["stress"]) / units.GPa
                notes.append(f"relaxed: mean stress xx yy zz = {st[0]:.3f} {st[1]:.3f} {st[2]:.3f} GPa, nearest "
                             f"pair {info['relax']['min_r_over_r0']:.3f} r0")
        if "single" in results and "polycrystal" in results:
            a, b = results["single"][2], results["polycrystal"][2]
            quantities["plateau_ratio"] = Quantity(b["vm_plateau"] / a["vm_plateau"], "",
                                                   note="polycrystal / single-crystal intensity plateau")
        return quantities, notes, {}, results

    def report(self, v, summaries, result, out):
        results = result.data
        times_by = {name: _profile_times(v.profile_times, info) for name, (info, _, _) in results.items()}
        plot_impact(results, out / "plate_impact_profiles.png", times_by)
        plot_visar(results, out / "plate_impact_visar.png")
        files = [out / "plate_impact_profiles.png", out / "plate_impact_visar.png"]
        for name, (info, run, an) in results.items():
            prof = run["profiles"]
            files.append(write_profiles_csv(out / f"plate_impact_profiles_{name}.csv", prof,
                                            frames=_pick_frames(prof, times_by[name])))
            files.append(write_visar_csv(out / f"plate_impact_visar_{name}.csv", run))
        return files


register_scene(PlateImpactScene())


def _summary(r):
    return (f"{r['n_clusters']} clusters, {r['n_grains']} grains, {r['clusters_per_grain_mean']:.0f} per "
            f"grain, porosity {100 * r['porosity']:.1f}%, d_min {r['d_min_r0']:.3f} r0")
