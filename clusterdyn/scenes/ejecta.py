"""Scene ``ejecta``: a shock pulse breaking out of a rough lead surface (the CD paper's section 4.2).

A quasi-2D slab of lead clusters (the paper's Tait parameters: 11.34 g/cm3,
c0 = 1.972 km/s, n = 3) with a profiled free surface
(:func:`clusterdyn.build.profiled_sample`) is driven from its base by a
piston whose velocity history U(t) is a flat-topped pulse sized for a
target pressure from lead's own CD Hugoniot
(:mod:`clusterdyn.scenes.pressure`, :func:`clusterdyn.md.pulses.flat_top`),
or given directly (``u``) or read from a CSV (``drive_csv``: a hydrocode's
U(t) of a Lagrangian boundary, as the paper used).

**Drive** (``drive``): ``pressure`` (the default) pushes the base layer with
a normal stress history (:class:`~clusterdyn.md.layer_drives.Traction`: the
target pressure for the plateau, then a linear release to zero stress); the
layer is free to move, so after the pulse the base is a stress-free face,
as the rear of a flyer.  ``piston`` moves the base layer with a prescribed
U(t) (sized from the CD Hugoniot); a rigid boundary holds whatever comes
back to it, so once the release reflected from the free surface reaches it
the sample is pulled back with about the shock pressure in tension, more
than lead's 10 GPa, and tears (measured: a 15 GPa pulse with a 1 us release
split a 275 um sample in the middle and at the piston).  A hydrocode's U(t)
of an inner Lagrangian point contains that point's response to the
returning waves; a flat-topped U(t) does not.  After breakout the
scene follows the jets and the ejected particles
(:mod:`clusterdyn.analysis.ejecta`) and reports:

* the pressure the shock actually delivered (measured before breakout)
  beside the target, and the order of the shocked lattice;
* the jet-tip velocity and the ejected mass per unit area against time
  (mass ahead of the valley front moving faster than 1.05 u_fs);
* the fragment spectrum N(g) and the size distribution in um at 6 us
  (optionally with the paper's two corrections: no particles under 10 um,
  then every size shifted by +5 um);
* snapshots coloured by velocity at 0-7 us (PNG);
* whether the surface jets or spalls.

**Cases** (``case``): ``Rz80`` -- peak-to-valley height 80 um, wavelength
300 um, one wavelength across, r0 = 5 um; ``Rz20`` -- 20 um, 20 um, three
wavelengths across, r0 = 1 um.  The paper gives "amplitude a0 = 80 um" for
the roughness it calls Rz80; Rz is the ISO mean peak-to-valley height, so a
sinusoid of Rz80 has amplitude (half peak-to-valley) 40 um: the scene reads
the paper's a0 as the Rz value (``rz``), and the sinusoid's amplitude is
``rz / 2`` (set ``rz=160um`` for the literal reading a0 = 80 um).

**Slab**: [100] along the surface normal, the periodic width along [010],
two lattice repeats (2.83 r0) along [001]: the same profile in every plane
(``direction`` and ``slab_cells`` change it).

**Depth**: the sample is as deep as the plateau is long,
``D * (rise + flat)`` below the deepest valley (D from the CD Hugoniot at
the plateau speed): the piston starts its release as the shock reaches the
valleys, so the surface sees the full plateau pressure and the release
follows it (a release that starts earlier catches the front and lowers the
pressure on the way: a 0.05 us plateau on 350 um delivered 11 GPa of a
15 GPa drive).  After the release the piston stands still, as a flyer's
rear face does; late in the run the tension reflected from the surface
reaches it and may tear the sample off it (the analysis takes the largest
full-width layer as the main body).  ``depth`` sets the depth.

**Reach**: the paper's 0.5 um clusters on its 500 um x 2.4 mm fragment are
about 1e10 clusters in 3D and some 1e13 particle-steps over 7 us: out of
reach here.  The Rz80 default (7k clusters, 7 us) runs in minutes; Rz20
needs r0 <= 1 um and is a study (tens of minutes).

**Damping**: ``J = 50`` by default (free-surface scenes run damped: the
pair damping removes the numerical dusting of smooth surfaces while the
shock and release stay, docs/theory.md); ``J=none`` shows the undamped
run, and ``profile=flat`` counts the smooth-surface dust under the same drive.
"""

import csv
import math

import numpy as np

from .. import units
from ..analysis.ejecta import (BREAKOUT_FRACTION, FS_LAYER, G_TIP, MARGIN, EjectaRecorder, ShockProbe,
                               spectrum_table)
from ..analysis.fragment_spectra import G_MAX
from ..analysis.shock import hugoniot_interpolant
from ..analysis.stress import add_piece_virials
from ..build import fcc_packing, along_axis, parse_axis, repeat_lengths
from ..build.bodies import crystal_rotation, plane_spacing
from ..build.lattice import ORIENTATIONS, lattice_sound_speed, parse_direction
from ..build.profiled import Grooves, RandomRoughness, Sinusoid, profiled_sample
from ..calculators import ClusterDynamics
from ..errors import InputError
from ..materials import cd_material_names, get_material
from ..md import DampedVerlet, Piston, Traction
from ..md.damped import TIMESTEP_FACTOR
from ..md.pulses import flat_top, pulse_end
from .base import Param, Quantity, register_scene
from .common import matplotlib_agg, piston_layer, piston_thickness, thermal_noise
from .lifecycle import SceneDef, Stage, scene_params
from .pressure import cd_hugoniot, piston_speed, pressure_at
from .shock import shock_timestep

CD_MATERIALS = tuple(cd_material_names())

#: the paper's roughness cases: (peak-to-valley, wavelength, periods across, r0)
CASES = {"Rz80": (80 * units.um, 300 * units.um, 1, 5 * units.um),
         "Rz20": (20 * units.um, 20 * units.um, 3, 1 * units.um)}
#: the paper's cluster size and fragment, for the reach statement
PAPER_R0 = 0.5 * units.um

