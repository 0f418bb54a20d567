"""Scene ``hypervelocity``: an aluminium sphere through a thin aluminium plate (the CD paper's Table 2).

A sphere of Al-2024 (standing for the 2017-T4 of Piekutowski's shots, the
nearest documented alloy) of 9.53 mm flies at 6.7 km/s along ``-axis``
onto a round plate of Al-6061-T6, 1.6 mm thick, of radius 25 mm (about three
hole radii: the hole does not feel the edge; ``radius`` changes it).  The
plate thickness is not given by the CD paper's sources: 1.6 mm is the
thickness for which the empirical hole-size law
``d/D = 0.45 V (t/D)^(2/3) + 0.9`` (V in km/s) gives the measured 17.3 mm, so
the comparison of the hole goes through that law.  Both bodies are fcc
single crystals: the plate with [100] along its normal, the sphere in a
random orientation drawn from ``seed`` (which also seeds the 10 m/s initial
noise that breaks the lattice's symmetry).

Measured (``clusterdyn.analysis.impact``), every 0.25 us and at the end:

* **hole diameter** (in the mid-plane): the plate's clusters within its
  original slab (the plate's thickness about its mid-plane) are projected on
  its plane; on an r0 mesh the empty cells connected to the impact point are
  the perforation; d is the diameter of the circle of equal area.  The final
  value is the one at the end of the run; its change over the last quarter
  of the run is reported (the plate has stopped deforming when it is
  small).  The lip around the hole bends out of the plate's slab; the
  **through-hole** (the narrowest opening of the bent plate: every cluster
  of the plate's largest fragment projected, at the end) is reported beside
  it;
* **backward ejecta**: clusters more than r0 in front of the plate's impact
  face moving backward (against the sphere's flight); theta is the
  half-angle about the plate normal, apex at the impact point, of the cone
  holding 90% of their mass; its complement 90 deg - theta is the cone's
  angle to the plate plane (the CD paper does not say which it quotes); the
  cone holding half the mass is reported too (``ejecta_median_angle_to_plane``);
* **debris cloud**: clusters more than r0 behind the plate's rear face
  moving forward; its leading edge is the 99.9th percentile of their
  distance from the rear face (single strays do not count), the length is
  that minus the 0.1th percentile, the diameter twice the 99.9th percentile
  of their distance from the axis; the leading-edge speed is the slope of a
  straight-line fit over the second half of the run (no reference data in
  the paper's sources: reported only);
* the **fragment spectrum** at the end (``analysis.fragments``, bonds at rc)
  and **radiographs** (projected density on the plane of the axis and the
  first lateral axis) at ``image_times``.

Resolution: ``r0`` (default 0.4 mm: 4 clusters across the plate, about 80k
clusters, a few minutes on 2 cores; the study runs 0.4, 0.267 and 0.2 mm).
Damping J = 50 (the impact scenes' default, scenes.impact_common).
"""

import csv
import math

import numpy as np
from scipy.spatial.transform import Rotation

from .. import units
from ..analysis.ejecta import fit_rate
from ..analysis.fragment_spectra import largest_piece, plot_spectrum
from ..analysis.fragments import fragments
from ..analysis.impact import cone_half_angle, plate_hole
from ..build import parse_axis
from ..build.bodies import combine_bodies, place, plate, sphere
from ..calculators import ClusterDynamics
from ..errors import InputError
from ..materials import cd_material_names
from ..md import DampedVerlet, RegionOfInterest
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, register_scene
from .common import matplotlib_agg, thermal_noise
from .impact_common import (announce_cost, lateral_axes, ledger, ledger_quantities, parse_times, projectile_params,
                            radiograph_frame,
                            retry_halved_dt, write_radiographs)
from .lifecycle import SceneDef, Stage, scene_params

#: Table 2 of the CD paper (Piekutowski's radiograph; the paper's SPH and CD)
TABLE2 = {"experiment": (17.3, 20.67), "SPH": (18.0, 27.08), "CD": (17.0, 39.0)}
#: analysis frames every FRAME_TIME
FRAME_TIME = 0.25 * units.us
#: fraction of the backward ejecta mass inside the cone
CONE_FRACTION = 0.9
#: quantile of the debris' distances taken as the cloud's leading edge (and 1 - it as its rear)
EDGE_Q = 0.999
#: clearance between the sphere and the plate at the start, in r0
START_GAP = 0.2

