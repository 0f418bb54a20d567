"""Scene ``multilayer``: a steel sphere through a stack of textolite, aluminium, steel and paraffin plates.

The CD paper's fig. 23: an iron sphere of 13.5 mm (10 g; the library's
``steel``, 4340, stands for iron: 10.1 g) at 6.5 km/s along ``+axis`` hits,
in order, textolite 15 mm and aluminium 4 mm (Al-6061-T6, the library's
documented alloy) in contact, a 25 mm air gap, then steel 10 mm, paraffin
20 mm, steel 10 mm, paraffin 60 mm, steel 10 mm in contact.  The paper's
plates are 300 x 300 mm; here they are cut to round plates of radius 50 mm
(``radius``), which holds every hole well inside the plate.  Plates "in
contact" are placed 0.2 r0 apart (clearance between the cluster spheres,
``build.bodies.place``): they touch but are not bonded, and interact (with
the mixed pair law of the two materials) once pressed together.  Every
plate is an fcc single crystal with [100] along the axis; the sphere is a
single crystal in a random orientation drawn from ``seed``.  Textolite and
paraffin have no sourced Hugoniot: their CD materials are the library's
documented estimates (docs/hugoniot.md).

Reported at ``t_end`` (default 67.6 us after contact, the radiograph of the
paper's fig. 24): for each layer whether it is perforated and the hole's
diameter (the clusters of the layer's largest remaining piece within its
original slab widened by r0 on each side, projected on its plane: the empty r0-mesh cells connected to
the axis, as a circle of equal area: for a thick layer the narrowest
cross-section of the channel; NaN when the opening reaches the plate's
rim); the mass, axial speed and make-up of the largest fragments that are
not plate remnants (fragments with a cluster within 3 r0 of a plate's rim
count as remnants); the residual speed of the projectile (its largest
piece); a radiograph at the image times (default t_end/3, 2 t_end/3, t_end).

Resolution: ``r0`` (default 1 mm: about 1.4 million clusters and some
10 000 steps, an hour or more on 2 cores: a study-size run; the scene says
so when it starts).  The test suite runs ``r0=2.5mm radius=15mm t_end=8``.
Damping J = 50 (the impact scenes' default, scenes.impact_common).  Time
step: 0.06 r0/(c0 + V) with the smallest c0 of the stack (textolite), twice
the project's default: on a coarse stack (r0 2.5 mm, radius 25 mm, 30 us)
0.03, 0.06 and 0.1 give the same perforated layers, holes within half an r0
of each other and projectile speeds within 2%, with energy residuals of
2-5e-4 of the kinetic energy; it halves the default run.
"""

import csv
import math

import numpy as np
from scipy.spatial.transform import Rotation

from .. import units
from ..analysis.fragment_spectra import largest_piece
from ..analysis.fragments import fragments
from ..analysis.impact import plate_hole
from ..build import parse_axis
from ..build.bodies import combine_bodies, place, plate, plate_stack, sphere
from ..calculators import ClusterDynamics
from ..errors import InputError
from ..materials import cd_material_names
from ..md import DampedVerlet
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, register_scene
from .common import thermal_noise
from .impact_common import (announce_cost, lateral_axes, ledger, ledger_quantities, parse_times, projectile_params,
                            radiograph_frame,
                            retry_halved_dt, write_radiographs)
from .lifecycle import SceneDef, Stage, scene_params

#: the stack of the CD paper's fig. 23, from the impact side: (material, thickness)
LAYERS = [("textolite", 15.0 * units.mm), ("Al-6061-T6", 4.0 * units.mm), ("steel", 10.0 * units.mm),
          ("paraffin", 20.0 * units.mm), ("steel", 10.0 * units.mm), ("paraffin", 60.0 * units.mm),
          ("steel", 10.0 * units.mm)]
#: the gaps between consecutive layers: None = in contact (CONTACT_GAP r0), else a length
GAPS = [None, 25.0 * units.mm, None, None, None, None]
#: clearance of layers in contact, in r0 (beyond the cutoff: touching, not bonded)
CONTACT_GAP = 0.2
#: clearance between the sphere and the first layer at the start, in r0
START_GAP = 0.2
#: analysis frames every FRAME_TIME
FRAME_TIME = 1.0 * units.us
#: fragments with a cluster within this many r0 of a plate's rim are plate remnants
RIM = 3.0
#: largest fragments reported
N_LARGEST = 5
#: default time-step factor: twice the project's TIMESTEP_FACTOR (module docstring)
DT_FACTOR = 2 * TIMESTEP_FACTOR

