"""MCA studies: the packing-independent elasticity table (and helpers the tests reuse).

    python -m clusterdyn.mca.studies elasticity [--out DIR] [--size L] [--quick]

prints the table of Young's modulus, Poisson ratio, bulk and shear modulus
measured on fcc, hcp, simple cubic and random packings for
nu in {0, 0.15, 0.25, 0.35, 0.45} against the input, and writes it as CSV and
Markdown under ``DIR`` (default ``out/mca``).

Method (static, faithful to the method's claim that a homogeneous strain
gives isotropic linear elasticity whatever the packing):

* normal strains and hydrostatic strain: a periodic box; the strain is
  imposed on the cell and the automata (affine), the pair state is
  evaluated at the strained positions, and the volume-averaged Love-Weber
  stress is read.  Random packings are then relaxed with damped MCA dynamics
  at fixed cell (their cells are not symmetric, so the affine field carries
  small torques and forces) before reading the stress.
* Young's modulus and Poisson ratio come from the uniaxial-stress response,
  obtained by superposing the three normal-strain responses (the compliance
  ``S = C^-1``, ``E = 1/S_aa``, ``nu = -S_ba/S_aa``, averaged over axes):
  exactly a uniaxial-stress test of a linear body.
* simple shear: a slab periodic in x and z with free faces in y; the top and
  bottom layers are held, the rest starts from ``u_x = gamma y`` with the
  automata rotated by the material spin ``-gamma/2`` (relaxed for random
  packings); ``G = <sigma_xy> / gamma`` over the middle half.
"""

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

from .. import units
from .builders import mca_packing
from .calculator import MCA
from .dynamics import Grip, MCADynamics
from .materials import mca_material

PACKINGS = ("fcc", "hcp", "sc", "random")
NUS = (0.0, 0.15, 0.25, 0.35, 0.45)


def elastic_material(nu, E_GPa=100.0, rho=2.7, response="elastic", **kw):
    """A purely elastic material with the given Poisson ratio (E = 100 GPa, rho = 2.7 g/cm3)."""
    return mca_material(f"elastic-nu{nu}", rho, E_GPa, nu, response=response, **kw)


def _relax(atoms, steps, damping=0.15, grips=()):
    dyn = MCADynamics(atoms, damping=damping, grips=grips)
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
        grips = [Grip(held, 0, 0.0, lateral="fixed")]
        _relax(atoms, relax, grips=grips)
    s = atoms.calc.get_property("stresses", atoms)
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


def _err(row):
    e = {"E": (row["E"] - row["E_in"]) / row["E_in"],
         "K": (row["K"] - row["K_in"]) / row["K_in"],
         "G": (row["G"] - row["G_in"]) / row["G_in"]}
    if row["nu_in"] == 0.0:
        e["nu"] = row["nu"] - row["nu_in"]          # absolute for nu = 0
    else:
        e["nu"] = (row["nu"] - row["nu_in"]) / row["nu_in"]
    return e


def elasticity_table(nus=NUS, packings=PACKINGS, size=5.0, out=None, stream=sys.stdout):
    rows = []
    t0 = time.perf_counter()
    for nu in nus:
        for pk in packings:
            row = elastic_case(nu, pk, size=size)
            row.update({f"err_{k}": v for k, v in _err(row).items()})
            rows.append(row)
    g = units.GPa
    head = ("| packing | nu in | E (GPa) | err E | nu | err nu | K (GPa) | err K | G (GPa) | err G |\n"
            "|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        lines.append(f"| {r['packing']} | {r['nu_in']:.2f} | {r['E'] / g:.2f} | {100 * r['err_E']:+.2f}% | "
                     f"{r['nu']:.4f} | {('%+.4f' % r['err_nu']) if r['nu_in'] == 0 else ('%+.2f%%' % (100 * r['err_nu']))} | "
                     f"{r['K'] / g:.2f} | {100 * r['err_K']:+.2f}% | {r['G'] / g:.2f} | {100 * r['err_G']:+.2f}% |")
    text = "\n".join(lines)
    if stream is not None:
        print(text, file=stream)
        print(f"(input E = 100 GPa; err nu absolute for nu = 0; {time.perf_counter() - t0:.1f} s)",
              file=stream)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "elasticity.md").write_text(text + "\n")
        with open(out / "elasticity.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            keys = ["packing", "nu_in", "E", "nu", "K", "G", "err_E", "err_nu", "err_K", "err_G"]
            w.writerow([k + ("_GPa" if k in "EKG" else "") for k in keys])
            for r in rows:
                w.writerow([r[k] / g if k in ("E", "K", "G") else r[k] for k in keys])
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m clusterdyn.mca.studies")
    ap.add_argument("study", choices=["elasticity"])
    ap.add_argument("--out", default="out/mca")
    ap.add_argument("--size", type=float, default=5.0, help="box edge in automaton sizes")
    a = ap.parse_args(argv)
    if a.study == "elasticity":
        elasticity_table(size=a.size, out=a.out)


if __name__ == "__main__":
    main()