CD_MATERIALS = tuple(cd_material_names())

PARAMS = [
    Param("r0", 0.4, "cluster size (0.4 mm = 4 clusters across the plate)", unit="mm", low=0.0, low_open=True),
    Param("V", 6.7, "impact speed", unit="km/s", low=0.0, high=20.0, low_open=True),
    Param("diameter", 9.53, "sphere diameter", unit="mm", low=0.0, low_open=True),
    Param("thickness", 1.6, "plate thickness (inferred from the hole-size law, module docstring)", unit="mm",
          low=0.0, low_open=True),
    Param("radius", 25.0, "plate radius", unit="mm", low=0.0, low_open=True),
    Param("sphere_material", "Al-2024", "material of the sphere (Al-2024 stands for 2017-T4)", kind="choice",
          choices=CD_MATERIALS),
    Param("plate_material", "Al-6061-T6", "material of the plate", kind="choice", choices=CD_MATERIALS),
    Param("t_end", 8.0, "run time after contact (the hole is stable from about 3 us on)", unit="us", low=0.0,
          low_open=True),
    Param("keep_within", None, "remove clusters that leave the cube of this half-width about the impact point "
          "(their energy and momentum are booked in the ledger; the H5MD rows keep fill values; the cloud and "
          "ejecta measures then see only what is inside); none = keep all",
          unit="mm", low=0.0, low_open=True, optional=True),
    Param("image_times", "auto", "radiograph times in us, comma separated, or auto (t_end/4, t_end/2, 3 t_end/4, "
          "t_end)", kind="str"),
] + projectile_params(TIMESTEP_FACTOR, "time step as a fraction of r0/(c0 + V)") + [
    Param("axis", "z", "plate normal; the sphere flies along -axis", kind="choice", choices=("x", "y", "z")),
    Param("packing", None, "plate and sphere as polycrystals: a packing preset or JSON file (clusterdyn.scenes.packing; "
          "sets grain size, porosity and boundaries, e.g. the boundary law; rc stays the scene's); none = single "
          "crystals", kind="str", optional=True),
]

#: quench cycles of 100 steps of a polycrystal set-up (``packing``), bodies apart and at rest
RELAX_CYCLES = 12
#: clearance between the bodies during that quench, in r0
RELAX_GAP = 3.0


def build_hypervelocity(v):
    """Plate and sphere, calculator and dynamics; returns ``(atoms, dyn, info)``."""
    r0, V, ax = v.r0, v.V, parse_axis(v.axis)
    t, R, D = v.thickness, v.radius, v.diameter
    e = np.eye(3)[ax]
    rot = Rotation.random(random_state=v["seed"]).as_matrix()
    term, notes = None, []
    if v.get("packing") is None:
        pl = plate(v["plate_material"], r0, t, radius=R, axis=ax, center=(0.0, 0.0, 0.0), orientation="100")
        sp = sphere(v["sphere_material"], r0, D, center=(0.0, 0.0, 0.0), velocity=-V * e, axis=ax, orientation=rot)
        sp = place(sp, pl, axis=ax, gap=START_GAP * r0, side=1, align=True)
        atoms = combine_bodies([pl, sp])
        calc = ClusterDynamics(rc=v["rc"])
        atoms.calc = calc
    else:
        atoms, calc, term, notes = _polycrystal_bodies(v, r0, t, R, D, ax)
    thermal_noise(atoms, v["noise"], v["seed"])
    calc.setup(atoms)
    c0 = max(p.c0 for p in calc.potentials)
    dt = v.dt_factor * r0 / (c0 + V)
    region = None
    if v.get("keep_within") is not None:
        half = float(v.keep_within)
        region = RegionOfInterest(lo=[-half] * 3, hi=[half] * 3)
    dyn = DampedVerlet(atoms, timestep=dt, J=v["J"], region=region)
    if term is not None:
        dyn.attach_piece(term)
    dyn.start_ledger()
    body = atoms.arrays["body"]
    z = atoms.positions[:, ax]
    zp = z[body == 0]
    z_front, z_rear = float(zp.max() + 0.5 * r0), float(zp.min() - 0.5 * r0)
    gap = float(z[body == 1].min() - 0.5 * r0 - z_front)
    t_contact = max(0.0, gap) / V
    nsteps = int(math.ceil((v.t_end + t_contact) / dt))
    announce_cost("hypervelocity", len(atoms), nsteps)
    info = {"r0": r0, "V": V, "axis": ax, "dt": dt, "nsteps": nsteps, "t_contact": t_contact,
            "z_front": z_front, "z_rear": z_rear, "z_mid": 0.5 * (z_front + z_rear), "thickness": t, "radius": R,
            "diameter": D, "n_plate": int((body == 0).sum()), "n_sphere": int((body == 1).sum()),
            "m_sphere_g": float(atoms.get_masses()[body == 1].sum() / units.g),
            "rotation": rot.tolist(), "bodies": [{k: b[k] for k in ("kind", "material", "n_clusters", "porosity")}
                                                 for b in atoms.info["bodies"]]}
    if v.get("packing") is not None:
        info.update({"packing": str(v["packing"]), "packing_notes": notes})
    return atoms, dyn, info