CD_MATERIALS = tuple(cd_material_names())

PARAMS = [
    Param("r0", 1.0, "cluster size (1 mm: about 1.4 million clusters, about an hour on 2 cores)", unit="mm",
          low=0.0, low_open=True),
    Param("V", 6.5, "impact speed", unit="km/s", low=0.0, high=20.0, low_open=True),
    Param("diameter", 13.5, "sphere diameter", unit="mm", low=0.0, low_open=True),
    Param("sphere_material", "steel", "material of the sphere (steel stands for the paper's iron)",
          kind="choice", choices=CD_MATERIALS),
    Param("radius", 50.0, "radius of the round plates (the paper's are 300 x 300 mm)", unit="mm", low=0.0,
          low_open=True),
    Param("t_end", 67.6, "run time after contact (the paper's radiograph is at 67.6 us)", unit="us", low=0.0,
          low_open=True),
    Param("image_times", "auto", "radiograph times in us, comma separated, or auto (t_end/3, 2 t_end/3, t_end)",
          kind="str"),
] + projectile_params(DT_FACTOR, "time step as a fraction of the smallest r0/(c0 + V) (default twice the "
                      "project's 0.03, module docstring)") + [
    Param("axis", "z", "the stack's axis; the sphere flies along +axis", kind="choice", choices=("x", "y", "z")),
    Param("packing", None, "every layer and the sphere as polycrystals: a packing preset or JSON file "
          "(clusterdyn.scenes.packing; grain size, porosity and boundaries, the same for every material; rc stays "
          "the scene's); none = single crystals", kind="str", optional=True),
]

#: quench cycles of 100 steps of a polycrystal set-up (``packing``), bodies at rest
RELAX_CYCLES = 12
#: clearance between the sphere and the stack during that quench, in r0
RELAX_GAP = 3.0


def build_multilayer(v):
    """The stack and the sphere, calculator and dynamics; returns ``(atoms, dyn, info)``."""
    r0, V, ax = v.r0, v.V, parse_axis(v.axis)
    e = np.eye(3)[ax]
    gaps = [CONTACT_GAP * r0 if g is None else g for g in GAPS]
    rot = Rotation.random(random_state=v["seed"]).as_matrix()
    term, notes = None, []
    if v.get("packing") is None:
        stack = plate_stack(LAYERS, r0, v["radius"], gaps=gaps, axis=ax, origin=(0.0, 0.0, 0.0), orientation="100")
        sp = sphere(v["sphere_material"], r0, v["diameter"], velocity=V * e, axis=ax, orientation=rot)
        sp = place(sp, stack, axis=ax, gap=START_GAP * r0, side=-1, align=True)
        atoms = combine_bodies([stack, sp])
        calc = ClusterDynamics(rc=v["rc"])
        atoms.calc = calc
    else:
        atoms, calc, term, notes = _polycrystal_stack(v, r0, ax, gaps)
    thermal_noise(atoms, v["noise"], v["seed"])
    calc.setup(atoms)
    dt = v["dt_factor"] * min(p.r0 / (p.c0 + V) for p in calc.potentials)
    dyn = DampedVerlet(atoms, timestep=dt, J=v["J"])
    if term is not None:
        dyn.attach_piece(term)
    dyn.start_ledger()
    body = atoms.arrays["body"]
    z = atoms.positions[:, ax]
    nl = len(LAYERS)
    layers = []
    for k, (mat, t) in enumerate(LAYERS):
        zk = z[body == k]
        layers.append({"material": mat, "thickness": t, "lo": float(zk.min() - 0.5 * r0),
                       "hi": float(zk.max() + 0.5 * r0), "n": int((body == k).sum())})
    gap = float(layers[0]["lo"] - (z[body == nl].max() + 0.5 * r0))
    t_contact = max(0.0, gap) / V
    nsteps = int(math.ceil((v.t_end + t_contact) / dt))
    announce_cost("multilayer", len(atoms), nsteps)
    m = atoms.get_masses()
    info = {"r0": r0, "V": V, "axis": ax, "dt": dt, "nsteps": nsteps, "t_contact": t_contact, "layers": layers,
            "radius": v.radius, "n_sphere": int((body == nl).sum()), "sphere_body": nl,
            "m_sphere_g": float(m[body == nl].sum() / units.g), "rotation": rot.tolist()}
    if v.get("packing") is not None:
        info.update({"packing": str(v["packing"]), "packing_notes": notes})
    return atoms, dyn, info


