"""Structural order of a cluster lattice: how many clusters keep their 12 fcc neighbours in place.

A shock either leaves the cluster lattice a (compressed, sheared) crystal,
which has strength, or disorders it into a state that flows like a fluid.
This module measures which, cluster by cluster, against the lattice the run
started from.

For cluster i with reference neighbours j (the pairs closer than
``shell * r0`` in the reference configuration: 12 in the bulk of an fcc
packing), with reference separations ``d0_ij`` and current separations
``d_ij`` (minimum image on periodic axes), the best local affine map

.. math::

    F_i = A_i B_i^{-1},\\quad A_i = \\sum_j d_{ij} d^0_{ij}{}^T,\\quad
    B_i = \\sum_j d^0_{ij} d^0_{ij}{}^T

takes any homogeneous deformation (the shock's uniaxial compression, an
elastic shear, a rotation) out; what is left is the non-affine residual
``e_ij = |d_ij - F_i d0_ij|`` (Falk and Langer's D2min is its sum of squares).
A cluster **keeps its fcc neighbourhood** when it had 12 reference
neighbours and every one of them is still within ``tolerance * r0`` of its
affinely mapped place (default tolerance 0.25 r0, a quarter of the
neighbour distance: thermal motion in the shocked lattice stays well below
it, a neighbour that has slipped past or swapped is far beyond it).  The
*ordered fraction* of a set of clusters is the fraction that keeps it.
Clusters with fewer than 12 reference neighbours (surfaces) are not judged.

:func:`fcc_order` works on one configuration against a reference (the
positions at set-up); :class:`OrderReference` keeps the reference pairs for
repeated use during a run.
"""

import numpy as np

from ..errors import InputError, check_positive
from ..neighbors import NeighborList

__all__ = ["OrderReference", "fcc_order", "TOLERANCE", "SHELL"]

#: a neighbour further than this from its affinely mapped place (in r0) breaks the order
TOLERANCE = 0.25
#: reference neighbours: pairs closer than SHELL * r0 at set-up (the first fcc shell at r0, the second at 1.414 r0)
SHELL = 1.2


def _r0_of(atoms, r0):
    if r0 is not None:
        return check_positive("r0", r0)
    if "cd_r0" in atoms.info:
        r = np.atleast_1d(atoms.info["cd_r0"]).astype(float)
        if len(r) != 1:
            raise InputError("r0", None, "a cluster size (the Atoms hold several materials; give r0)")
        return float(r[0])
    raise InputError("r0", None, "a cluster size, Angstrom (the Atoms carry no info['cd_r0'])")


def _min_image(d, cell, pbc):
    L = np.diag(np.asarray(cell, float))
    for k in range(3):
        if pbc[k]:
            d[:, k] -= L[k] * np.round(d[:, k] / L[k])
    return d