def _polycrystal_bodies(v, r0, t, R, D, ax):
    """Plate and sphere as polycrystals of the packing ``v["packing"]`` (grain size, porosity and
    boundaries; the scene's rc), quenched apart and at rest, then the sphere brought to
    ``START_GAP`` and set flying (:func:`clusterdyn.scenes.packing.quench_and_launch`).
    Returns ``(atoms, calc, term, notes)``."""
    from .packing import quench_and_launch, resolve_packing
    from .plate_impact import relax_sample
    spec = resolve_packing(v["packing"])
    poly = {"grain_size": spec["grain_size"] * r0, "target_porosity": spec["porosity"]}
    pl = plate(v["plate_material"], r0, t, radius=R, axis=ax, center=(0.0, 0.0, 0.0), seed=v["seed"], **poly)
    sp = sphere(v["sphere_material"], r0, D, center=(0.0, 0.0, 0.0), axis=ax, seed=v["seed"] + 1, **poly)
    sp = place(sp, pl, axis=ax, gap=RELAX_GAP * r0, side=1, align=True)
    atoms = combine_bodies([pl, sp])
    calc, term, notes = quench_and_launch(atoms, spec, v["rc"], 1, ax, START_GAP * r0, -v["V"] * np.eye(3)[ax],
                                          lambda a, tm: relax_sample(a, cycles=RELAX_CYCLES, lateral=False, term=tm),
                                          cycles=RELAX_CYCLES)
    return atoms, calc, term, notes


class HyperRecord:
    """Per frame: hole diameter, debris cloud, ejecta; radiographs at the image times."""

    def __init__(self, atoms, dyn, info, image_times):
        self.atoms, self.dyn, self.info = atoms, dyn, info
        self.ax = int(info["axis"])
        self.lat = lateral_axes(self.ax)
        self.image_times = [float(t) for t in image_times]
        self.rows = []
        self.images = []

    def _extent(self):
        R, r0 = self.info["radius"], self.info["r0"]
        return [[-R - 2 * r0, R + 2 * r0], [-R - 2 * r0, R + 2 * r0]]

    def measure(self):
        """The frame's measures (ASE units), a dict."""
        info, ax = self.info, self.ax
        r0 = info["r0"]
        pos = self.atoms.positions
        vel = self.atoms.get_velocities()
        m = self.atoms.get_masses()
        t = self.dyn.get_time() - info["t_contact"]
        hole = plate_hole(pos[self.plate], ax, info["z_rear"], info["z_front"], (0.0, 0.0), r0, self._extent())
        z = pos[:, ax]
        vz = vel[:, ax]
        # debris cloud: behind the rear face, moving forward (-axis)
        deb = (z < info["z_rear"] - r0) & (vz < 0)
        row = {"t": t, "hole_d": hole["d"], "hole_area": hole["area"], "n_debris": int(deb.sum()),
               "lead": np.nan, "tail": np.nan, "cloud_d": np.nan, "n_ejecta": 0, "ejecta_mass": 0.0,
               "theta": np.nan, "theta50": np.nan}
        if deb.sum() >= 10:
            dist = info["z_rear"] - z[deb]
            lat = pos[deb][:, self.lat]
            row["lead"] = float(np.quantile(dist, EDGE_Q))
            row["tail"] = float(np.quantile(dist, 1.0 - EDGE_Q))
            row["cloud_d"] = 2.0 * float(np.quantile(np.hypot(lat[:, 0], lat[:, 1]), EDGE_Q))
        ej = (z > info["z_front"] + r0) & (vz > 0)
        if ej.sum() >= 10:
            apex = np.zeros(3)
            apex[ax] = info["z_front"]
            n = np.zeros(3)
            n[ax] = 1.0
            row["theta"] = cone_half_angle(pos[ej] - apex, m[ej], n, CONE_FRACTION)
            row["theta50"] = cone_half_angle(pos[ej] - apex, m[ej], n, 0.5)
            row["n_ejecta"] = int(ej.sum())
            row["ejecta_mass"] = float(m[ej].sum())
        return row

    def frame(self, d):
        row = self.measure()
        self.rows.append(row)
        t = row["t"]
        while self.image_times and t >= self.image_times[0] - 0.5 * FRAME_TIME:
            self.image_times.pop(0)
            self.images.append(self.image(t))

    @property
    def plate(self):
        """Rows of the plate's clusters in the current Atoms (clusters may have been removed)."""
        return np.nonzero(self.atoms.arrays["body"] == 0)[0]

    def image(self, t):
        return radiograph_frame(self.atoms.positions, self.atoms.get_masses(), self.ax, self.lat[0], self.info["radius"],
                                self.info["r0"], t)

    def get_state(self):
        return {"rows": [dict(r) for r in self.rows], "images": [dict(i) for i in self.images],
                "image_times": list(self.image_times)}

    def set_state(self, st):
        self.rows = [dict(r) for r in st["rows"]]
        self.images = [dict(i) for i in st["images"]]
        self.image_times = [float(t) for t in st["image_times"]]


