"""MCA studies: the packing-independent elasticity table, its Cluster Dynamics contrast, the
degrading unload-reload cycle (and helpers the tests reuse).

    clusterdyn study mca-elasticity [--set size=L] [--out DIR]
    clusterdyn study mca-degrading [--set steps=N] [--out DIR]

``elasticity`` prints the table of Young's modulus, Poisson ratio, bulk and
shear modulus measured on fcc, hcp, simple cubic and random packings for
nu in {0, 0.15, 0.25, 0.35, 0.45} against the input, then the same test on a
Cluster Dynamics fcc packing of aluminium along [100] and [111] against the
nearest-neighbour central-force values (docs/theory.md 1.5), and writes both as
CSV and Markdown under ``DIR`` (default ``runs/mca-elasticity-size5``).  ``degrading`` runs a
load / unload / reload cycle of concrete and writes the curve (CSV, PNG) with
the fitted initial and unloading moduli.

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

The CD contrast (:func:`cd_elastic_constants`) applies the same test to a
pair-potential packing, with the full 6x6 stiffness (rotated lattices couple
normal and shear components): normal and hydrostatic strains on the
periodic box (``atoms.get_stress()``); each simple shear ``u_a = gamma x_b``
on a slab open along ``b`` and periodic along the other two axes, read as the
mean virial stress of the clusters more than r0 from the free faces (their
neighbourhood is the bulk one).  An fcc lattice is a Bravais lattice (every
site a centre of inversion), so the affine field is the equilibrium and no
relaxation is needed.  Central differences, ``+-strain``.
"""

import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

from .. import units
from ..scenes.base import Param
from ..analysis.stress import VOIGT
from ..build.mca import mca_packing
from ..mca.calculator import MCA
from ..mca.dynamics import MCADynamics
from ..md.layer_drives import Piston
from ..materials.mca import mca_material
from .common import out_folder, parse_params

PACKINGS = ("fcc", "hcp", "sc", "random")
NUS = (0.0, 0.15, 0.25, 0.35, 0.45)


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


# -- Cluster Dynamics contrast: the same test on a pair-potential fcc packing ------------------



def _voigt_to_tensor(C6):
    C = np.zeros((3, 3, 3, 3))
    for I, (i, j) in enumerate(VOIGT):
        for J, (k, m) in enumerate(VOIGT):
            for a, b in ((i, j), (j, i)):
                for c, e in ((k, m), (m, k)):
                    C[a, b, c, e] = C6[I, J]
    return C


def rotate_stiffness(C6, M):
    """Stiffness (6, 6) Voigt, engineering shear strains, in the frame where ``v' = M v``."""
    C = np.einsum("ia,jb,kc,ld,abcd->ijkl", M, M, M, M, _voigt_to_tensor(np.asarray(C6, float)))
    return np.array([[C[i, j, k, m] for (k, m) in VOIGT] for (i, j) in VOIGT])


def cubic_stiffness(C11, C12, C44):
    """(6, 6) Voigt stiffness of a cubic crystal in its cube axes."""
    C6 = np.zeros((6, 6))
    C6[:3, :3] = C12
    C6[range(3), range(3)] = C11
    C6[range(3, 6), range(3, 6)] = C44
    return C6


def uniaxial_moduli(C6):
    """Uniaxial stress along x from a (6, 6) stiffness: ``E = 1/S_xx``, ``nu_xy``, ``nu_xz``."""
    S = np.linalg.inv(0.5 * (C6 + C6.T))
    return 1.0 / S[0, 0], -S[1, 0] / S[0, 0], -S[2, 0] / S[0, 0]


def _cd_sample(material, r0, direction, pbc, min_periodic=4.5, min_open=7.0):
    """Periodic (or slab) CD fcc packing at least ``min_periodic`` (``min_open``) r0 long per axis."""
    from ..build import fcc_packing, repeat_lengths
    from ..calculators import ClusterDynamics
    lengths = repeat_lengths(direction, r0) / r0
    size = [max(1, math.ceil((min_periodic if p else min_open) / L - 1e-9)) for L, p in zip(lengths, pbc)]
    atoms = fcc_packing(material, r0, size=size, direction=direction, pbc=pbc)
    atoms.calc = ClusterDynamics()
    return atoms


