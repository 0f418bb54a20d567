"""Virial stress of clusters (CD eq. 3) and the von Mises stress intensity (CD eq. 4).

docs/theory.md 1.4: the virial of particle a (energy units, tension positive) is

.. math::

    W^a_{ij} = -m_a (v_i - \\langle v\\rangle_i)(v_j - \\langle v\\rangle_j)
               + \\tfrac12 \\sum_b \\frac{dE}{dr_{ab}} \\frac{r_{ab,i} r_{ab,j}}{r_{ab}}

and the stress of a region is ``sum_a W^a / V_region`` with ``<v>`` the
region's mean velocity.  The potential part is the calculator's ``virials``
property (:class:`~clusterdyn.calculators.ClusterDynamics`; for another
calculator, ``stresses`` times the cell volume, ASE's convention), plus the
share of forces a dynamics adds beside the calculator (the boundary pair law's
bonds: :func:`add_piece_virials`).  The
kinetic part and the volume belong to the region, so they are added here.

Voigt order everywhere: xx, yy, zz, yz, xz, xy.  Stresses in eV/Angstrom^3
(``/ units.GPa`` for GPa).
"""

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from ..errors import InputError

#: Voigt component index -> Cartesian pair
VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
VOIGT_NAMES = ("xx", "yy", "zz", "yz", "xz", "xy")


def particle_virials(atoms, calc=None):
    """Potential part of the per-particle virial W^a, (N, 6) Voigt, eV (tension positive).

    Uses ``calc`` (default ``atoms.calc``): its ``virials`` property if it has
    one, else ``stresses`` times the cell volume (ASE's per-atom stress
    convention, which needs a 3-D cell).
    """
    calc = atoms.calc if calc is None else calc
    if calc is None:
        raise InputError("atoms.calc", None, "a calculator (e.g. ClusterDynamics) or virials given directly")
    if "virials" in getattr(calc, "implemented_properties", ()):
        return np.asarray(calc.get_property("virials", atoms))
    if atoms.cell.rank != 3:
        raise InputError("atoms.cell", atoms.cell, "a 3-D cell (per-atom stresses are per cell volume)")
    return np.asarray(calc.get_property("stresses", atoms)) * atoms.get_volume()


def add_piece_virials(virials, dyn):
    """The potential virials ``virials`` ((N, 6) eV) with the per-particle virials of the forces that
    the dynamics ``dyn`` adds through its pieces (e.g. the boundary pair law's bonds,
    :meth:`clusterdyn.md.boundary.BoundaryTerm.add_virials`: a piece with ``add_virials``).

    Returns ``virials`` itself (no copy) when ``dyn`` has no such piece, else a new array (the
    calculator's own result is not changed).  The pieces' virials are those of their last force
    pass: call it after a step (or a force evaluation) at the current positions.
    """
    pieces = [q for q in getattr(dyn, "pieces", ()) if hasattr(q, "add_virials")]
    if not pieces:
        return virials
    W = np.array(virials, dtype=float, copy=True)
    for q in pieces:
        q.add_virials(W)
    return W


def kinetic_virials(masses, velocities, mean_velocity):
    """Kinetic part ``-m (v - <v>)(v - <v>)``, (N, 6) Voigt, eV.

    ``mean_velocity`` is (3,) or (N, 3) (each particle's region mean).
    """
    dv = np.asarray(velocities, float) - np.asarray(mean_velocity, float)
    m = np.asarray(masses, float)
    return -np.stack([m * dv[:, p] * dv[:, q] for p, q in VOIGT], axis=1)


def von_mises(s):
    """Von Mises stress intensity (CD eq. 4) of Voigt stresses ``s`` (..., 6).

    .. math::

        \\sigma_u = \\sqrt{\\tfrac12[(s_{11}-s_{22})^2 + (s_{22}-s_{33})^2 + (s_{33}-s_{11})^2
                    + 6(s_{12}^2 + s_{23}^2 + s_{31}^2)]}
    """
    s = np.asarray(s, float)
    xx, yy, zz, yz, xz, xy = (s[..., k] for k in range(6))
    return np.sqrt(0.5 * ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2
                          + 6.0 * (xy ** 2 + yz ** 2 + xz ** 2)))


def pressure(s):
    """Mean pressure ``-(s_xx + s_yy + s_zz)/3`` of Voigt stresses (..., 6)."""
    s = np.asarray(s, float)
    return -(s[..., 0] + s[..., 1] + s[..., 2]) / 3.0