def _fit_speed(t, x):
    """Slope of x(t) over the second half of the times where x is known (NaN: fewer than 4 known)."""
    ok = np.isfinite(x)
    t, x = np.asarray(t)[ok], np.asarray(x)[ok]
    if len(t) < 4:
        return float("nan")
    return fit_rate(t, x, t[0] + 0.5 * (t[-1] - t[0]), t[-1])[0]


class HypervelocityScene(SceneDef):
    """The ``hypervelocity`` scene on the lifecycle (module docstring)."""

    name = "hypervelocity"
    description = ("Al sphere (9.53 mm, 6.7 km/s) through a 1.6 mm Al plate: hole diameter, ejecta angle, debris "
                   "cloud, fragments, radiographs vs the CD paper's Table 2")
    params = scene_params(PARAMS, h5md_frames=12, checkpoint_every=10)

    def estimate_particles(self, v):
        from .lifecycle import fcc_count
        return fcc_count(math.pi * v.radius ** 2 * v.thickness + math.pi / 6 * v.diameter ** 3, v.r0)

    def check(self, v):
        if v.thickness < v.r0:
            raise InputError("r0", f"{v.r0 / units.mm:g}mm", f"at most the plate thickness "
                             f"{v.thickness / units.mm:g} mm")
        if v.diameter < 2 * v.r0:
            raise InputError("r0", f"{v.r0 / units.mm:g}mm", "at most half the sphere diameter")
        if v.radius < v.diameter:
            raise InputError("radius", f"{v.radius / units.mm:g}mm", f"at least the sphere diameter "
                             f"{v.diameter / units.mm:g} mm (the hole must not reach the edge)")
        if v.keep_within is not None:
            need = max(v.radius, v.diameter + v.thickness) + 2 * v.r0
            if v.keep_within < need:
                raise InputError("keep_within", f"{v.keep_within / units.mm:g}mm", f"at least "
                                 f"{need / units.mm:g} mm (the plate radius or the sphere's start, plus 2 r0: "
                                 "the region must hold the set-up)")
        if v["packing"] is not None:
            from .packing import resolve_packing
            resolve_packing(v["packing"])            # checked before any work
        late = [t for t in parse_times(v["image_times"], "image_times", []) if t > v["t_end"] * (1 + 1e-9)]
        if late:
            raise InputError("image_times", v.image_times, f"auto or times within the run, 0-"
                             f"{v.t_end / units.us:g} us (t_end)")

    def setup(self, v, stage):
        return build_hypervelocity(v)

    def attach(self, v, stage, atoms, dyn, info):
        te = v.t_end
        times = parse_times(v.image_times, "image_times", [0.25 * te, 0.5 * te, 0.75 * te, te])
        rec = HyperRecord(atoms, dyn, info, [t for t in times if t <= te + 1e-9 * te])
        nframes = max(1, int(round(info["nsteps"] * info["dt"] / FRAME_TIME)))
        return Stage(stage, atoms, dyn, int(info["nsteps"]), nframes, info, on_frame=rec.frame, analysis=rec)

    def retry(self, v, stage, exc, attempt):
        return retry_halved_dt(v, exc, attempt)

    def finish(self, v, stage):
        atoms, dyn, rec = stage.atoms, stage.dyn, stage.analysis
        if not rec.images or rec.images[-1]["t"] < rec.rows[-1]["t"] - 0.5 * FRAME_TIME:
            rec.images.append(rec.image(rec.rows[-1]["t"]))
        fr = fragments(atoms)
        body = atoms.arrays["body"]
        info = stage.info
        # the through-hole: every cluster of the plate's largest fragment, projected
        main = largest_piece(fr.labels, rec.plate)
        through = plate_hole(atoms.positions[main], info["axis"], -np.inf, np.inf, (0.0, 0.0), info["r0"],
                             rec._extent())["d"]
        sphere_mass = np.bincount(fr.labels, weights=atoms.get_masses() * (body == 1), minlength=fr.n_fragments)
        order = np.argsort(-fr.mass)[:10]
        return {"info": stage.info, "rows": rec.get_state()["rows"], "images": rec.images,
                "g": fr.g, "frag_mass": fr.mass, "frag_v": fr.velocity, "frag_sphere_mass": sphere_mass,
                "largest": order, "ledger": ledger(dyn), "steps": int(dyn.nsteps), "t_run": stage.t_run,
                "n": len(atoms), "nbuilds": int(atoms.calc.nl.nbuilds), "through": float(through)}

    def analyse(self, v, summaries):
        sm = summaries[0]
        info = sm["info"]
        rows = sm["rows"]
        t = np.array([r["t"] for r in rows])
        d = np.array([r["hole_d"] for r in rows])
        last = rows[-1]
        late = t >= t[-1] - 0.25 * (t[-1] - t[0])
        d_late = d[late & np.isfinite(d)]
        change = float((d_late.max() - d_late.min()) / d[-1]) if len(d_late) and d[-1] > 0 else float("nan")
        theta = last["theta"]
        lead = np.array([r["lead"] for r in rows])
        u_lead = _fit_speed(t, lead)
        exp_d, exp_th = TABLE2["experiment"]
        q = {
            "hole_diameter": Quantity(last["hole_d"] / units.mm, "mm", exp_d,
                                      note="equal-area circle of the perforation (Piekutowski 17.3 mm)"),
            "hole_through": Quantity(sm["through"] / units.mm, "mm", note="narrowest opening of the bent plate "
                                     "(its largest fragment projected)"),
            "hole_change": Quantity(change, "", note="relative change of the hole diameter over the last quarter "
                                    "of the run"),
            "ejecta_half_angle": Quantity(math.degrees(theta), "deg", exp_th,
                                          note="half-angle from the plate normal of the cone with 90% of the "
                                          "backward ejecta mass"),
            "ejecta_angle_to_plane": Quantity(90.0 - math.degrees(theta), "deg", exp_th,
                                              note="the same cone's angle to the plate plane"),
            "ejecta_median_angle_to_plane": Quantity(90.0 - math.degrees(last["theta50"]), "deg",
                                                     note="angle to the plate plane of the cone holding half "
                                                     "the backward ejecta mass"),
            "ejecta_mass": Quantity(last["ejecta_mass"] / units.g, "g", note="mass ejected backward"),
            "cloud_lead_speed": Quantity(u_lead / units.km_s, "km/s", note="debris cloud leading edge, fit over "
                                         "the second half (no reference data)"),
            "cloud_length": Quantity((last["lead"] - last["tail"]) / units.mm, "mm", note="at the end"),
            "cloud_diameter": Quantity(last["cloud_d"] / units.mm, "mm", note="at the end"),
            "t_end": Quantity(last["t"] / units.us, "us", note="time after contact at the end"),
        }
        g, mass, vel = np.asarray(sm["g"]), np.asarray(sm["frag_mass"]), np.asarray(sm["frag_v"])
        order = np.asarray(sm["largest"], dtype=np.int64)
        notes = []
        for k, f in enumerate(order[:3]):
            sp = float(np.linalg.norm(vel[f]))
            q[f"fragment{k + 1}_mass"] = Quantity(mass[f] / units.g, "g", note=f"{g[f]} clusters, "
                                                  f"{100 * sm['frag_sphere_mass'][f] / mass[f]:.0f}% sphere material")
            q[f"fragment{k + 1}_speed"] = Quantity(sp / units.km_s, "km/s")
        q["n_fragments"] = Quantity(float(len(g)), "", note="fragments at the end (bonds at rc)")
        lq, lnote = ledger_quantities(sm["ledger"])
        q.update(lq)
        notes.append(f"sphere {info['n_sphere']} clusters ({info['m_sphere_g']:.3f} g), plate {info['n_plate']} "
                     f"clusters, r0 = {info['r0'] / units.mm:g} mm = {info['thickness'] / info['r0']:.3g} "
                     f"clusters across the plate, plate radius {info['radius'] / units.mm:g} mm")
        notes.append(f"{sm['steps']} steps of {info['dt'] / units.ns:.4g} ns, {sm['t_run']:.1f} s stepping, "
                     f"{sm['n'] * sm['steps'] / max(sm['t_run'], 1e-9):.3g} particle-steps/s, {sm['nbuilds']} "
                     "neighbour-list builds")
        notes.append("Table 2 (d mm, theta deg): experiment 17.3 / 20.67, the paper's SPH 18.0 / 27.08, its CD "
                     "17 / 39; plate thickness 1.6 mm inferred from the hole-size law")
        notes.append(lnote)
        notes += info.get("packing_notes", [])
        for r in v.retried:
            notes.append(f"time step halved after a stop: {r}")
        extra = {"history": {k: [r[k] for r in rows] for k in rows[0]}, "ledger_J": sm["ledger"],
                 "n_clusters": sm["n"], "steps": sm["steps"], "stepping_time_s": sm["t_run"]}
        return q, notes, extra

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        files = []
        files += write_radiographs(sm["images"], out / "hypervelocity_radiographs.png",
                                   out / "hypervelocity_radiographs.csv",
                                   labels=("xyz"[lateral_axes(sm["info"]["axis"])[0]], "xyz"[sm["info"]["axis"]]),
                                   title=f"sphere through plate, r0 = {sm['info']['r0'] / units.mm:g} mm")
        gs, n = np.unique(np.asarray(sm["g"]), return_counts=True)
        files += plot_spectrum(out / "hypervelocity_fragments.png", gs, n)
        files += write_history(out / "hypervelocity_history.png", sm["rows"])
        return files