def cd_elastic_constants(material="Al", r0=5 * units.um, direction=(1, 0, 0), strain=1e-5):
    """Elastic constants of a Cluster Dynamics fcc packing by the MCA study's static test.

    Normal and hydrostatic strains ``+-strain`` on a periodic box (``get_stress``);
    simple shears ``u_a = +-strain x_b`` on a slab open along b, read as the mean
    virial stress (``virials / Omega``, ``Omega = r0^3/sqrt 2``) of the clusters
    more than r0 from the free faces.  From the (6, 6) lab stiffness:
    uniaxial stress along x (``S = C^-1``, ``E = 1/S_xx``, ``nu = -S_yx/S_xx``),
    ``B`` from the hydrostatic strain, and the cubic constants in the crystal
    axes.  Analytic (docs/theory.md 1.5): ``C11 = 2k/a``, ``C12 = C44 = k/a``,
    ``k = -f'(r0)``, ``a = sqrt(2) r0``, ``B = rho0 c0^2``.

    Parameters
    ----------
    material : str or Material
        A CD material (with a cold curve).
    r0 : float
        Cluster size, Angstrom.
    direction : [100] | [110] | [111]
        Crystal direction along x (``fcc_packing(direction=...)``).
    strain : float
        Strain amplitude of the central differences.

    Returns
    -------
    dict
        ``direction`` (label), ``C_lab`` (6, 6), ``C11, C12, C44, B, E, nu_xy, nu_xz``
        (moduli in eV/Angstrom^3), ``cubic_residual`` (largest entry of the crystal-frame
        stiffness that is not cubic, relative to C11), ``asymmetry`` (of C_lab, relative),
        ``n_atoms``, and ``analytic``: a dict with the same moduli and ``k`` (eV/Angstrom^2).
    """
    from ..build import orientation_matrix, parse_direction
    from ..materials import get_material
    from ..potentials.cluster import ClusterPotential

    mat = get_material(material)
    key = parse_direction(direction)
    C_lab = np.zeros((6, 6))
    atoms = _cd_sample(mat, r0, key, (True, True, True))
    cell0 = atoms.cell.array.copy()
    pos0 = atoms.positions.copy()
    n_atoms = len(atoms)

    def strained_stress(F):
        atoms.set_cell(cell0, scale_atoms=False)
        atoms.positions = pos0
        atoms.set_cell(cell0 @ F.T, scale_atoms=True)
        return atoms.get_stress()

    for a in range(3):
        F = np.eye(3)
        F[a, a] += strain
        C_lab[:, a] = (strained_stress(F) - strained_stress(2 * np.eye(3) - F)) / (2 * strain)
    s_p = strained_stress((1 + strain) * np.eye(3))
    s_m = strained_stress((1 - strain) * np.eye(3))
    B = np.sum(s_p[:3] - s_m[:3]) / 3.0 / (3.0 * 2 * strain)

    omega = r0 ** 3 / math.sqrt(2.0)
    for J in range(3, 6):
        b, a = VOIGT[J]                    # u_a = gamma x_b, open along b
        pbc = [True, True, True]
        pbc[b] = False
        slab = _cd_sample(mat, r0, key, pbc)
        p0 = slab.positions.copy()
        xb = p0[:, b]
        inner = (xb > xb.min() + 1.01 * r0) & (xb < xb.max() - 1.01 * r0)
        mid = 0.5 * (xb.min() + xb.max())
        col = np.zeros(6)
        for sign in (1.0, -1.0):
            slab.positions = p0
            pos = p0.copy()
            pos[:, a] += sign * strain * (xb - mid)
            slab.positions = pos
            w = slab.calc.get_property("virials", slab)
            col += sign * w[inner].mean(axis=0) / omega
        C_lab[:, J] = col / (2 * strain)

    M = orientation_matrix(key)                         # v_lab = M v_crystal
    C_cr = rotate_stiffness(0.5 * (C_lab + C_lab.T), M.T)
    C11 = np.mean(np.diag(C_cr)[:3])
    C12 = np.mean([C_cr[i, j] for i in range(3) for j in range(3) if i != j])
    C44 = np.mean(np.diag(C_cr)[3:])
    E, nu_xy, nu_xz = uniaxial_moduli(C_lab)

    k = ClusterPotential(mat, r0).stiffness()
    lat = math.sqrt(2.0) * r0
    C_an = rotate_stiffness(cubic_stiffness(2 * k / lat, k / lat, k / lat), M)
    E_an, nuxy_an, nuxz_an = uniaxial_moduli(C_an)
    analytic = {"C11": 2 * k / lat, "C12": k / lat, "C44": k / lat, "B": mat.rho0 * mat.c0 ** 2,
                "B_springs": 4 * k / (3 * lat), "E": E_an, "nu_xy": nuxy_an, "nu_xz": nuxz_an, "k": k}
    return {"material": mat.name, "direction": "[" + "".join(str(v) for v in key) + "]", "C_lab": C_lab,
            "C11": C11, "C12": C12, "C44": C44, "B": B, "E": E, "nu_xy": nu_xy, "nu_xz": nu_xz,
            "cubic_residual": np.abs(C_cr - cubic_stiffness(C11, C12, C44)).max() / C11,
            "asymmetry": np.abs(C_lab - C_lab.T).max() / np.abs(C_lab).max(),
            "n_atoms": n_atoms, "analytic": analytic}


