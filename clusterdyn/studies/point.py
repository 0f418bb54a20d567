"""One material-point run as a study's cached unit (``flow-stress-point``), shared by the
flow-stress and calibrate studies.

The physics is :func:`clusterdyn.scenes.material_point.material_point`; here are its parameters in
display units (:data:`POINT_PARAMS`), the runner that turns its dict into a
:class:`~clusterdyn.scenes.base.SceneResult` and the :class:`~clusterdyn.studies.common.StudyPoint`
:data:`POINT` that :func:`~clusterdyn.studies.common.run_scene` caches as
``<cache>/flow-stress-point-<hash>``.
"""

from .. import units
from ..scenes.base import Param, Quantity, SceneResult
from ..scenes.material_point import BOUNDARIES, material_point
from ..scenes.shock import CD_MATERIALS
from .common import ListParam, StudyPoint

#: the material-point tests
TESTS = ("confined", "unconfined", "tension")

#: parameters of one material-point run (the study passes them in these display units)
POINT_PARAMS = [
    Param("material", "Al", "material", kind="choice", choices=CD_MATERIALS),
    Param("r0", 100.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("size", 24.0, "cube edge, in r0", low=4.0),
    Param("sample", "polycrystal", "polycrystal or a [100] single crystal", kind="choice",
          choices=("polycrystal", "single")),
    Param("grain_size", 11.0, "mean grain diameter, in r0", low=3.0),
    Param("porosity", 0.14, "target porosity", low=0.0, high=0.5),
    Param("rc", 1.15, "cutoff (multiple of r0)", low=1.0, high=1.414, low_open=True),
    Param("boundaries", "bonded", "grain-boundary pairs attract (bonded) or only repel (repulsive)",
          kind="choice", choices=BOUNDARIES),
    ListParam("strains", (0.05, 0.10, 0.15), "strains at which the curve is read; the ramp runs to the last",
              low=0.0, high=0.49, low_open=True),
    Param("rate", 1e-3, "strain rate of the ramp, per r0/c0", low=0.0, low_open=True),
    Param("hold", 30.0, "hold at the final strain, in r0/c0", low=0.0, low_open=True),
    Param("average", 10.0, "window at the end of the hold, in r0/c0", low=0.0, low_open=True),
    Param("dt", 0.1, "time step, in r0/c0", low=0.0, high=0.5, low_open=True),
    Param("J", 50.0, "pair damping Gamma = c0/(J r0)", low=0.0, low_open=True, optional=True),
    Param("noise", 10.0, "random velocity after the quench", unit="m/s", low=0.0),
    Param("seed", 1, "random seed (grains, orientations, noise)", kind="int", low=0),
    Param("relax_cycles", 12, "quench cycles of 100 damped steps", kind="int", low=0),
    Param("test", "confined", "confined (uniaxial strain), unconfined (uniaxial stress) or tension (uniaxial "
          "strain, stretched: the spall strength)", kind="choice", choices=TESTS),
    Param("law_sigma_t", None, "boundary law: tensile strength (none = no law)", unit="GPa", low=0.0,
          low_open=True, optional=True),
    Param("law_G_c", 1e5, "boundary law: fracture energy per area, J/m^2", low=0.0, low_open=True),
    Param("law_tau_c", 0.0, "boundary law: cohesive shear strength", unit="GPa", low=0.0),
    Param("law_mu", 0.0, "boundary law: Coulomb friction", low=0.0),
    Param("law_select", "boundary", "boundary law on the pairs across grain boundaries or on all pairs",
          kind="choice", choices=("boundary", "all")),
]

#: material-point runs actually computed in this process (runs read back from a study folder are not counted)
RUNS = [0]


def point_law(v):
    """The boundary law of a point's values (display units) or None."""
    if v.get("law_sigma_t") is None:
        return None
    return {"sigma_t": v["law_sigma_t"] / units.GPa, "G_c": v["law_G_c"],
            "tau_c": v["law_tau_c"] / units.GPa, "mu": v["law_mu"], "select": v["law_select"]}


def _point_runner(v, out=None, progress=False):
    RUNS[0] += 1
    law = point_law(v)
    test = v.get("test", "confined")
    r = material_point(law=law, tension=test == "tension", lateral_free=test == "unconfined",
                       material=v["material"], r0=v["r0"], size=v["size"], sample=v["sample"],
                       grain_size=v["grain_size"], porosity=v["porosity"], rc=v["rc"], boundaries=v["boundaries"],
                       strains=v["strains"], rate=v["rate"], hold=v["hold"], average=v["average"], dt=v["dt"],
                       J=v["J"], noise=v["noise"], seed=v["seed"], relax_cycles=v["relax_cycles"], progress=progress)
    rel = r["relaxed"]
    q = {"flow_stress": Quantity(r["flow_stress"], "GPa", note="relaxed von Mises intensity at the final strain"),
         "sigma_u_ramp_end": Quantity(r["sigma_u_ramp_end"], "GPa"),
         "sigma_u_max": Quantity(r["sigma_u_max"], "GPa"),
         "sigma_axial": Quantity(rel["sigma_axial"], "GPa", note="-sigma_xx, relaxed"),
         "sigma_lateral": Quantity(rel["sigma_lateral"], "GPa", note="-(sigma_yy + sigma_zz)/2, relaxed"),
         "n_clusters": Quantity(r["n_clusters"], "")}
    if r["sample"]:
        q["porosity"] = Quantity(r["sample"]["porosity"], "")
    if r["spall_strength"] is not None:
        q["spall_strength"] = Quantity(r["spall_strength"], "GPa", note="largest tensile sigma_axial")
    return SceneResult("flow-stress-point", q, r["wall_time_s"], extra=r)


#: the cached unit of the study (not a registered scene: ``clusterdyn run`` does not list it)
POINT = StudyPoint("flow-stress-point", "one uniaxial-strain material-point test", POINT_PARAMS, _point_runner)
