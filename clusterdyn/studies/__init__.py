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

Each is a :class:`~clusterdyn.studies.base.Study` registered with
:func:`~clusterdyn.studies.base.register_study`; :mod:`clusterdyn.studies.base` describes the
lifecycle they share (parse, plan, collect, report, finish).
"""

from .base import STUDIES, Study, all_studies, get_study, register_study


def study_names():
    """The registered studies' names, in the order ``clusterdyn study`` lists them."""
    return list(all_studies())


def study_params(name):
    """The study's own parameters (list of :class:`~clusterdyn.scenes.base.Param`)."""
    return list(get_study(name).params)


def study_summary(name):
    """One line on what the study does."""
    return get_study(name).summary


__all__ = ["STUDIES", "Study", "all_studies", "get_study", "register_study", "study_names", "study_params",
           "study_summary"]