#: spall: the main body has lost its material at least this many r0 below the initial surface in every bin
SPALL_MIN = 3.0
#: the paper's spectrum corrections: drop particles under 10 um, then shift every size by +5 um
PAPER_DROP = 10 * units.um
PAPER_SHIFT = 5 * units.um
#: kg/m^2 per (amu/Angstrom^2) and the display unit of areal mass
MG_CM2 = 1e-6 * units.kg / (1e-2 * units.m) ** 2


def drive_params(pressure, flat, release, t_end, J=50.0, drive="piston"):
    """The drive, sample and run parameters shared by ``ejecta`` and ``jets``."""
    return [
        Param("drive", drive, "piston: the base layer moves with a prescribed U(t) (rigid: tension that comes "
              "back to it is held); pressure: the base layer is pushed by a prescribed normal stress and is free "
              "to move (after the release a stress-free face, as a flyer's rear)", kind="choice",
              choices=("piston", "pressure")),
        Param("pressure", pressure, "target shock pressure (-sigma along the axis behind the front) in the CD "
              "model; the piston speed is sized from the material's measured CD Hugoniot", unit="GPa", low=0.0,
              low_open=True),
        Param("u", None, "piston plateau speed; none = sized from 'pressure'", unit="km/s", low=0.0, high=20.0,
              low_open=True, optional=True),
        Param("drive_csv", None, "the drive's history from a CSV: t_us|t_ns|... with u_km_s|u_m_s|... (a "
              "hydrocode's Lagrangian boundary U(t), drive=piston) or sigma_GPa|sigma_MPa (drive=pressure); "
              "replaces pressure/u/rise/flat/release", kind="str", optional=True),
        Param("rise", 0.0, "rise time of the piston from rest to the plateau speed", unit="us", low=0.0),
        Param("flat", flat, "plateau duration; none = the plateau lasts the whole run", unit="us", low=0.0,
              optional=True),
        Param("release", release, "linear release from the plateau to u_end", unit="us", low=0.0),
        Param("u_end", 0.0, "piston speed after the release (drive=piston; a pressure drive releases to zero "
              "stress)", unit="km/s", low=0.0),
        Param("slab_cells", 2, "slab thickness across (periodic) in lattice repeats", kind="int", low=1),
        Param("direction", "100", "crystal direction along the surface normal", kind="choice",
              choices=("100", "110", "111")),
        Param("axis", "x", "surface normal (the piston pushes along +axis)", kind="choice", choices=("x", "y", "z")),
        Param("rc", 1.15, "cutoff as a multiple of r0", low=1.0, high=1.414, low_open=True),
        Param("J", J, "pair damping Gamma = c0/(J r0); none = off (free-surface scenes run damped: it removes "
              "the numerical dusting of smooth surfaces)", low=0.0, low_open=True, optional=True),
        Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
        Param("seed", 1, "random seed (noise, random roughness)", kind="int", low=0),
        Param("dt_factor", TIMESTEP_FACTOR, "time step as a fraction of r0/(c0 + u)", low=0.0, high=0.5,
              low_open=True),
        Param("t_end", t_end, "simulated time", unit="us", low=0.0, low_open=True),
        Param("frames", 140, "analysis frames over the run (jets, ejecta, fragments)", kind="int", low=5),
        Param("probes", 20, "samples of the shock before breakout (pressure, speed, order)", kind="int", low=3),
        Param("g_tip", G_TIP, "smallest fragment (clusters) whose foremost cluster can be the jet tip",
              kind="int", low=1),
        Param("margin", MARGIN, "ejecta move faster than margin * u_fs", low=1.0),
        Param("fs_layer", FS_LAYER, "free-surface velocity: mean over the body's layer this many r0 below "
              "the valley front", low=0.0, low_open=True),
    ]


def _dir_key(v):
    return {"100": (1, 0, 0), "110": (1, 1, 0), "111": (1, 1, 1)}[v.direction]


def flat_sample(material, r0, *, depth, width, axis=0, direction=(1, 0, 0), slab_cells=2):
    """A slab with a flat free surface, in the conventions of :func:`~clusterdyn.build.profiled_sample`.

    ``info['profile']`` holds ``kind = "flat"``, the lateral bins (one
    lattice plane each), the orientation and the built width and depth.
    """
    key = parse_direction(direction)
    ax = parse_axis(axis)
    rep = repeat_lengths(key, r0)
    nx = max(2, int(round(depth / rep[0])))
    nu = max(1, int(round(width / rep[1])))
    atoms = fcc_packing(material, r0, size=(nx, nu, int(slab_cells)), direction=key, pbc=(False, True, True))
    along_axis(atoms, ax)
    iu, iv = (ax + 1) % 3, (ax + 2) % 3
    rot = crystal_rotation(key, ax)
    d_u, d_v = plane_spacing(r0, rot, iu), plane_spacing(r0, rot, iv)
    rows = ORIENTATIONS[key]
    mil = lambda x: "[" + "".join(str(int(c)) for c in x) + "]"      # noqa: E731
    top = float(atoms.positions[:, ax].max())
    atoms.info["profile"] = {"kind": "flat", "dims": 2, "axis": ax, "u_axis": iu, "v_axis": iv,
                             "direction": mil(key), "bins_A": [float(d_u), None],
                             "bin_offsets_A": [-0.5 * d_u, -0.5 * d_v], "n_sampling": 5,
                             "orientation": {"normal": mil(rows[0]), "u": mil(rows[1]), "v": mil(rows[2])},
                             "depth_A": top, "width_A": float(atoms.cell.lengths()[iu]),
                             "length_A": float(atoms.cell.lengths()[iv]), "slab_cells": int(slab_cells)}
    return atoms