def _polycrystal_stack(v, r0, ax, gaps):
    """Every layer and the sphere as polycrystals of the packing ``v["packing"]`` (grain size, porosity
    and boundaries, the same for every material; the scene's rc; layer k seeded ``seed + k``),
    quenched at rest, then the sphere brought to ``START_GAP`` and set flying
    (:func:`clusterdyn.scenes.packing.quench_and_launch`).  Returns ``(atoms, calc, term, notes)``."""
    from .packing import quench_and_launch, resolve_packing
    from .plate_impact import relax_sample
    spec = resolve_packing(v["packing"])
    poly = {"grain_size": spec["grain_size"] * r0, "target_porosity": spec["porosity"]}
    e = np.eye(3)[ax]
    plates = []
    for k, (mat, t) in enumerate(LAYERS):
        p = plate(mat, r0, t, radius=v["radius"], axis=ax, center=0.5 * t * e, seed=v["seed"] + k, **poly)
        if k:
            p = place(p, plates[-1], axis=ax, gap=float(gaps[k - 1]), side=1, align=True)
        plates.append(p)
    stack = combine_bodies(plates)
    sp = sphere(v["sphere_material"], r0, v["diameter"], axis=ax, seed=v["seed"] + len(LAYERS), **poly)
    sp = place(sp, stack, axis=ax, gap=RELAX_GAP * r0, side=-1, align=True)
    atoms = combine_bodies([stack, sp])
    calc, term, notes = quench_and_launch(atoms, spec, v["rc"], len(LAYERS), ax, START_GAP * r0, v["V"] * e,
                                          lambda a, tm: relax_sample(a, cycles=RELAX_CYCLES, lateral=False, term=tm),
                                          cycles=RELAX_CYCLES)
    return atoms, calc, term, notes


class StackRecord:
    """Per frame: each layer's hole; radiographs at the image times."""

    def __init__(self, atoms, dyn, info, image_times):
        self.atoms, self.dyn, self.info = atoms, dyn, info
        self.ax = int(info["axis"])
        body = atoms.arrays["body"]
        self.rows_of = [np.nonzero(body == k)[0] for k in range(len(info["layers"]))]
        self.m = atoms.get_masses()
        self.image_times = [float(t) for t in image_times]
        self.rows = []
        self.images = []

    def holes(self):
        info, r0, R = self.info, self.info["r0"], self.info["radius"]
        ext = [[-R - 2 * r0, R + 2 * r0], [-R - 2 * r0, R + 2 * r0]]
        out = []
        pos = self.atoms.positions
        # each layer's largest remaining piece: debris of the layer that still lies in its slab
        # (ejecta, spall, petals torn off) would otherwise close the opening in projection
        # bonds at the run's cutoff (read from the dynamics' calculator: the Atoms measured may be a
        # frame read back without one, e.g. a LAMMPS run of the same scene)
        labels = fragments(self.atoms, b=self.dyn.atoms.calc.parameters["rc"]).labels
        for k, lay in enumerate(info["layers"]):
            h = plate_hole(pos[largest_piece(labels, self.rows_of[k])], self.ax, lay["lo"] - r0, lay["hi"] + r0,
                           (0.0, 0.0), r0, ext)
            out.append(h["d"])
        return out

    def frame(self, d):
        t = self.dyn.get_time() - self.info["t_contact"]
        self.rows.append({"t": t, "holes": self.holes()})
        while self.image_times and t >= self.image_times[0] - 0.5 * FRAME_TIME:
            self.image_times.pop(0)
            self.images.append(self.image(t))

    def image(self, t):
        return radiograph_frame(self.atoms.positions, self.m, self.ax, lateral_axes(self.ax)[0], self.info["radius"],
                                self.info["r0"], t)

    def get_state(self):
        return {"rows": [dict(r) for r in self.rows], "images": [dict(i) for i in self.images],
                "image_times": list(self.image_times)}

    def set_state(self, st):
        self.rows = [{"t": float(r["t"]), "holes": [float(x) for x in r["holes"]]} for r in st["rows"]]
        self.images = [dict(i) for i in st["images"]]
        self.image_times = [float(t) for t in st["image_times"]]


