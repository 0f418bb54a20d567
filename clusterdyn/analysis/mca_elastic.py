"""MCA's packing-independent elasticity: the static tests of E, nu, K and G on a packing.

The method (faithful to the method's claim that a homogeneous strain gives isotropic linear
elasticity whatever the packing):

* normal strains and hydrostatic strain (:func:`normal_response`): a periodic box; the strain is
  imposed on the cell and the automata (affine), the pair state is evaluated at the strained
  positions, and the volume-averaged Love-Weber stress is read.  Random packings are then
  relaxed with damped MCA dynamics at fixed cell (their cells are not symmetric, so the affine
  field carries small torques and forces) before reading the stress.
* Young's modulus and Poisson ratio come from the uniaxial-stress response, obtained by
  superposing the three normal-strain responses (the compliance ``S = C^-1``, ``E = 1/S_aa``,
  ``nu = -S_ba/S_aa``, averaged over axes): exactly a uniaxial-stress test of a linear body.
* simple shear (:func:`shear_modulus`): a slab periodic in x and z with free faces in y; the top
  and bottom layers are held, the rest starts from ``u_x = gamma y`` with the automata rotated by
  the material spin ``-gamma/2`` (relaxed for random packings); ``G = <sigma_xy> / gamma`` over
  the middle half.

``clusterdyn study mca-elasticity`` tabulates them (:mod:`clusterdyn.studies.mca`); the same
test on a Cluster Dynamics packing is :func:`clusterdyn.analysis.elastic.cd_elastic_constants`.
Moduli in eV/Angstrom^3.
"""

import numpy as np

from ..build.mca import mca_packing
from ..materials.mca import mca_material
from ..mca.calculator import MCA
from ..mca.dynamics import MCADynamics
from ..md.layer_drives import Piston


def elastic_material(nu, E_GPa=100.0, rho=2.7, response="elastic", **kw):
    """A purely elastic material with the given Poisson ratio (E = 100 GPa, rho = 2.7 g/cm3)."""
    return mca_material(f"elastic-nu{nu}", rho, E_GPa, nu, response=response, **kw)


def _relax(atoms, steps, damping=0.15, hold_layer_rotation=False):
    dyn = MCADynamics(atoms, damping=damping, hold_layer_rotation=hold_layer_rotation)
    dyn.run(steps)
    return dyn


def normal_response(mat, packing, size=5.0, strain=1e-6, relax=None, seed=0):
    """3x3 normal stiffness block and hydrostatic response of a periodic packing (d = 1 A)."""
    d = 1.0
    if relax is None:
        relax = 400 if packing == "random" else 0
    C = np.zeros((3, 3))
    for a in range(4):
        atoms = mca_packing(mat, d, (size, size, size), packing, pbc=True, seed=seed)
        atoms.calc = MCA()
        atoms.calc.setup(atoms)
        F = np.eye(3)
        if a < 3:
            F[a, a] += strain
        else:
            F += strain * np.eye(3)
        atoms.set_cell(atoms.cell.array @ F, scale_atoms=True)
        if relax:
            _relax(atoms, relax)
        s = atoms.get_stress(voigt=False)
        if a < 3:
            C[:, a] = np.diag(s) / strain
        else:
            Kb = np.trace(s) / 3.0 / (3.0 * strain)
    Sm = np.linalg.inv(C)
    E = np.mean([1.0 / Sm[a, a] for a in range(3)])
    nu = np.mean([-Sm[b, a] / Sm[a, a] for a in range(3) for b in range(3) if a != b])
    return {"E": E, "nu": nu, "K": Kb, "C": C}


def shear_modulus(mat, packing, size=5.0, gamma=1e-6, relax=None, seed=0):
    """Simple shear of a slab periodic in x and z, held at its y faces (see module doc)."""
    d = 1.0
    if relax is None:
        relax = 600 if packing == "random" else 0
    atoms = mca_packing(mat, d, (size, size + 2.0, size), packing, pbc=(True, False, True), seed=seed)
    atoms.calc = MCA()
    atoms.calc.setup(atoms)
    y = atoms.positions[:, 1]
    ymid = 0.5 * (y.min() + y.max())
    atoms.positions[:, 0] += gamma * (y - ymid)
    atoms.arrays["theta"][:, 2] = -0.5 * gamma
    h = y.max() - y.min()
    held = (y < y.min() + 0.6 * d) | (y > y.max() - 0.6 * d)
    if relax:
        atoms.set_constraint(Piston(held, 0.0))            # the faces held at rest, not rotating
        _relax(atoms, relax, hold_layer_rotation=True)
        atoms.set_constraint()
    s = atoms.calc.get_property("automaton_stresses", atoms)
    om = atoms.calc.state.per_atom("omega_n", atoms)
    mid = np.abs(atoms.positions[:, 1] - ymid) < 0.25 * h
    sxy = np.sum(s[mid, 5] * om[mid]) / np.sum(om[mid])
    return sxy / gamma


def elastic_case(nu, packing, size=5.0, seed=0):
    mat = elastic_material(nu)
    r = normal_response(mat, packing, size=size, seed=seed)
    G = shear_modulus(mat, packing, size=size, seed=seed)
    return {"packing": packing, "nu_in": nu, "E_in": mat.E, "K_in": mat.K, "G_in": mat.G,
            "E": r["E"], "nu": r["nu"], "K": r["K"], "G": G}


def relative_errors(row):
    """Errors of a row of :func:`elastic_case` against its input moduli (relative; absolute for nu = 0)."""
    e = {"E": (row["E"] - row["E_in"]) / row["E_in"],
         "K": (row["K"] - row["K_in"]) / row["K_in"],
         "G": (row["G"] - row["G_in"]) / row["G_in"]}
    if row["nu_in"] == 0.0:
        e["nu"] = row["nu"] - row["nu_in"]          # absolute for nu = 0
    else:
        e["nu"] = (row["nu"] - row["nu_in"]) / row["nu_in"]
    return e