class OrderReference:
    """The reference neighbour pairs of a lattice (its set-up configuration).

    Parameters
    ----------
    atoms : ase.Atoms
        The reference configuration (open or periodic orthorhombic cell).
    r0 : float, optional
        Cluster size, Angstrom (default ``atoms.info['cd_r0']``).
    shell : float
        Reference neighbours: pairs closer than ``shell * r0`` (default 1.2).

    Attributes
    ----------
    i_p, j_p : (P,) int64
        Reference pairs (rows of the Atoms), each once.
    d0_pc : (P, 3) float64, Angstrom
        Their reference separations ``x_j - x_i``.
    count_n : (N,) int64
        Reference neighbours per cluster.
    """

    def __init__(self, atoms, r0=None, shell=SHELL):
        self.r0 = _r0_of(atoms, r0)
        self.shell = check_positive("shell", shell)
        nl = NeighborList(self.shell * self.r0)
        pos = np.ascontiguousarray(atoms.positions, dtype=float)
        nl.build(pos, atoms.cell.array, atoms.pbc)
        i_p, j_p, d, _ = nl.pairs(pos)
        self.i_p = np.ascontiguousarray(i_p, dtype=np.int64)
        self.j_p = np.ascontiguousarray(j_p, dtype=np.int64)
        self.d0_pc = np.ascontiguousarray(d, dtype=float)
        self.n = len(atoms)
        self.count_n = (np.bincount(self.i_p, minlength=self.n) + np.bincount(self.j_p, minlength=self.n))

    def measure(self, atoms, tolerance=TOLERANCE):
        """Per-cluster residuals and order flags of ``atoms`` (same rows as the reference).

        Returns
        -------
        dict
            ``judged`` (N,) bool: clusters with 12 reference neighbours;
            ``ordered`` (N,) bool: judged and every neighbour within
            ``tolerance * r0`` of its affine place; ``max_residual`` (N,)
            float: the largest ``e_ij / r0`` (NaN where not judged);
            ``rms_residual`` (N,) float: ``sqrt(D2min / 12) / r0``;
            ``tolerance`` (the value used, in r0).
        """
        if len(atoms) != self.n:
            raise InputError("atoms", f"{len(atoms)} particles", f"the reference's {self.n} particles (same rows)")
        tol = check_positive("tolerance", tolerance)
        pos = np.asarray(atoms.positions, dtype=float)
        d = _min_image(pos[self.j_p] - pos[self.i_p], atoms.cell.array, atoms.pbc)
        d0 = self.d0_pc
        n = self.n
        # both directions of a pair give the same outer products (d_ji = -d_ij)
        dd0 = d[:, :, None] * d0[:, None, :]
        d0d0 = d0[:, :, None] * d0[:, None, :]
        A = np.zeros((n, 3, 3))
        B = np.zeros((n, 3, 3))
        for idx in (self.i_p, self.j_p):
            for a in range(3):
                for b in range(3):
                    A[:, a, b] += np.bincount(idx, weights=dd0[:, a, b], minlength=n)
                    B[:, a, b] += np.bincount(idx, weights=d0d0[:, a, b], minlength=n)
        judged = self.count_n == 12
        F = np.zeros((n, 3, 3))
        F[judged] = A[judged] @ np.linalg.inv(B[judged])
        # residual of each pair as seen from either end
        e_i = np.linalg.norm(d - np.einsum("pab,pb->pa", F[self.i_p], d0), axis=1)
        e_j = np.linalg.norm(-d + np.einsum("pab,pb->pa", F[self.j_p], d0), axis=1)
        emax = np.zeros(n)
        np.maximum.at(emax, self.i_p, e_i)
        np.maximum.at(emax, self.j_p, e_j)
        e2 = np.bincount(self.i_p, weights=e_i ** 2, minlength=n) + np.bincount(self.j_p, weights=e_j ** 2,
                                                                                 minlength=n)
        emax = emax / self.r0
        rms = np.sqrt(e2 / np.maximum(self.count_n, 1)) / self.r0
        emax[~judged] = np.nan
        rms[~judged] = np.nan
        ordered = judged & (emax < tol)
        return {"judged": judged, "ordered": ordered, "max_residual": emax, "rms_residual": rms,
                "tolerance": tol}

    def fraction(self, atoms, mask=None, tolerance=TOLERANCE):
        """Ordered fraction of the judged clusters in ``mask`` (all if None); NaN if none is judged."""
        m = self.measure(atoms, tolerance)
        sel = m["judged"] if mask is None else (m["judged"] & np.asarray(mask, bool))
        k = int(sel.sum())
        return float(m["ordered"][sel].sum() / k) if k else float("nan")


def fcc_order(atoms, reference, *, r0=None, mask=None, tolerance=TOLERANCE, shell=SHELL):
    """Ordered fraction of ``atoms`` against ``reference`` (module docstring).

    Parameters
    ----------
    atoms : ase.Atoms
        Current configuration.
    reference : ase.Atoms or OrderReference
        Set-up configuration with the same rows (e.g. ``atoms.copy()`` taken
        before the run).
    r0 : float, optional
        Cluster size, Angstrom (default ``info['cd_r0']``).
    mask : (N,) bool, optional
        Clusters to judge (e.g. those behind a shock front); default all.
    tolerance : float
        Largest affine residual of a neighbour that keeps the order, in r0 (default 0.25).
    shell : float
        Reference neighbour shell in r0 (default 1.2).

    Returns
    -------
    dict
        ``fraction`` (ordered / judged in the mask), ``n_judged``, and the
        per-cluster arrays of :meth:`OrderReference.measure`.
    """
    ref = reference if isinstance(reference, OrderReference) else OrderReference(reference, r0=r0, shell=shell)
    m = ref.measure(atoms, tolerance)
    sel = m["judged"] if mask is None else (m["judged"] & np.asarray(mask, bool))
    k = int(sel.sum())
    m["fraction"] = float(m["ordered"][sel].sum() / k) if k else float("nan")
    m["n_judged"] = k
    return m