class ProfiledShockScene(SceneDef):
    """Shared machinery of ``ejecta`` and ``jets``: a profiled slab, a piston pulse, the analysis."""

    #: subclasses: the profile and geometry from the parameters
    def geometry(self, v):
        """``(profile or None, amplitude, wavelength, width, r0, depth or None)`` in ASE units."""
        raise NotImplementedError

    # -- drive ---------------------------------------------------------------------------
    def drive(self, v, r0):
        """``(history Table, info)``: the drive's history (speeds or stresses) and how it was chosen."""
        mat = get_material(v.material)
        info = {"material": mat.name, "kind": v.drive}
        try:
            hug = cd_hugoniot(mat.name, J=v.J, direction=v.direction, rc=v.rc)
        except InputError:
            hug = None
        Du = hugoniot_interpolant(hug["u"], hug["D"]) if hug is not None and len(hug["u"]) >= 2 else None
        Pu = (lambda x: pressure_at(x, hug)) if hug is not None and len(hug["u"]) >= 2 else None
        if v.drive_csv is not None:
            from .lifecycle import read_history_csv
            hist, kind = read_history_csv("drive_csv", v.drive_csv, kinds=("u", "sigma"))
            stress = hist.values.ndim == 1 and kind == "sigma"
            if hist.values.ndim != 1:
                raise InputError("drive_csv", v.drive_csv, "a CSV of one u_<unit> or sigma_<unit> column")
            if stress != (v.drive == "pressure"):
                raise InputError("drive_csv", v.drive_csv, "a u_<unit> column with drive=piston, a sigma_<unit> "
                                 "column with drive=pressure")
            peak = float(np.abs(hist.values).max())
            if not peak > 0:
                raise InputError("drive_csv", v.drive_csv, "a history with a non-zero value")
            top = hist.times[np.abs(hist.values) >= 0.95 * peak]
            u = peak if not stress else piston_speed(mat.name, peak, J=v.J, direction=v.direction,
                                                     rc=v.rc, hugoniot=hug)["u"]
            info.update(source=f"CSV {v.drive_csv}", u=u, duration=float(top.max()) if top.max() > 0 else None,
                        pulse=pulse_end(hist), peak=peak)
        else:
            if v.drive == "pressure":
                P = v.pressure
                s = piston_speed(mat.name, P, J=v.J, direction=v.direction, rc=v.rc, hugoniot=hug)
                u = s["u"]
                info.update(source=f"normal stress {P / units.GPa:g} GPa on a free base layer (particle velocity "
                                   f"{u / units.km_s:.4g} km/s from the CD Hugoniot, {s['hugoniot']['source']}, "
                                   f"J={s['hugoniot']['J']})", ordered_table=s["ordered"])
                hist = flat_top(P, v.flat, v.release, rise=v.rise, u_end=0.0)
            else:
                if v.u is not None:
                    u = v.u
                    info.update(source="piston speed given")
                else:
                    s = piston_speed(mat.name, v.pressure, J=v.J, direction=v.direction, rc=v.rc,
                                     hugoniot=hug)
                    u = s["u"]
                    info.update(source=f"piston sized for {v.pressure / units.GPa:g} GPa from the CD Hugoniot "
                                       f"({s['hugoniot']['source']}, J={s['hugoniot']['J']})",
                                ordered_table=s["ordered"])
                hist = flat_top(u, v.flat, v.release, rise=v.rise, u_end=v.u_end)
            info.update(u=u, duration=None if v.flat is None else v.rise + v.flat,
                        pulse=None if v.flat is None else v.rise + v.flat + v.release)
        u = info["u"]
        info["D_table"] = float(Du(u)) if Du is not None else lattice_sound_speed(mat.c0) + 1.3 * u
        info["P_table"] = float(Pu(u)) if Pu is not None else math.nan
        return hist, info

    # -- lifecycle hooks -----------------------------------------------------------------
    def estimate_particles(self, v):
        from .lifecycle import fcc_count
        prof, A, lam, width, r0, depth = self.geometry(v)
        if depth is None:
            return None
        return fcc_count(width * (depth + A) * v.slab_cells * repeat_lengths(_dir_key(v), r0)[2], r0)

    def check(self, v):
        mat = get_material(v.material)
        if mat.curve is None:
            raise InputError("material", v.material, "a material with a cold curve: " + ", ".join(CD_MATERIALS))
        prof, A, lam, width, r0, depth = self.geometry(v)
        rep = repeat_lengths(_dir_key(v), r0)
        if v.slab_cells * rep[2] < 2 * v.rc * r0:
            n = int(math.ceil(2 * v.rc * r0 / rep[2]))
            raise InputError("slab_cells", v.slab_cells, f">= {n} (the periodic slab must be at least 2 rc r0 "
                             "thick so that no cluster meets its own image)")
        if depth is None and v.drive_csv is None and v.flat is None:
            raise InputError("depth", None, "a depth (a drive that holds its plateau for the whole run sets none)")
        if v.drive == "pressure" and v.u is not None:
            raise InputError("u", v.u / units.km_s, "none with drive=pressure (the stress is 'pressure')")
        if v.u_end > (v.u if v.u is not None else math.inf):
            raise InputError("u_end", v.u_end / units.km_s, "a speed <= u")
        if v.get("spectrum_time") is not None and v.spectrum_time > v.t_end * (1 + 1e-9):
            raise InputError("spectrum_time", f"{v.spectrum_time / units.us:g}us",
                             f"none or a time within the run, 0-{v.t_end / units.us:g} us (t_end)")
        if depth is not None and depth < A + 10 * r0:
            raise InputError("depth", f"{depth / units.um:g}um", f">= the profile's amplitude + 10 r0 = "
                             f"{(A + 10 * r0) / units.um:g} um")
        if lam is not None and lam < 4 * r0:
            raise InputError("r0", r0 / units.um, f"<= wavelength/4 = {lam / 4 / units.um:g} um (the profile "
                             "needs a few clusters per wavelength)")

    def setup(self, v, stage):
        mat = get_material(v.material)
        prof, A, lam, width, r0, depth = self.geometry(v)
        hist, dinfo = self.drive(v, r0)
        u = dinfo["u"]
        D = dinfo["D_table"]
        ax = parse_axis(v.axis)
        if depth is None:
            dur = dinfo["duration"]
            if dur is None or not dur > 0:
                raise InputError("depth", None, "a depth (the drive has no finite duration to set it)")
            depth = D * dur + A
            dinfo["depth_rule"] = (f"D x (rise + plateau) below the deepest valley: {D / units.km_s:.3f} km/s x "
                                   f"{dur / units.us:g} us = {D * dur / units.um:.1f} um")
        depth = max(depth, A + 10 * r0)
        if prof is None:
            atoms = flat_sample(mat, r0, depth=depth, width=width, axis=ax, direction=_dir_key(v),
                                slab_cells=v.slab_cells)
        else:
            atoms = profiled_sample(mat, r0, prof, depth=depth, width=width, axis=ax, direction=_dir_key(v), dims=2,
                                    slab_cells=v["slab_cells"])
        term = None
        if v.get("packing") is None:
            calc = ClusterDynamics(rc=v["rc"])
            atoms.calc = calc
        else:                   # the law on every set-up pair of the lattice (at rest: no quench)
            from ..md.boundary import apply_boundary_law
            from .packing import law_of, resolve_packing
            calc, term = apply_boundary_law(atoms, law_of(resolve_packing(v["packing"])), rc=v["rc"])
        calc.setup(atoms)
        mask = piston_layer(atoms, piston_thickness(r0), ax)
        e = np.zeros(3)
        e[ax] = 1.0
        if v.drive == "pressure":
            piston = Traction(mask, -e, hist)
        else:
            piston = Piston(mask, hist, direction=e)
        thermal_noise(atoms, v.noise, v.seed, exclude=mask)
        atoms.set_constraint(piston)
        atoms.set_momenta(atoms.get_momenta())
        dt = shock_timestep(calc, u, v["dt_factor"])
        dyn = DampedVerlet(atoms, timestep=dt, J=v["J"])
        if term is not None:
            dyn.attach_piece(term)
        x = atoms.positions[:, ax]
        p = atoms.info["profile"]
        iu = (ax + 1) % 3
        # the deepest valley and the highest crest of the built surface (topmost cluster per lateral bin)
        from ..analysis.ejecta import _bins, surface_profile
        nb, bw, off, W = _bins(atoms, p, ax, iu)
        h0 = surface_profile(atoms.positions, np.ones(len(atoms), bool), ax, iu, nb, bw, off, W)
        slab = max(float(repeat_lengths(_dir_key(v), r0)[0]), r0)
        info = {"piston": np.flatnonzero(mask), "nsteps": int(math.ceil(v.t_end / dt)), "u": u,
                "D_table": D, "P_table": dinfo["P_table"], "drive_source": dinfo["source"],
                "depth_rule": dinfo.get("depth_rule", "given"), "depth": float(depth), "r0": float(r0),
                "amplitude": float(A), "wavelength": -1.0 if lam is None else float(lam),
                "width": float(W), "area": float(W * atoms.cell.lengths()[(ax + 2) % 3]),
                "valley0": float(np.nanmin(h0)), "crest0": float(np.nanmax(h0)), "base": float(x[~mask].min()),
                "mean_surface0": float(np.nanmean(h0)), "slab": slab, "axis": ax,
                "orientation": dict(p["orientation"]), "profile_kind": p["kind"],
                "profile_info": {k: x_ for k, x_ in p.items() if isinstance(x_, (int, float, str))},
                "duration": -1.0 if dinfo["duration"] is None else float(dinfo["duration"]),
                "pulse": -1.0 if dinfo["pulse"] is None else float(dinfo["pulse"]),
                "ordered_table": float(dinfo.get("ordered_table", math.nan))}
        return atoms, dyn, info

    def attach(self, v, stage, atoms, dyn, info):
        ax = int(info["axis"])
        mask = np.zeros(len(atoms), bool)
        mask[np.asarray(info["piston"], dtype=np.int64)] = True
        r0 = float(info["r0"])
        nsteps = int(info["nsteps"])
        dt = dyn.dt
        every = max(1, int(round(nsteps / max(1, v.frames))))
        lam = None if info["wavelength"] < 0 else float(info["wavelength"])
        rec = EjectaRecorder(atoms, axis=ax, r0=r0, exclude=mask, u_drive=float(info["u"]), wavelength=lam,
                             snapshot_times=self.snapshot_times(v), spectrum_time=self.spectrum_time(v),
                             half_frame=0.5 * every * dt, g_small=G_MAX, g_tip=int(v.g_tip),
                             margin=float(v.margin), fs_layer=float(v.fs_layer),
                             breakout_fraction=BREAKOUT_FRACTION)
        probe = ShockProbe(atoms, axis=ax, r0=r0, slab=float(info["slab"]), u_drive=float(info["u"]),
                           lo=float(info["base"]), hi=float(info["valley0"]), exclude=mask)
        ana = _Analysis(rec, probe)
        calc = atoms.calc
        transit = (float(info["valley0"]) - float(info["base"])) / float(info["D_table"])
        pevery = max(1, int(transit / dt / max(1, v.probes)))

        def probe_obs():
            if not probe.done:
                probe.sample(dyn.get_time(), atoms,
                             add_piece_virials(calc.compute(atoms, per_particle=True, forces=False)["virials"], dyn))

        def frame(d):
            rec.add(d.get_time(), atoms)

        st = Stage(stage, atoms, dyn, nsteps, v.frames, info, on_frame=frame, analysis=ana,
                   observers=[(probe_obs, pevery)], observables={})
        return st

    def snapshot_times(self, v):
        return []

    def spectrum_time(self, v):
        return None

    def finish(self, v, stage):
        ana = stage.analysis
        n = len(stage.atoms)
        return {"recorder": ana.rec.get_state(), "probe": ana.probe.get_state(), "info": stage.info, "n": n,
                "nsteps": stage.nsteps, "t_run": stage.t_run, "dt": stage.dyn.dt,
                "layers_end": ana.rec.layer_depths(stage.atoms),
                "separation_end": {k: x for k, x in ana.rec.separation(stage.atoms).items()}}

    # -- shared analysis -------------------------------------------------------------------
    @staticmethod
    def restore(sm):
        rec = EjectaRecorder()
        rec.set_state(sm["recorder"])
        probe = ShockProbe()
        probe.set_state(sm["probe"])
        return rec, probe

    def drive_quantities(self, v, sm, probe):
        info = sm["info"]
        pr = probe.result()
        q = {}
        target = None if (v.u is not None or v.drive_csv is not None) else v.pressure / units.GPa
        q["P"] = Quantity(pr["P"] / units.GPa, "GPa", target, spread=pr["P_spread"] / units.GPa,
                          note="pressure delivered: -sigma along the axis on the plateau behind the front "
                               "(slabs within 10% of the peak velocity) before breakout, vs the target")
        q["u_drive"] = Quantity(info["u"] / units.km_s, "km/s", note="plateau speed of the drive (pressure drive: "
                                "the CD Hugoniot's particle velocity at its stress)")
        q["u_behind"] = Quantity(pr["u"] / units.km_s, "km/s", info["u"] / units.km_s,
                                 note="particle velocity on the plateau before breakout")
        q["D"] = Quantity(pr["D"] / units.km_s, "km/s", info["D_table"] / units.km_s,
                          note="front speed before breakout vs the CD Hugoniot table")
        q["ordered_fraction"] = Quantity(pr["ordered"], "",
                                         note="clusters behind the front keeping their 12 fcc neighbours "
                                              "(affine residual < 0.25 r0)")
        return q, pr

    @staticmethod
    def regime(ordered):
        if not np.isfinite(ordered):
            return "unknown (no shock samples)"
        if ordered >= 0.5:
            return f"ordered: the shocked lattice keeps its fcc order ({ordered:.2f}), a solid with strength"
        return f"disordered: the shocked lattice has lost its fcc order ({ordered:.2f}), fluid-like"

    def common_notes(self, v, sm, pr):
        info = sm["info"]
        n, nsteps, t_run = sm["n"], sm["nsteps"], sm["t_run"]
        o = info["orientation"]
        notes = [f"quasi-2D slab: surface normal {o['normal']} along {'xyz'[int(info['axis'])]}, periodic width "
                 f"along {o['u']}, slab {v.slab_cells} lattice repeats along {o['v']} (periodic)",
                 f"drive: {info['drive_source']}; plateau {info['u'] / units.km_s:.4g} km/s"
                 + (f", pulse {info['pulse'] / units.us:g} us (rise {v.rise / units.us:g}, plateau "
                    f"{(info['duration'] - v.rise) / units.us:g}, release {v.release / units.us:g} us to "
                    + (f"{v.u_end / units.km_s:g} km/s)" if v.drive == "piston" else "zero stress)")
                    if info["pulse"] > 0 and v.drive_csv is None
                    else ", from the CSV" if v.drive_csv is not None else ", held") +
                 f"; depth {info['depth'] / units.um:.1f} um ({info['depth_rule']})",
                 f"pressure delivered {pr['P'] / units.GPa:.2f} +- {pr['P_spread'] / units.GPa:.2f} GPa over "
                 f"{pr['n']} samples before breakout; the CD Hugoniot table gives "
                 f"{info['P_table'] / units.GPa:.2f} GPa at this speed",
                 "regime: " + self.regime(pr["ordered"]),
                 f"{n} clusters, r0 = {info['r0'] / units.um:g} um, {nsteps} steps of {sm['dt'] / units.ns:.4g} ns, "
                 f"{n * nsteps / max(t_run, 1e-9):.3g} particle-steps/s, stepping {t_run:.0f} s",
                 "damping: " + ("off" if v.J is None else f"J = {v.J:g} (Gamma = c0/(J r0))")]
        return notes

    @staticmethod
    def write_summary(out, summaries, stem):
        """The stage summaries (recorder and probe states) as a pickle, to analyse the run again
        (``scene.analyse(params, [pickle.load(fh)])``); returns the path."""
        import pickle
        path = out / f"{stem}_summary.pkl"
        tmp = path.with_suffix(".pkl.tmp")
        with open(tmp, "wb") as fh:
            pickle.dump(summaries[0], fh)
        tmp.replace(path)
        return path

    def history_png(self, out, rec, info, title, stem):
        """Jet tip and free surface against time, ejected mass per area; PNG + CSV."""
        plt = matplotlib_agg()
        keys = ("x_tip", "v_tip", "x_bubble", "u_fs", "ejected_mass_area", "eta", "eta_pv", "n_dust",
                "dust_mass", "n_layers", "n_fragments")
        t = np.array([f["t"] for f in rec.frames])
        cols = {k: np.array([f[k] for f in rec.frames]) for k in keys}
        csvp = out / f"{stem}_history.csv"
        with open(csvp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_us", "x_tip_um", "v_tip_km_s", "x_bubble_um", "u_fs_km_s", "ejected_mass_mg_cm2",
                        "eta_um", "eta_pv_um", "n_dust", "dust_mass_mg_cm2", "n_layers", "n_fragments"])
            for i in range(len(t)):
                w.writerow([f"{t[i] / units.us:.6g}", f"{cols['x_tip'][i] / units.um:.6g}",
                            f"{cols['v_tip'][i] / units.km_s:.6g}", f"{cols['x_bubble'][i] / units.um:.6g}",
                            f"{cols['u_fs'][i] / units.km_s:.6g}",
                            f"{cols['ejected_mass_area'][i] / MG_CM2:.6g}", f"{cols['eta'][i] / units.um:.6g}",
                            f"{cols['eta_pv'][i] / units.um:.6g}", int(cols["n_dust"][i]),
                            f"{cols['dust_mass'][i] / info['area'] / MG_CM2:.6g}", int(cols["n_layers"][i]),
                            int(cols["n_fragments"][i])])
        fig, axs = plt.subplots(1, 3, figsize=(15, 4.2))
        tu = t / units.us
        axs[0].plot(tu, cols["v_tip"] / units.km_s, label="jet tip")
        axs[0].plot(tu, cols["u_fs"] / units.km_s, label="free surface u_fs (below the valley)")
        axs[0].axhline(info["u"] / units.km_s, color="k", ls=":", lw=0.8, label="piston plateau")
        axs[0].set_xlabel("t (us)")
        axs[0].set_ylabel("velocity along the normal (km/s)")
        axs[0].legend(fontsize=8)
        axs[1].plot(tu, (cols["x_tip"] - info["mean_surface0"]) / units.um, label="jet tip")
        axs[1].plot(tu, (cols["x_bubble"] - info["mean_surface0"]) / units.um, label="valley (bubble) front")
        axs[1].set_xlabel("t (us)")
        axs[1].set_ylabel("position above the initial mean surface (um)")
        axs[1].legend(fontsize=8)
        axs[2].plot(tu, cols["ejected_mass_area"] / MG_CM2, label="ejected (ahead of the valley, v > margin u_fs)")
        axs[2].plot(tu, cols["dust_mass"] / info["area"] / MG_CM2, label="dust (fragments of <= 10 clusters; "
                    "ahead of the valley front)")
        axs[2].set_xlabel("t (us)")
        axs[2].set_ylabel("mass per unit area (mg/cm2)")
        axs[2].legend(fontsize=8)
        fig.suptitle(title)
        fig.tight_layout()
        png = out / f"{stem}_history.png"
        fig.savefig(png, dpi=110)
        plt.close(fig)
        return [png, csvp]

    def snapshots_png(self, out, rec, info, title, stem, vmax=None):
        """Panels of the snapshots, clusters coloured by their velocity along the normal; PNG + CSV."""
        if not rec.snapshots:
            return []
        plt = matplotlib_agg()
        snaps = sorted(rec.snapshots, key=lambda s: s["t"])
        n = len(snaps)
        fig, axs = plt.subplots(1, n, figsize=(2.2 * n + 1.5, 6.0), squeeze=False)
        vm = vmax or max(float(np.nanmax(np.abs(s["v"]))) for s in snaps) / units.km_s
        sc = None
        size = max(0.3, min(6.0, 4000.0 / len(snaps[0]["x"])))
        for a, s in zip(axs[0], snaps):
            uw = np.mod(np.asarray(s["u"], float), info["width"])       # lateral positions wrapped into the period
            sc = a.scatter(uw / units.um, (np.asarray(s["x"]) - info["mean_surface0"]) / units.um,
                           c=np.asarray(s["v"]) / units.km_s, s=size, cmap="viridis", vmin=0.0, vmax=vm,
                           linewidths=0)
            a.set_title(f"{s['t'] / units.us:.2f} us", fontsize=9)
            a.set_xlabel("u (um)", fontsize=8)
            a.tick_params(labelsize=7)
        axs[0][0].set_ylabel("height above the initial mean surface (um)")
        fig.colorbar(sc, ax=axs[0].tolist(), label="velocity along the normal (km/s)", shrink=0.8)
        fig.suptitle(title)
        png = out / f"{stem}_snapshots.png"
        fig.savefig(png, dpi=100)
        plt.close(fig)
        csvp = out / f"{stem}_snapshots.csv"
        with open(csvp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_us", "u_wrapped_um", "height_um", "v_km_s"])
            for s in snaps:
                tt = f"{s['t'] / units.us:.5g}"
                for uu, xx, vv in zip(np.mod(np.asarray(s["u"], float), info["width"]), s["x"], s["v"]):
                    w.writerow([tt, f"{uu / units.um:.5g}", f"{(xx - info['mean_surface0']) / units.um:.5g}",
                                f"{vv / units.km_s:.5g}"])
        return [png, csvp]


class _Analysis:
    """The stage's analysis state: the ejecta recorder and the pre-breakout probe."""

    def __init__(self, rec, probe):
        self.rec, self.probe = rec, probe

    def get_state(self):
        return {"recorder": self.rec.get_state(), "probe": self.probe.get_state()}

    def set_state(self, st):
        self.rec.set_state(st["recorder"])
        self.probe.set_state(st["probe"])


EJECTA_PARAMS = [
    Param("case", "Rz80", "the paper's roughness: Rz80 (80 um peak-to-valley, wavelength 300 um, 1 wavelength "
          "across, r0 5 um) or Rz20 (20 um, 20 um, 3 across, r0 1 um)", kind="choice", choices=tuple(CASES)),
    Param("profile", "sinusoid", "surface: sinusoid (amplitude rz/2), grooves (V, depth rz), random (Gaussian, "
          "Rz = rz, correlation length wavelength/4) or flat (the smooth-surface reference)", kind="choice",
          choices=("sinusoid", "grooves", "random", "flat")),
    Param("rz", None, "peak-to-valley height Rz; none = the case's (the paper's a0 read as Rz)", unit="um",
          low=0.0, low_open=True, optional=True),
    Param("wavelength", None, "wavelength (period); none = the case's", unit="um", low=0.0, low_open=True,
          optional=True),
    Param("n_periods", None, "wavelengths across the periodic width; none = the case's", kind="int", low=1,
          optional=True),
    Param("r0", None, "cluster size; none = the case's", unit="um", low=0.0, low_open=True, optional=True),
    Param("depth", None, "mean height of the surface above the base; none = set by the drive's duration "
          "(D x duration below the deepest valley)", unit="um", low=0.0, low_open=True, optional=True),
    Param("material", "Pb", "material (the paper: lead, Tait 11.34 g/cm3, 1.972 km/s, n = 3)", kind="choice",
          choices=CD_MATERIALS),
] + drive_params(15.0, 0.1, 0.1, 7.0, drive="pressure") + [
    Param("snapshot_every", 1.0, "time between the velocity snapshots (from 0)", unit="us", low=0.0,
          low_open=True),
    Param("spectrum_time", 6.0, "time of the fragment spectrum; none = the end", unit="us", low=0.0,
          optional=True),
    Param("corrections", False, "apply the paper's two spectrum corrections (no particles under 10 um, then "
          "every size +5 um) to the reported size distribution", kind="bool"),
    Param("packing", None, "the boundary pair law on every pair of the slab: a packing preset or JSON file "
          "(clusterdyn.scenes.packing) with boundaries=law and select=all (the slab stays a single crystal: the "
          "packing's grain size and porosity are not built); none = the paper's model", kind="str", optional=True),
]


class EjectaScene(ProfiledShockScene):
    """The ``ejecta`` scene (module docstring)."""

    name = "ejecta"
    description = ("shock pulse breaking out of a rough lead surface (Rz80/Rz20): jets, ejected mass, "
                   "fragment spectrum, spall")
    params = scene_params(EJECTA_PARAMS, h5md_frames=15)

    def geometry(self, v):
        rz_c, lam_c, nper_c, r0_c = CASES[v.case]
        rz = v.rz if v.rz is not None else rz_c
        lam = v.wavelength if v.wavelength is not None else lam_c
        nper = v.n_periods if v.n_periods is not None else nper_c
        r0 = v.r0 if v.r0 is not None else r0_c
        width = nper * lam
        kind = v.profile
        if kind == "sinusoid":
            prof, A = Sinusoid(0.5 * rz, lam), 0.5 * rz
        elif kind == "grooves":
            prof, A = Grooves(rz, lam), 0.5 * rz
        elif kind == "random":
            prof, A = RandomRoughness(rz, 0.25 * lam, seed=v.seed), 0.5 * rz
        else:
            prof, A = None, 0.0
        return prof, A, (lam if kind in ("sinusoid", "grooves") else None), width, r0, v.depth

    #: most velocity snapshots a run may take (each holds every cluster's velocity)
    MAX_SNAPSHOTS = 1000

    def check(self, v):
        super().check(v)
        if v["packing"] is not None:
            from .packing import resolve_packing
            spec = resolve_packing(v["packing"])            # checked before any work
            if spec["boundaries"] != "law" or spec["law"].get("select", "boundary") != "all":
                raise InputError("packing", v["packing"], "a packing with boundaries=law and law select=all (the "
                                 "profiled slab is a single crystal: no grain boundaries are built)")
        if v["t_end"] / v["snapshot_every"] > self.MAX_SNAPSHOTS:
            raise InputError("snapshot_every", f"{v['snapshot_every'] / units.us:g}us", f">= t_end / "
                             f"{self.MAX_SNAPSHOTS} = {v['t_end'] / self.MAX_SNAPSHOTS / units.us:.4g} us (at most "
                             f"{self.MAX_SNAPSHOTS} velocity snapshots; t_end = {v['t_end'] / units.us:g} us)")
        if v["profile"] == "random":
            lam = v["wavelength"] if v["wavelength"] is not None else CASES[v["case"]][1]
            r0 = v["r0"] if v["r0"] is not None else CASES[v["case"]][3]
            if 0.25 * lam < r0:
                raise InputError("wavelength", lam / units.um, f">= 4 r0 = {4 * r0 / units.um:g} um (random: the "
                                 "correlation length wavelength/4 must be >= r0)")

    def snapshot_times(self, v):
        k = int(math.floor(v.t_end / v.snapshot_every + 1e-9))
        return [i * v.snapshot_every for i in range(k + 1)]

    def spectrum_time(self, v):
        if v.spectrum_time is None or v.spectrum_time > v.t_end:
            return v.t_end
        return v.spectrum_time

    def analyse(self, v, summaries):
        sm = summaries[0]
        info = sm["info"]
        rec, probe = self.restore(sm)
        q, pr = self.drive_quantities(v, sm, probe)
        t, vtip = rec.series("v_tip")
        _, ufs = rec.series("u_fs")
        _, mej = rec.series("ejected_mass_area")
        _, xtip = rec.series("x_tip")
        _, xb = rec.series("x_bubble")
        area = info["area"]
        ts = rec.spectrum["t"] if rec.spectrum else t[-1]
        ks = int(np.argmin(np.abs(t - ts)))
        moving = np.isfinite(mej)
        q["u_fs_max"] = Quantity(float(np.nanmax(ufs)) / units.km_s, "km/s",
                                 note="largest free-surface velocity (layer below the valley front)")
        q["v_tip_max"] = Quantity(float(np.nanmax(vtip)) / units.km_s, "km/s",
                                  note=f"largest jet-tip velocity (fragments of >= {v.g_tip} clusters)")
        q["v_tip"] = Quantity(float(vtip[ks]) / units.km_s, "km/s", note=f"jet-tip velocity at {ts / units.us:.2f} us")
        q["ejected_mass"] = Quantity(float(mej[ks]) / MG_CM2 if moving[ks] else math.nan, "mg/cm2",
                                     note=f"per unit area at {ts / units.us:.2f} us: mass ahead of the valley "
                                          f"front faster than {v.margin:g} u_fs")
        q["ejected_mass_max"] = Quantity(float(np.nanmax(mej)) / MG_CM2 if moving.any() else math.nan, "mg/cm2",
                                         note="largest over the run")
        q["jet_length"] = Quantity(float(xtip[-1] - xb[-1]) / units.um, "um",
                                   note="jet tip ahead of the valley front at the end")
        spec = rec.spectrum or {}
        g = np.asarray(spec.get("g", []), dtype=np.int64)
        d = np.asarray(spec.get("diameter", []), dtype=float)
        dust = g <= G_MAX
        q["dust_count"] = Quantity(float(dust.sum()) / (area / units.mm ** 2), "1/mm2",
                                   note=f"fragments of <= {G_MAX} clusters ahead of the valley front per unit area "
                                        f"at {ts / units.us:.2f} us (on a smooth surface: the numerical dusting)")
        q["dust_mass"] = Quantity(float(np.asarray(spec.get("mass", []), float)[dust].sum()) / area / MG_CM2
                                  if len(g) else 0.0, "mg/cm2",
                                  note=f"their mass per unit area")
        q["n_ejecta_fragments"] = Quantity(float(len(g)), "", note="fragments ahead of the valley front at the "
                                           "spectrum time (not full-width layers)")
        q["mean_diameter"] = Quantity(float(d.mean()) / units.um if len(d) else math.nan, "um",
                                      note="mean equivalent diameter of those fragments")
        if v.corrections and len(d):
            dc = spectrum_table(g, d, drop_below=PAPER_DROP, shift=PAPER_SHIFT)["diameter"]
            q["n_corrected"] = Quantity(float(len(dc)), "", note="fragments left after the paper's first "
                                        "correction (no particles under 10 um)")
            q["mean_diameter_corrected"] = Quantity(float(dc.mean()) / units.um if len(dc) else math.nan, "um",
                                                    note="their mean diameter after the +5 um shift")
        # character
        layers = np.asarray(sm["layers_end"], float)
        sep = sm["separation_end"]
        ptv = 2 * info["amplitude"]
        r0 = info["r0"]
        spalled = bool(np.isfinite(sep["min"]) and sep["min"] > SPALL_MIN * r0)
        jets = bool(ptv > 0 and (xtip[-1] - xb[-1]) > 2 * ptv)
        q["spall_depth"] = Quantity(sep["median"] / units.um if spalled else math.nan, "um",
                                    note="median over the width of the initial depth below the surface at which "
                                         "the material has left the main body (NaN: no spall)")
        q["separation_min"] = Quantity(sep["min"] / units.um, "um",
                                       note="smallest such depth over the width (spall when > "
                                            f"{SPALL_MIN:g} r0 everywhere)")
        character = ("jets and spall" if jets and spalled else "jets" if jets else "spall" if spalled
                     else "neither jets nor spall")
        # full-width separations anywhere (Lagrangian depth below the initial mean surface of each plane)
        planes = sorted(info["mean_surface0"] - layers[1:]) if len(layers) >= 2 else []
        if planes:
            character += (f"; the sample split across its width at {', '.join(f'{p_ / units.um:.0f}' for p_ in planes)}"
                          f" um below the initial surface (depth {info['depth'] / units.um:.0f} um)")
        notes = self.common_notes(v, sm, pr)
        prof = info["profile_info"]
        notes.insert(0, f"surface: {info['profile_kind']}"
                     + (f", peak-to-valley {ptv / units.um:g} um (amplitude {info['amplitude'] / units.um:g} um), "
                        f"wavelength {info['wavelength'] / units.um:g} um" if info["wavelength"] > 0 else "")
                     + f", periodic width {info['width'] / units.um:.1f} um"
                     + ("; the paper's 'a0' is read as Rz (peak-to-valley), amplitude = Rz/2"
                        if info["profile_kind"] == "sinusoid" else "")
                     + (f"; measured Rz {prof.get('rz_A', math.nan) / units.um:.1f} um"
                        if "rz_A" in prof else ""))
        notes.append(f"character: {character} (jets: jet tip more than twice the initial peak-to-valley ahead "
                     f"of the valley front at the end; spall: the main body has lost the material above "
                     f"{SPALL_MIN:g} r0 below the initial surface across the whole width; {len(layers)} "
                     "full-width layers at the end)")
        notes.append(f"ejecta: mass ahead of the valley front moving faster than {v.margin:g} u_fs, u_fs the "
                     f"mean velocity of the body's {v.fs_layer:g} r0 layer below the valley front; jet tip: "
                     f"foremost cluster of fragments with >= {v.g_tip} clusters")
        n_paper = (500 * units.um * 2.4 * units.mm) / PAPER_R0 ** 2
        notes.append(f"reach: the paper's 0.5 um clusters on 500 um x 2.4 mm are about {n_paper:.1e} clusters per "
                     f"plane and, in 3D or over 7 us, about 1e13 particle-steps; this run took "
                     f"{sm['n'] * sm['nsteps']:.2e} particle-steps")
        extra = {"character": character, "spalled": spalled, "jets": bool(jets), "n_layers_end": int(len(layers)),
                 "split_depths_um": [p_ / units.um for p_ in planes],
                 "layers_min_X0_um": (layers / units.um).tolist(), "regime": self.regime(pr["ordered"]),
                 "spectrum_t_us": ts / units.us, "n_particles": sm["n"], "n_steps": sm["nsteps"],
                 "particle_steps": sm["n"] * sm["nsteps"], "stepping_time_s": sm["t_run"],
                 "u_drive_km_s": info["u"] / units.km_s, "depth_um": info["depth"] / units.um,
                 "r0_um": info["r0"] / units.um, "orientation": info["orientation"]}
        return q, notes, extra

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        info = sm["info"]
        rec, probe = self.restore(sm)
        jtxt = "off" if v.J is None else f"{v.J:g}"
        title = (f"{info['profile_kind']} Rz {2 * info['amplitude'] / units.um:g} um, lambda "
                 f"{info['wavelength'] / units.um:g} um, {result.quantities['P'].value:.1f} GPa, r0 "
                 f"{info['r0'] / units.um:g} um, J = {jtxt}")
        files = [self.write_summary(out, summaries, "ejecta")]
        files += self.history_png(out, rec, info, title, "ejecta")
        files += self.snapshots_png(out, rec, info, title, "ejecta")
        files += self.spectrum_png(out, rec, info, title, v.corrections)
        return files

    def spectrum_png(self, out, rec, info, title, corrections):
        spec = rec.spectrum
        if not spec or len(spec["g"]) == 0:
            return []
        plt = matplotlib_agg()
        g = np.asarray(spec["g"], np.int64)
        d = np.asarray(spec["diameter"], float) / units.um
        csvp = out / "ejecta_spectrum.csv"
        with open(csvp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["g", "diameter_um", "mass_kg", "v_km_s"])
            for k in range(len(g)):
                w.writerow([int(g[k]), f"{d[k]:.6g}", f"{spec['mass'][k] / units.kg:.6g}",
                            f"{spec['v'][k] / units.km_s:.6g}"])
        fig, axs = plt.subplots(1, 2, figsize=(11, 4.2))
        gs, n = np.unique(g, return_counts=True)
        axs[0].loglog(gs, n, "o")
        axs[0].set_xlabel("clusters per fragment g")
        axs[0].set_ylabel("N(g)")
        axs[0].grid(True, which="both", alpha=0.3)
        bins = np.linspace(0, max(d.max() * 1.05, 1.0), 30)
        axs[1].hist(d, bins=bins, histtype="step", label="as computed")
        if corrections:
            dc = spectrum_table(g, d * units.um, drop_below=PAPER_DROP, shift=PAPER_SHIFT)["diameter"] / units.um
            axs[1].hist(dc, bins=bins, histtype="step", label="no particles < 10 um, +5 um (paper's corrections)")
        axs[1].set_xlabel("equivalent diameter (um)")
        axs[1].set_ylabel("number of fragments")
        axs[1].legend(fontsize=8)
        fig.suptitle(f"{title}: fragments ahead of the valley at {spec['t'] / units.us:.2f} us")
        fig.tight_layout()
        png = out / "ejecta_spectrum.png"
        fig.savefig(png, dpi=110)
        plt.close(fig)
        return [png, csvp]


register_scene(EjectaScene())


__all__ = ["EjectaScene", "ProfiledShockScene", "flat_sample", "drive_params", "CASES"]
