"""Elastic constants of a Cluster Dynamics lattice, and its static uniaxial compression.

* :func:`cd_elastic_constants`: the full (6, 6) stiffness of a CD fcc packing by static strains
  (the MCA elasticity test's method applied to the pair potential, :mod:`clusterdyn.analysis.mca_elastic`),
  with the nearest-neighbour central-force values of docs/theory.md 1.5 beside it.  Normal and
  hydrostatic strains on the periodic box (``atoms.get_stress()``); each simple shear
  ``u_a = gamma x_b`` on a slab open along ``b`` and periodic along the other two axes, read as
  the mean virial stress of the clusters more than r0 from the free faces (their neighbourhood is
  the bulk one).  An fcc lattice is a Bravais lattice (every site a centre of inversion), so the
  affine field is the equilibrium and no relaxation is needed.  Central differences,
  ``+-strain``.
* :func:`uniaxial_stress`: the longitudinal stress of the lattice under uniaxial compression
  (the static check behind the soft shock response near 2 km/s, ``clusterdyn study hugoniot``).
* Stiffness algebra in Voigt notation (order xx, yy, zz, yz, xz, xy; engineering shear strains):
  :func:`cubic_stiffness`, :func:`rotate_stiffness`, :func:`uniaxial_moduli`.

Moduli and stresses in eV/Angstrom^3 (``/ units.GPa`` for GPa).
"""

import math

import numpy as np

from .. import units
from ..build import fcc_packing, orientation_matrix, parse_direction, repeat_lengths
from ..calculators import ClusterDynamics, mark_initial_bonds
from ..materials import get_material
from ..potentials.cluster import ClusterPotential
from .stress import VOIGT


def voigt_to_tensor(C6):
    """(3, 3, 3, 3) stiffness tensor from a (6, 6) Voigt one (engineering shear strains)."""
    C = np.zeros((3, 3, 3, 3))
    for I, (i, j) in enumerate(VOIGT):
        for J, (k, m) in enumerate(VOIGT):
            for a, b in ((i, j), (j, i)):
                for c, e in ((k, m), (m, k)):
                    C[a, b, c, e] = C6[I, J]
    return C


def rotate_stiffness(C6, M):
    """Stiffness (6, 6) Voigt, engineering shear strains, in the frame where ``v' = M v``."""
    C = np.einsum("ia,jb,kc,ld,abcd->ijkl", M, M, M, M, voigt_to_tensor(np.asarray(C6, float)))
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
    lengths = repeat_lengths(direction, r0) / r0
    size = [max(1, math.ceil((min_periodic if p else min_open) / L - 1e-9)) for L, p in zip(lengths, pbc)]
    atoms = fcc_packing(material, r0, size=size, direction=direction, pbc=pbc)
    atoms.calc = ClusterDynamics()
    return atoms


def cd_elastic_constants(material="Al", r0=5 * units.um, direction=(1, 0, 0), strain=1e-5):
    """Elastic constants of a Cluster Dynamics fcc packing by the MCA elasticity test's static method.

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


def uniaxial_stress(material, deltas, direction="100", rc=1.15, attraction="all", r0=5 * units.um):
    """Longitudinal stress ``-sigma_xx`` of the lattice under uniaxial compression (ASE units).

    A periodic fcc block with ``direction`` along x is compressed along x only,
    to density ``delta * rho0`` (affine, no relaxation: every cluster of an fcc
    lattice is a centre of symmetry, so the affine state is in equilibrium),
    and the virial stress is read.  With ``attraction="initial"`` the pairs
    within the cutoff before compression are the set-up bonds.

    Returns
    -------
    (n,) array of ``-sigma_xx`` (eV/Angstrom^3).
    """
    L = repeat_lengths(direction, r0)
    size = tuple(int(max(2, math.ceil(4.5 * r0 / x))) for x in L)
    base = fcc_packing(material, r0, size=size, direction=direction, pbc=True)
    if attraction == "initial":
        mark_initial_bonds(base, rc)
    out = []
    for d in np.atleast_1d(deltas):
        a = base.copy()
        cell = a.cell.array.copy()
        cell[0, 0] /= d
        a.set_cell(cell, scale_atoms=True)
        a.calc = ClusterDynamics(rc=rc, attraction=attraction)
        out.append(-a.get_stress()[0])
    return np.array(out)
