"""The packing of a CD polycrystal in a scene: the paper's (default), cohesionless boundaries, or the
boundary pair law of :mod:`clusterdyn.md.boundary` with a material preset or a parameter file.

``--set packing=NAME`` (a key of :data:`clusterdyn.build.polycrystal.PACKINGS`) or
``--set packing=path/to/packing.json`` (the same keys).  Material presets are calibrated (tuned)
to the targets they name (docs/polycrystal.md, "Calibrated packings").

:func:`prepare` gives a built polycrystal its calculator (and the law's term): with the law,
the bonds are marked on the packing as built, the packing is quenched with them held elastic
(:attr:`~clusterdyn.md.boundary.BoundaryTerm.hold`), then released, so a bond whose quenched
tension exceeds its strength fails at once (counted in the report), and quenched again with
the law as it is (bonds may fail: the packing settles to rest).  The scene attaches the
term to its dynamics: ``dyn.attach_piece(term)``.
"""

from ..build.polycrystal import PACKINGS, packing_spec
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..errors import InputError
from ..md.boundary import BoundaryLaw, apply_boundary_law
from .base import Param

__all__ = ["packing_param", "resolve_packing", "prepare", "quench_and_launch", "PACKINGS"]


def packing_param(default="paper", doc=None):
    """The scenes' ``packing`` parameter: a preset name or a JSON file of packing keys."""
    return Param("packing", default, doc or ("packing of the polycrystal: " + ", ".join(PACKINGS)
                                             + ", or a JSON file of its keys (docs/polycrystal.md)"), kind="str")


def resolve_packing(value):
    """The packing dict of a ``packing`` parameter value (checked: one-line InputError)."""
    return packing_spec(value)


def law_of(spec):
    """The :class:`~clusterdyn.md.boundary.BoundaryLaw` of a packing with ``boundaries="law"`` (else None)."""
    if spec["boundaries"] != "law":
        return None
    try:
        return BoundaryLaw.fromdict(spec["law"], display=True)
    except (TypeError, ValueError, KeyError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError("packing: law", spec["law"], f"sigma_t, G_c or ductility, tau_c, mu, kt_ratio, select ({exc})") from None


def prepare(atoms, spec, rc, relax=None):
    """Calculator for a polycrystal ``atoms`` (``arrays['grain']``) with packing ``spec``.

    ``relax(atoms, term)``: the scene's quench (returns its report), run with the calculator set
    (and the law's bonds held elastic).  Returns ``(calc, term, report)``: ``term`` is None
    unless the packing uses the law; ``report`` the quench's, plus ``boundary`` (the law's bonds:
    total, failed at release, damaged).  ``atoms.calc`` is set.
    """
    kind = spec["boundaries"]
    term = None
    if kind == "law":
        calc, term = apply_boundary_law(atoms, law_of(spec), rc=rc)
        term.hold = True
    elif kind == "repulsive":
        mark_initial_bonds(atoms, rc=rc, within="grain")
        calc = ClusterDynamics(rc=rc, attraction="initial")
    else:
        calc = ClusterDynamics(rc=rc)
    atoms.calc = calc
    report = relax(atoms, term) if relax is not None else None
    if term is not None:
        term.hold = False
        import numpy as np
        term.accumulate(atoms, np.zeros((len(atoms), 3)))     # the quenched openings' damage, stored
        report = dict(report or {}, boundary_at_release=term.summary())
        if relax is not None:               # released: quenched again with the law as it is
            report["released"] = relax(atoms, term)
        report["boundary"] = term.summary()
    return calc, term, report


def quench_and_launch(atoms, spec, rc, mover, axis, gap, velocity, relax, cycles=12):
    """Bodies built at rest and apart (``atoms.arrays['body']``) with packing ``spec``: quenched
    (:func:`prepare` with ``relax(atoms, term)``, the scene's quench of ``cycles`` x 100 steps
    without lateral rescaling, e.g. :func:`clusterdyn.scenes.plate_impact.relax_sample`; the law's
    bonds held then released), then body
    ``mover`` brought to clearance ``gap`` (between the clusters' spheres, as
    :func:`clusterdyn.build.bodies.place`) from the others along ``axis``, on the side it came
    from, and given ``velocity`` (3,); the others at rest.  Returns ``(calc, term, notes)``."""
    import numpy as np
    calc, term, report = prepare(atoms, spec, rc, relax)
    m = atoms.arrays["body"] == mover
    z, rad = atoms.positions[:, axis], atoms.arrays["radius"]
    if z[m].mean() > z[~m].mean():          # above the others: moved down
        atoms.positions[m, axis] -= float((z - rad)[m].min() - (z + rad)[~m].max()) - gap
    else:
        atoms.positions[m, axis] += float((z - rad)[~m].min() - (z + rad)[m].max()) - gap
    vel = np.zeros((len(atoms), 3))
    vel[m] = np.asarray(velocity, float)
    atoms.set_velocities(vel)
    notes = [f"packing {spec.get('name', '')}: grains of {spec['grain_size']:g} r0, porosity {spec['porosity']:g} "
             f"(target), boundaries {spec['boundaries']}, rc {rc:g} (the scene's); quenched {cycles} x 100 steps "
             f"apart, smallest pair {report['min_r_over_r0']:.3f} r0"]
    if term is not None:
        b = report["boundary"]
        notes.append(f"boundary law: {b['bonds']} bonds, {report['boundary_at_release']['failed']} failed at "
                     f"release, {b['failed']} failed after the second quench")
    return calc, term, notes


def refuse_law_on_lammps(v):
    """The boundary pair law has no LAMMPS form yet: a packing that uses it is refused, in one line,
    by the LAMMPS export and the LAMMPS engine alike (before any work)."""
    if v.get("packing") is not None and resolve_packing(v["packing"])["boundaries"] == "law":
        raise InputError("packing", v["packing"], "a packing without the boundary law on LAMMPS",
                         hint="the boundary pair law (clusterdyn.md.boundary) has no LAMMPS form yet: "
                              "run it on the numba engine")