def _tree(atoms):
    pbc = np.asarray(atoms.pbc, bool)
    pos = atoms.get_positions()
    if not pbc.any():
        return cKDTree(pos), pos, None
    if not atoms.cell.orthorhombic:
        raise InputError("atoms.cell", atoms.cell, "an orthorhombic cell (periodic axes)")
    L = atoms.cell.lengths()
    rel = np.where(pbc, np.mod(pos, np.where(pbc, L, 1.0)), pos)
    return cKDTree(rel, boxsize=np.where(pbc, L, 0.0)), rel, L


def local_stress(atoms, radius, virials=None, centers=None):
    """Stress averaged over spheres of neighbours (CD eq. 3), virial + kinetic.

    Parameters
    ----------
    atoms : ase.Atoms
        Clusters with velocities; open or periodic orthorhombic cell.
    radius : float
        Sphere radius, Angstrom (2-3 r0 is typical).
    virials : (N, 6) array, optional
        Potential virials, eV (default :func:`particle_virials`).
    centers : (M,) int array or (M, 3) float array, optional
        Particle indices or points at the sphere centres (default: every particle).

    Returns
    -------
    (M, 6) array
        Voigt stress, eV/Angstrom^3, tension positive; the kinetic part is
        taken about each sphere's mean velocity and the volume is the sphere's
        ``4/3 pi radius^3`` (so spheres cut by a free surface read low).
    """
    W = particle_virials(atoms) if virials is None else np.asarray(virials, float)
    if W.shape != (len(atoms), 6):
        raise InputError("virials", f"array of shape {W.shape}", f"shape ({len(atoms)}, 6)")
    tree, rel, L = _tree(atoms)
    if L is not None and radius > 0.5 * L[np.asarray(atoms.pbc, bool)].min():
        raise InputError("radius", radius, f"<= half the smallest periodic length "
                         f"({0.5 * L[np.asarray(atoms.pbc, bool)].min():.6g} A): a sphere must not see "
                         "a particle's periodic image twice")
    if centers is None:
        q = rel
    else:
        c = np.asarray(centers)
        if c.ndim == 1 and np.issubdtype(c.dtype, np.integer):
            q = rel[c]
        else:
            q = np.asarray(c, float).reshape(-1, 3)
            if L is not None:
                pbc = np.asarray(atoms.pbc, bool)
                q = np.where(pbc, np.mod(q, np.where(pbc, L, 1.0)), q)
    members = tree.query_ball_point(q, radius)
    counts = np.array([len(x) for x in members])
    cols = np.concatenate([np.asarray(x, dtype=np.int64) for x in members]) if counts.sum() else \
        np.zeros(0, np.int64)
    rows = np.repeat(np.arange(len(q)), counts)
    A = csr_matrix((np.ones(len(cols)), (rows, cols)), shape=(len(q), len(atoms)))
    m = atoms.get_masses()
    v = atoms.get_velocities()
    M = A @ m
    with np.errstate(invalid="ignore", divide="ignore"):
        vbar = (A @ (m[:, None] * v)) / M[:, None]
    vbar[M == 0] = 0.0
    # sum m (v - vbar)(v - vbar) = sum m v v - M vbar vbar
    kin = np.stack([A @ (m * v[:, p] * v[:, q_]) - M * vbar[:, p] * vbar[:, q_] for p, q_ in VOIGT], axis=1)
    total = A @ W - kin
    return total / (4.0 / 3.0 * math.pi * radius ** 3)


def cell_stress(atoms, virials=None):
    """Stress of a whole periodic cell, virial + kinetic (CD eq. 3 over the cell), Voigt (6,).

    The kinetic part is taken about the cell's mean velocity and the volume
    is the cell's, so this is the mean stress a material-point test reads
    (eV/Angstrom^3, tension positive).  ``virials``: the potential part,
    (N, 6) eV (default :func:`particle_virials`).
    """
    if atoms.cell.rank != 3:
        raise InputError("atoms.cell", atoms.cell, "a 3-D cell (the stress is per cell volume)")
    W = particle_virials(atoms) if virials is None else np.asarray(virials, float)
    m = atoms.get_masses()
    v = atoms.get_velocities()
    vbar = (m[:, None] * v).sum(axis=0) / m.sum()
    return (W.sum(axis=0) + kinetic_virials(m, v, vbar).sum(axis=0)) / atoms.get_volume()
