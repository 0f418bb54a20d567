"""Studies: sweeps of scenes that produce tables and figures (``clusterdyn study NAME``).

A study is a function ``study(overrides, out=None, progress=True, quiet=None)``:
``overrides`` maps parameter names to text (``{"material": "Pb", "u": "1,2,3km/s"}``)
or Python values; ``out`` is the folder for its CSV, PNG and JSON files
(default ``runs/<study>-<tag>``); with ``progress`` it shows tqdm bars and
prints its tables (``quiet`` overrides the printing).  It returns a
JSON-ready dict listing every run.

====================  ======================================================================
hugoniot              piston-speed sweep of the shock scene: D-u and P-rho against the
                      experimental Hugoniot and the cold curve; damping, attraction and
                      low-u checks; two-phase samples against the mixture rule
convergence           error of D against the experiment and the finest run, versus wall
                      time and particle-steps, over sample size, time step, cutoff,
                      noise and r0
stability             the measured time-step limit (bounded energy error) for u = 0-8 km/s
mca-elasticity        MCA's packing-independent elastic constants (E, nu, K, G on fcc, hcp,
                      sc and random packings) and the Cluster Dynamics contrast
mca-degrading         a load / unload / reload cycle of a degrading MCA material
mca-compression-flow  MCA through large strain: a Johnson-Cook cylinder between
                      frictionless platens to 60% strain against the input hardening curve
mca-taylor            every room-temperature 6061-T6 Taylor test with the MCA rod
flow-stress           the flow stress of a CD polycrystal (uniaxial-strain material-point
                      test) against grain size, porosity, rc and boundary cohesion, and the
                      packing closest to a target yield stress
calibrate             tunes the boundary pair law (docs/theory.md 1.11) to target flow
                      stress and spall strength; writes a packing file
dusting               numerical dusting of a smooth free surface against u, rc, damping
                      and r0 (the CD paper's figs. 18-20)
====================  ======================================================================
"""

import importlib

from ..errors import InputError

#: study name -> ("module:function:parameter list", summary)
STUDIES = {
    "hugoniot": ("hugoniot:hugoniot_study:PARAMS", "piston-speed sweep of the shock scene: D-u and P-rho "
                 "against the experimental Hugoniot (also forwards the shock scene's parameters)"),
    "convergence": ("convergence:convergence_study:PARAMS", "error of D against experiment and the finest run "
                    "versus wall time, over size, time step, cutoff, noise and r0"),
    "stability": ("stability:stability_study:PARAMS", "the measured time-step limit (bounded energy error) "
                  "against u"),
    "mca-elasticity": ("mca:elasticity_study:ELASTICITY_PARAMS", "MCA's packing-independent E, nu, K, G on "
                       "fcc, hcp, sc and random packings, and the Cluster Dynamics contrast"),
    "mca-degrading": ("mca:degrading_study:DEGRADING_PARAMS", "a load / unload / reload cycle of a degrading "
                      "MCA material"),
    "mca-compression-flow": ("mca_flow:compression_flow_study:PARAMS", "MCA large strain: a Johnson-Cook "
                             "cylinder between frictionless platens to 60% strain against the input curve"),
    "mca-taylor": ("mca_taylor:taylor_study:PARAMS", "every room-temperature 6061-T6 Taylor test with the MCA "
                   "rod (Johnson-Cook, large strain): Lf/L0, Df/D0 against the tests, error against wall time"),
    "flow-stress": ("flow_stress:flow_stress_study:PARAMS", "flow stress of a CD polycrystal (material-point "
                    "test) against grain size, porosity, rc and boundary cohesion; the packing closest to a target"),
    "calibrate": ("calibrate:calibrate_study:PARAMS", "tune the boundary pair law to target strengths (flow "
                  "stress, spall strength): unconfined, tension and confined material-point tests; writes a "
                  "packing file"),
    "dusting": ("dusting:dusting_study:PARAMS", "dispersed clusters of a shocked smooth free surface against u, "
                "rc, damping and r0 (CD paper figs. 18-20)"),
}


def study_names():
    return list(STUDIES)


def _entry(name):
    if name not in STUDIES:
        raise InputError("study", name, "one of " + ", ".join(STUDIES))
    mod, fn, params = STUDIES[name][0].split(":")
    return importlib.import_module(f"{__name__}.{mod}"), fn, params


def get_study(name):
    """The study function registered as ``name`` (see :data:`STUDIES`)."""
    mod, fn, _ = _entry(name)
    return getattr(mod, fn)


def study_params(name):
    """The study's own parameters (list of :class:`~clusterdyn.scenes.base.Param`)."""
    mod, _, params = _entry(name)
    return list(getattr(mod, params))


def study_summary(name):
    """One line on what the study does."""
    _entry(name)
    return STUDIES[name][1]


__all__ = ["STUDIES", "get_study", "study_names", "study_params", "study_summary"]