def write_history(png, rows):
    """Hole diameter, ejecta angle and cloud leading edge against time (PNG + CSV)."""
    plt = matplotlib_agg()
    t = np.array([r["t"] for r in rows]) / units.us
    d = np.array([r["hole_d"] for r in rows]) / units.mm
    th = np.degrees(np.array([r["theta"] for r in rows], dtype=float))
    lead = np.array([r["lead"] for r in rows]) / units.mm
    fig, axs = plt.subplots(3, 1, figsize=(6, 7), sharex=True)
    axs[0].plot(t, d)
    axs[0].axhline(TABLE2["experiment"][0], color="r", ls="--", label="experiment")
    axs[0].set_ylabel("hole diameter (mm)")
    axs[0].legend(fontsize=8)
    axs[1].plot(t, th, label="half-angle from the normal")
    axs[1].plot(t, 90 - th, label="angle to the plate")
    axs[1].axhline(TABLE2["experiment"][1], color="r", ls="--", label="experiment")
    axs[1].set_ylabel("ejecta cone (deg)")
    axs[1].legend(fontsize=8)
    axs[2].plot(t, lead)
    axs[2].set_ylabel("cloud leading edge (mm)")
    axs[2].set_xlabel("t after contact (us)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
    path = png.with_suffix(".csv")
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_us", "hole_d_mm", "ejecta_half_angle_deg", "cloud_lead_mm", "cloud_tail_mm",
                    "cloud_diameter_mm", "ejecta_mass_g", "n_debris"])
        for r in rows:
            w.writerow([f"{r['t'] / units.us:.5g}", f"{r['hole_d'] / units.mm:.5g}",
                        f"{math.degrees(r['theta']):.4g}" if np.isfinite(r["theta"]) else "nan",
                        f"{r['lead'] / units.mm:.5g}", f"{r['tail'] / units.mm:.5g}",
                        f"{r['cloud_d'] / units.mm:.5g}", f"{r['ejecta_mass'] / units.g:.5g}", r["n_debris"]])
    return [png, path]


register_scene(HypervelocityScene())