class MultilayerScene(SceneDef):
    """The ``multilayer`` scene on the lifecycle (module docstring)."""

    name = "multilayer"
    description = ("steel sphere (13.5 mm, 6.5 km/s) through textolite, aluminium, steel and paraffin plates "
                   "(CD paper fig. 23): perforated layers, holes, residual fragments, radiograph")
    params = scene_params(PARAMS, h5md_frames=10, checkpoint_every=10)

    def check(self, v):
        thin = min(t for _, t in LAYERS)
        if v["r0"] > thin:
            raise InputError("r0", f"{v['r0'] / units.mm:g}mm", f"at most the thinnest layer {thin / units.mm:g} mm")
        if v["radius"] < v["diameter"]:
            raise InputError("radius", f"{v['radius'] / units.mm:g}mm", "at least the sphere diameter")
        if v["diameter"] < 4 * v["r0"]:
            raise InputError("r0", f"{v['r0'] / units.mm:g}mm", f"at most a quarter of the sphere diameter, "
                             f"{v['diameter'] / 4 / units.mm:g} mm (a sphere of a few clusters across)")
        if v["packing"] is not None:
            from .packing import resolve_packing
            resolve_packing(v["packing"])            # checked before any work
        late = [t for t in parse_times(v["image_times"], "image_times", []) if t > v["t_end"] * (1 + 1e-9)]
        if late:
            raise InputError("image_times", v.image_times, f"auto or times within the run, 0-"
                             f"{v.t_end / units.us:g} us (t_end)")

    def setup(self, v, stage):
        return build_multilayer(v)

    def attach(self, v, stage, atoms, dyn, info):
        te = v.t_end
        times = parse_times(v.image_times, "image_times", [te / 3.0, 2.0 * te / 3.0, te])
        rec = StackRecord(atoms, dyn, info, [t for t in times if t <= te * (1 + 1e-9)])
        nframes = max(1, int(round(info["nsteps"] * info["dt"] / FRAME_TIME)))
        return Stage(stage, atoms, dyn, int(info["nsteps"]), nframes, info, on_frame=rec.frame, analysis=rec)

    def retry(self, v, stage, exc, attempt):
        return retry_halved_dt(v, exc, attempt)

    def finish(self, v, stage):
        atoms, dyn, rec = stage.atoms, stage.dyn, stage.analysis
        info = stage.info
        if not rec.images or rec.images[-1]["t"] < rec.rows[-1]["t"] - 0.5 * FRAME_TIME:
            rec.images.append(rec.image(rec.rows[-1]["t"]))
        fr = fragments(atoms)
        ax = info["axis"]
        lat = atoms.positions[:, lateral_axes(ax)]
        rim = np.hypot(lat[:, 0], lat[:, 1]) > info["radius"] - RIM * info["r0"]
        body = atoms.arrays["body"]
        nb = len(info["layers"]) + 1
        m = atoms.get_masses()
        remnant = np.bincount(fr.labels, weights=rim.astype(float), minlength=fr.n_fragments) > 0
        comp = np.stack([np.bincount(fr.labels, weights=m * (body == b), minlength=fr.n_fragments)
                         for b in range(nb)], axis=1)
        free = np.nonzero(~remnant)[0]
        order = free[np.argsort(-fr.mass[free])][:N_LARGEST]
        largest = [{"g": int(fr.g[f]), "mass": float(fr.mass[f]), "v_axis": float(fr.velocity[f, ax]),
                    "speed": float(np.linalg.norm(fr.velocity[f])), "z": float(fr.com[f, ax]),
                    "composition": (comp[f] / fr.mass[f]).tolist()} for f in order]
        sp = info["sphere_body"]
        f_sp = int(np.argmax(comp[:, sp]))
        proj = {"mass": float(fr.mass[f_sp]), "sphere_fraction": float(comp[f_sp, sp] / comp[:, sp].sum()),
                "v_axis": float(fr.velocity[f_sp, ax]), "z": float(fr.com[f_sp, ax])}
        return {"info": info, "rows": rec.get_state()["rows"], "images": rec.images, "largest": largest,
                "projectile": proj, "ledger": ledger(dyn), "steps": int(dyn.nsteps), "t_run": stage.t_run,
                "n": len(atoms), "n_fragments": int(fr.n_fragments), "nbuilds": int(atoms.calc.nl.nbuilds)}

    def analyse(self, v, summaries):
        sm = summaries[0]
        info = sm["info"]
        last = sm["rows"][-1]
        q, notes = {}, []
        perforated = []
        for k, (lay, d) in enumerate(zip(info["layers"], last["holes"])):
            name = f"layer{k + 1}_{lay['material']}"
            through = not (d == 0.0)
            if through:
                perforated.append(k + 1)
            q[f"{name}_hole"] = Quantity(d / units.mm if through else 0.0, "mm",
                                         note=("perforated" + (", opening reaches the rim" if math.isnan(d) else "")
                                               if through else "not perforated"))
        q["perforated_layers"] = Quantity(float(len(perforated)), "", note="layers " + (", ".join(map(str, perforated))
                                                                                          or "none"))
        pr = sm["projectile"]
        q["projectile_mass"] = Quantity(pr["mass"] / units.g, "g", note=f"largest piece holding sphere material, "
                                        f"{100 * pr['sphere_fraction']:.0f}% of the sphere's mass")
        q["projectile_speed"] = Quantity(pr["v_axis"] / units.km_s, "km/s", note="its axial velocity")
        mats = [lay["material"] for lay in info["layers"]] + ["sphere"]
        for k, f in enumerate(sm["largest"]):
            main = int(np.argmax(f["composition"]))
            q[f"fragment{k + 1}_mass"] = Quantity(f["mass"] / units.g, "g", note=f"{f['g']} clusters, "
                                                  f"{100 * f['composition'][main]:.0f}% {mats[main]}"
                                                  + (f" (layer {main + 1})" if main < len(info["layers"]) else ""))
            q[f"fragment{k + 1}_speed"] = Quantity(f["v_axis"] / units.km_s, "km/s",
                                                   note=f"axial, at {f['z'] / units.mm:.1f} mm")
        lq, lnote = ledger_quantities(sm["ledger"])
        q.update(lq)
        lay_txt = ", ".join(f"{lay['material']} {lay['thickness'] / units.mm:g} mm ({lay['n']} clusters)"
                            for lay in info["layers"])
        notes.append(f"stack: {lay_txt}; plate radius {info['radius'] / units.mm:g} mm; sphere {info['n_sphere']} "
                     f"clusters, {info['m_sphere_g']:.2f} g; r0 = {info['r0'] / units.mm:g} mm")
        notes.append(f"{sm['n']} clusters, {sm['steps']} steps of {info['dt'] / units.ns:.4g} ns, "
                     f"{sm['t_run']:.1f} s stepping, {sm['n'] * sm['steps'] / max(sm['t_run'], 1e-9):.3g} "
                     f"particle-steps/s, {sm['nbuilds']} neighbour-list builds; {sm['n_fragments']} fragments")
        notes.append(lnote)
        notes += info.get("packing_notes", [])
        for r in v.retried:
            notes.append(f"time step halved after a stop: {r}")
        extra = {"holes_mm": [[r["t"] / units.us] + [d / units.mm for d in r["holes"]] for r in sm["rows"]],
                 "perforated": perforated, "ledger_J": sm["ledger"], "n_clusters": sm["n"], "steps": sm["steps"],
                 "stepping_time_s": sm["t_run"]}
        return q, notes, extra

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        ax = sm["info"]["axis"]
        files = write_radiographs(sm["images"], out / "multilayer_radiographs.png", out / "multilayer_radiographs.csv",
                                  labels=("xyz"[lateral_axes(ax)[0]], "xyz"[ax]),
                                  title=f"multilayer target, r0 = {sm['info']['r0'] / units.mm:g} mm")
        path = out / "multilayer_holes.csv"
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_us"] + [f"layer{k + 1}_{lay['material']}_hole_mm"
                                   for k, lay in enumerate(sm["info"]["layers"])])
            for r in sm["rows"]:
                w.writerow([f"{r['t'] / units.us:.5g}"] + [f"{d / units.mm:.5g}" for d in r["holes"]])
        return files + [path]


register_scene(MultilayerScene())