CD_KEYS = ("C11", "C12", "C44", "B", "E", "nu_xy", "nu_xz")


def cd_contrast_table(material="Al", r0=5 * units.um, directions=((1, 0, 0), (1, 1, 1)), strain=1e-5,
                      out=None, stream=sys.stdout):
    """The CD contrast rows (measured and analytic) for each direction; Markdown and CSV in ``out``."""
    g = units.GPa
    rows = [cd_elastic_constants(material, r0, d, strain) for d in directions]

    def fmt(k, v):
        return f"{v:.4f}" if k.startswith("nu") else f"{v / g:.3f}"

    head = ("| CD " + str(rows[0]["material"]) + " fcc, x along | C11 (GPa) | C12 (GPa) | C44 (GPa) | "
            "B (GPa) | E_x (GPa) | nu_xy | nu_xz | largest rel. diff. |\n|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        an = r["analytic"]
        dev = max(abs(r[k] - an[k]) / abs(an[k]) for k in CD_KEYS)
        lines.append(f"| {r['direction']} measured | " + " | ".join(fmt(k, r[k]) for k in CD_KEYS)
                     + f" | {dev:.1e} |")
        lines.append(f"| {r['direction']} analytic | " + " | ".join(fmt(k, an[k]) for k in CD_KEYS) + " |  |")
    text = "\n".join(lines)
    if stream is not None:
        print(text, file=stream)
        print(f"(pair potential, r0 = {r0 / units.um:g} um, rc = 1.15 r0; analytic: C11 = 2k/a, "
              "C12 = C44 = k/a, k = -f'(r0), a = sqrt(2) r0, B = rho0 c0^2, E and nu from the "
              "rotated cubic tensor; strain +-%g)" % strain, file=stream)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        with open(out / "elasticity_cd.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["direction", "kind"] + [k + ("" if k.startswith("nu") else "_GPa") for k in CD_KEYS])
            for r in rows:
                for kind, src in (("measured", r), ("analytic", r["analytic"])):
                    w.writerow([r["direction"], kind] + [src[k] if k.startswith("nu") else src[k] / g
                                                         for k in CD_KEYS])
    return rows, text


# -- degrading response: load / unload / reload ---------------------------------------------

def load_unload_reload(s):
    """Load fraction s in [0, 1] -> strain / strain_max: load, unload to zero strain, reload."""
    if s < 0.4:
        return s / 0.4
    if s < 0.6:
        return 1 - (s - 0.4) / 0.2
    return (s - 0.6) / 0.4


#: load-fraction windows of the slope fits (away from the turning points)
FIT_WINDOWS = {"initial": (0.04, 0.22), "unloading": (0.43, 0.57), "reloading": (0.65, 0.95)}


def degrading_cycle(material="concrete", size=(16, 5, 5), steps=6000, peak=0.95, damping=0.1,
                    out=None, stream=sys.stdout):
    """Load / unload / reload cycle of a degrading material (bar in tension, fcc, d = 1 A).

    The grips follow :func:`load_unload_reload` to ``strain_max = peak sigma_t / E`` (load over
    the first 40% of the steps, unload to zero strain over 20%, reload over 40%).
    Slopes are fitted on the windows :data:`FIT_WINDOWS`; ``D_mean`` is the mean
    damage of the linked pairs in the middle half of the bar at the end.
    Writes ``degrading_cycle.csv`` and ``degrading_cycle.png`` in ``out``.

    Returns
    -------
    dict with ``strain``, ``stress`` (eV/Angstrom^3), ``s`` (load fraction), the
    fitted ``E_initial``, ``E_unloading``, ``E_reloading`` (eV/Angstrom^3), ``peak_stress``,
    ``stress_at_zero_strain`` (end of unloading), ``D_mean`` and the material.
    """
    from ..materials import get_material
    from ..scenes.mca_experiments import uniaxial

    mat = get_material(material)
    em = peak * mat.sigma_t / mat.E
    t0 = time.perf_counter()
    r = uniaxial(mat, "tension", size=size, strain_max=em, steps=steps, path=load_unload_reload, damping=damping)
    e, sg = r["strain"], r["stress"]
    s = r["time"] / (steps * r["dyn"].dt)
    fits = {}
    for name, (a, b) in FIT_WINDOWS.items():
        w = (s >= a) & (s <= b)
        fits[name] = np.polyfit(e[w], sg[w], 1)
    st = r["dyn"].state
    atoms = r["atoms"]
    i_p, j_p = st.pair_rows(atoms)[:2]
    x = atoms.positions[:, 0]
    lo, hi = np.percentile(x, 25), np.percentile(x, 75)
    gauge = (st.linked_p == 1) & (x[i_p] > lo) & (x[i_p] < hi) & (x[j_p] > lo) & (x[j_p] < hi)
    D_mean = float(st.D_p[gauge].mean())
    k0 = int(np.argmin(np.abs(s - 0.6)))
    res = {"material": mat, "strain": e, "stress": sg, "s": s, "strain_max": em,
           "E_initial": fits["initial"][0], "E_unloading": fits["unloading"][0],
           "E_reloading": fits["reloading"][0], "fits": fits, "peak_stress": sg.max(),
           "stress_at_zero_strain": sg[k0], "D_mean": D_mean, "seconds": time.perf_counter() - t0,
           "size": size, "steps": steps}
    g = units.GPa
    lines = [f"{mat.name}: E = {mat.E / g:.2f} GPa, sigma_t = {mat.sigma_t / units.MPa:.3g} MPa; bar "
             f"{size[0]}x{size[1]}x{size[2]} d fcc, {steps} steps, strain_max = {em:.3g} "
             f"({peak:g} sigma_t/E), damping {damping:g}",
             f"initial modulus    {res['E_initial'] / g:8.3f} GPa  = {res['E_initial'] / mat.E:.3f} E",
             f"unloading modulus  {res['E_unloading'] / g:8.3f} GPa  = {res['E_unloading'] / mat.E:.3f} E",
             f"reloading modulus  {res['E_reloading'] / g:8.3f} GPa  = {res['E_reloading'] / mat.E:.3f} E",
             f"peak stress {res['peak_stress'] / mat.sigma_t:.3f} sigma_t; at zero strain after unloading "
             f"{res['stress_at_zero_strain'] / mat.sigma_t:+.3f} sigma_t; mean damage of gauge pairs "
             f"D = {D_mean:.3f} (1 - D = {1 - D_mean:.3f}); {res['seconds']:.1f} s"]
    if stream is not None:
        print("\n".join(lines), file=stream)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        phase = np.where(s < 0.4, "load", np.where(s < 0.6, "unload", "reload"))
        with open(out / "degrading_cycle.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["load_fraction", "strain", "stress_GPa", "stress_over_sigma_t", "phase"])
            for row in zip(s, e, sg / g, sg / mat.sigma_t, phase):
                w.writerow(row)
        (out / "degrading_cycle.txt").write_text("\n".join(lines) + "\n")
        res["png"] = _plot_cycle(res, out / "degrading_cycle.png")
    return res


def _plot_cycle(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    mat, e, sg, s = res["material"], res["strain"], res["stress"], res["s"]
    st = mat.sigma_t
    g = units.GPa
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    for (a, b), lab, c in (((0, 0.4), "load", "C0"), ((0.4, 0.6), "unload", "C3"), ((0.6, 1.01), "reload", "C2")):
        w = (s >= a - 1e-9) & (s <= b)
        ax.plot(e[w] * 1e4, sg[w] / st, color=c, lw=1.6, label=lab)
    x = np.linspace(0.0, res["strain_max"], 2)
    for name, ls in (("initial", "--"), ("unloading", ":")):
        m, c0 = res["fits"][name]
        E = res[f"E_{name}"]
        ax.plot(x * 1e4, (m * x + c0) / st, "k" + ls, lw=1.0,
                label=f"{name} fit: {E / g:.1f} GPa = {E / mat.E:.2f} E")
    # damage onset in uniaxial tension: Drucker-Prager sigma_eq = beta sigma = sigma_d
    onset = mat.extra.get("sigma_d", 0.7 * mat.sigma_c) * mat.sigma_t / mat.sigma_c
    ax.axhline(onset / st, color="0.6", lw=0.8, ls="-.", label="damage onset (sigma_d / beta)")
    ax.set_xlabel("strain (1e-4)")
    ax.set_ylabel("stress / sigma_t")
    ax.set_title(f"{mat.name}: load, unload to zero strain, reload")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def _degrading_materials():
    from ..materials import get_material, material_names
    return tuple(n for n in material_names() if getattr(get_material(n), "response", None)
                 in ("degrading", "plastic-degrading"))


def _cd_materials():
    from ..materials import cd_material_names
    return tuple(cd_material_names())


ELASTICITY_PARAMS = [
    Param("size", 5.0, "box edge of the elasticity samples in automaton sizes", low=2.0),
    Param("material", "Al", "Cluster Dynamics material of the contrast", kind="choice", choices=_cd_materials()),
]
DEGRADING_PARAMS = [
    Param("material", "concrete", "degrading MCA material", kind="choice", choices=_degrading_materials()),
    Param("steps", 6000, "steps of the whole load-unload-reload cycle", kind="int", low=100),
    Param("peak", 0.95, "peak strain as a fraction of sigma_t/E", low=0.0, high=1.0, low_open=True),
    Param("damping", 0.1, "viscous damping of relative pair velocity", low=0.0),
]


def elasticity_study(overrides=None, out=None, progress=True, quiet=None):
    """``clusterdyn study mca-elasticity``: the packing-independence table and its CD contrast."""
    quiet = (not progress) if quiet is None else quiet
    v, _ = parse_params(ELASTICITY_PARAMS, overrides, study="mca-elasticity")
    t0 = time.perf_counter()
    folder = out_folder(out, "mca-elasticity", f"size{v['size']:g}")
    stream = None if quiet else sys.stdout
    rows = elasticity_table(size=v["size"], out=folder, stream=stream)
    cd_rows, cd_text = cd_contrast_table(material=v["material"], out=folder, stream=stream)
    md = folder / "elasticity.md"
    md.write_text(md.read_text() + "\nCluster Dynamics contrast (same test, pair potential):\n\n"
                  + cd_text + "\n")
    return {"study": "mca-elasticity", "rows": rows, "cd_rows": cd_rows, "files": [str(md)],
            "wall_time_s": time.perf_counter() - t0}


def degrading_study(overrides=None, out=None, progress=True, quiet=None):
    """``clusterdyn study mca-degrading``: a load / unload / reload cycle of a degrading material."""
    quiet = (not progress) if quiet is None else quiet
    v, _ = parse_params(DEGRADING_PARAMS, overrides, study="mca-degrading")
    folder = out_folder(out, "mca-degrading", v["material"])
    res = degrading_cycle(v["material"], steps=v["steps"], peak=v["peak"], damping=v["damping"],
                          out=folder, stream=None if quiet else sys.stdout)
    keep = ("E_initial", "E_unloading", "E_reloading", "peak_stress", "stress_at_zero_strain", "D_mean",
            "strain_max", "seconds")
    out_d = {k: res[k] for k in keep}
    out_d.update({"study": "mca-degrading", "material": res["material"].name,
                  "files": [str(folder / "degrading_cycle.csv"), str(res["png"])]})
    return out_d
