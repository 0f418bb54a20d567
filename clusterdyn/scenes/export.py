"""Exporting a scene to LAMMPS (``clusterdyn export lammps SCENE``), on io's deck writer."""

import numpy as np

from ..errors import InputError
from ..io.lammps import export_lammps
from .base import get_scene
from .shock import build_shock


def export_scene(scene_name, overrides, out_dir, **kw):
    """Build a scene's set-up from ``--set`` overrides and export it (``clusterdyn export lammps``).

    Supported: ``shock``.  The deck runs the scene's full number of steps and
    dumps frames for the front analysis (:func:`clusterdyn.analysis.shock.shock_from_lammps`).
    """
    scene = get_scene(scene_name)
    if scene_name != "shock":
        raise InputError("scene", scene_name, "a scene with a LAMMPS export: shock")
    v = scene.parse(overrides)
    s = build_shock(v["material"], v["u"], v["direction"], v["size"], v["r0"], v["rc"], v["J"],
                    v["noise"], v["seed"], v["dt_factor"])
    if out_dir is None:
        raise InputError("--out", None, "a folder for the LAMMPS deck")
    extra = {"scene": "shock", "params": scene.display(v), "rho0_ase": float(s.material.rho0),
             "u_ase": float(s.u), "slab_A": float(s.slab), "length_A": float(s.length),
             "piston_mask_ids": (np.nonzero(s.piston_mask)[0] + 1).tolist(),
             "x0_lo_A": float(s.atoms.positions[~s.piston_mask, 0].min())}
    return export_lammps(s.atoms, s.calc, s.dyn, out_dir, nsteps=kw.pop("nsteps", s.nsteps),
                         frames=kw.pop("frames", v["frames"]), extra=extra, **kw)
