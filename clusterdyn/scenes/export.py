"""Exporting a scene to LAMMPS (``clusterdyn export lammps SCENE``), on io's deck writer.

Every setting of a scene is in the exported deck or refused in one line
naming it (docs/lammps.md has the table).  The deck is built from what the
scene itself builds (:meth:`~clusterdyn.scenes.lifecycle.SceneDef.setup` of
each stage: sample, calculator, drives, dynamics), so the physics settings
reach it through the Atoms, the calculator (materials, r0, rc, set-up
bonds), the drives and the dynamics (time step, damping) that
:func:`clusterdyn.io.lammps.export.export_lammps` writes or refuses; the run length
is the stage's steps and ``frames`` the number of dumped frames.

What a deck cannot carry are the run controls of clusterdyn's own run
(:data:`NOT_IN_DECK`): given with ``--set`` to a value the deck does not
honour they are refused; left at their defaults they are listed in cd.json
under ``not_in_deck`` with the reason.

A scene of several stages (``plate-impact`` with ``sample=both``,
``polycrystal-shock`` with ``single=true``) gets one deck per stage, in
sub-folders named after the stages.  MCA scenes have no LAMMPS form and are
refused.
"""

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.lammps.export import check_deck, export_lammps
from .base import get_scene
from .lifecycle import check_out

#: scenes with a LAMMPS export
EXPORTABLE = ("shock", "plate-impact", "polycrystal-shock")

#: run controls a deck cannot carry: key -> (values the deck honours (a callable), why)
NOT_IN_DECK = {
    "h5md": (lambda x: not x, "the deck writes its frames as a LAMMPS dump (frames.dump), not as H5MD"),
    "h5md_frames": (lambda x: False, "the deck dumps 'frames' frames to frames.dump: set frames"),
    "checkpoint_every": (lambda x: x == 0, "the deck writes no clusterdyn checkpoints"),
    "dt_retries": (lambda x: x == 0, "LAMMPS stops at a failing step ('Pair distance < table inner cutoff') "
                   "instead of running again with half the time step"),
    "profile_times": (lambda x: False, "the plate-impact profile analysis runs on clusterdyn's own frames; "
                      "the deck dumps 'frames' frames"),
}


def _jsonable(v):
    if isinstance(v, Mapping):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def check_exportable(scene, overrides, v):
    """Refuse (InputError, one line) a scene without a LAMMPS form or a given key the deck cannot honour.

    Returns ``{key: why}`` of the run controls left at defaults the deck does not carry.
    """
    if scene.name not in EXPORTABLE:
        why = ("MCA automata (links that break, Coulomb friction) have no LAMMPS form in this export"
               if scene.name.startswith("mca") else "its deck, with the analysis of its dumps, is written by "
               f"clusterdyn run {scene.name} --engine lammps --deck-only --out DIR")
        raise InputError("scene", scene.name, "a Cluster Dynamics scene with a LAMMPS export: "
                         + ", ".join(EXPORTABLE), hint=why)
    skipped = {}
    for key, (honoured, why) in NOT_IN_DECK.items():
        if key not in v:
            continue
        if key in (overrides or {}):
            if not honoured(v[key]):
                raise InputError(key, overrides[key], "a value a LAMMPS deck honours (not in the deck)", hint=why)
        elif not honoured(v[key]):
            skipped[key] = why
    return skipped


def export_scene(scene_name, overrides, out_dir, **kw):
    """Build a scene's set-up from ``--set`` overrides and export it (``clusterdyn export lammps``).

    Exportable: ``shock`` (every parameter, with ``u_history`` as ``fix move
    variable``), ``plate-impact`` and ``polycrystal-shock`` (one deck per
    stage); the deck runs each stage's full number of steps and dumps
    ``frames`` frames (for the shock the front analysis
    :func:`clusterdyn.analysis.shock.shock_from_lammps` reads them).
    ``kw``: passed to :func:`~clusterdyn.io.lammps.export.export_lammps` (``nsteps``,
    ``frames``, ``n_points`` override the scene's).  Refusals (InputError) come
    before any file is written.

    Returns the list of deck folders.
    """
    scene = get_scene(scene_name)
    if out_dir is None:
        raise InputError("--out", None, "a folder for the LAMMPS deck")
    v = scene.parse(overrides)
    skipped = check_exportable(scene, overrides, v)
    scene.check(v)
    from .packing import refuse_law_on_lammps
    refuse_law_on_lammps(v)
    out = check_out(out_dir)
    stages = scene.plan(v)
    built = [scene.build_stage(v, name) for name in stages]   # build (and refuse) every stage before any deck
    for st in built:
        check_deck(st.atoms, st.atoms.calc, st.dyn)   # what the deck cannot carry is refused here
    folders = []
    for st in built:
        name, atoms, dyn, info = st.name, st.atoms, st.dyn, st.info
        folder = out if len(stages) == 1 else out / name
        extra = {"scene": scene.name, "stage": name, "params": scene.display(v), "not_in_deck": skipped,
                 "stage_info": _jsonable(info)}
        piston = info.get("piston_index", info.get("piston"))
        if piston is not None:                  # a piston shock: what shock_from_lammps needs
            ax = int(info["axis"])
            mask = np.zeros(len(atoms), bool)
            mask[np.asarray(piston, dtype=np.int64)] = True
            extra.update({"rho0_ase": float(info["rho0"]), "u_ase": float(info["u"]), "slab_A": float(info["slab"]),
                          "length_A": float(info["length"]), "axis": ax,
                          "piston_mask_ids": (np.nonzero(mask)[0] + 1).tolist(),
                          "x0_lo_A": float(atoms.positions[~mask, ax].min())})
        kwargs = dict(kw)
        nsteps = kwargs.pop("nsteps", int(info["nsteps"]))
        frames = kwargs.pop("frames", v.frames)
        folders.append(Path(export_lammps(atoms, atoms.calc, dyn, folder, nsteps=nsteps, frames=frames,
                                          extra=extra, **kwargs)))
    return folders
