"""Dusting: small fragments that have left a free surface, and cluster counts per layer.

After a plane shock reaches a smooth free surface, a Cluster Dynamics lattice
may shed single clusters and small fragments (the CD paper's "numerical
dusting", docs/theory.md 1.3 and 1.8).  Here a fragment (a connected
component of the bond graph, :mod:`clusterdyn.analysis.fragments`) is

* the *main body* when it is the largest fragment,
* *small* when it has at most ``g_max`` clusters (default 10),
* *dispersed* when it is small and its centre of mass lies beyond the main
  body's free surface -- its outermost cluster along ``axis`` on the side
  ``side`` -- by more than ``gap`` (default ``b r0``, the bond distance: a
  fragment that far out has no bond to the surface).

Small fragments elsewhere (inside a spall gap, at a driven face) are not
counted; fragments of more than ``g_max`` clusters beyond the surface are
counted apart (``n_large``, ``large_clusters``).  Counts are given per unit
area of the cross-section normal to ``axis`` (the cell's, for a sample
periodic across) and as a mass fraction.

Entry points: :func:`dispersed` (one configuration) and :func:`layer_counts`
(clusters per layer along the axis, the CD paper's fig. 20).
"""

from dataclasses import dataclass

import numpy as np

from .. import units
from ..errors import InputError
from .fragment_spectra import G_MAX
from .fragments import fragments

__all__ = ["Dispersed", "dispersed", "layer_counts", "cross_section"]


@dataclass
class Dispersed:
    """The dispersed fragments of one configuration (ASE units).

    Attributes
    ----------
    fragments : Fragments
        All fragments of the configuration.
    mask : (F,) bool
        Which fragments are dispersed.
    surface : float, Angstrom
        Position of the main body's free surface along the axis (its outermost cluster).
    n_fragments : int
        Dispersed fragments.
    n_clusters : int
        Clusters in them.
    mass : float, amu
        Their mass.
    mass_fraction : float
        Their mass over the mass of every fragment (excluded particles left out).
    area : float, Angstrom^2
        Cross-section the counts are divided by.
    g_max : int
    gap : float, Angstrom
    n_large : int
        Fragments of more than ``g_max`` clusters beyond the surface (other than the main body).
    large_clusters : int
        Clusters in them.
    """

    fragments: object
    mask: np.ndarray
    surface: float
    n_fragments: int
    n_clusters: int
    mass: float
    mass_fraction: float
    area: float
    g_max: int
    gap: float
    n_large: int = 0
    large_clusters: int = 0

    @property
    def per_mm2(self):
        """Dispersed clusters per mm^2 of cross-section."""
        return self.n_clusters / (self.area / units.mm ** 2)

    @property
    def fragments_per_mm2(self):
        """Dispersed fragments per mm^2 of cross-section."""
        return self.n_fragments / (self.area / units.mm ** 2)

    def spectrum(self):
        """N(g) of the dispersed fragments: ``(g, N)`` for g = 1 ... g_max."""
        g = np.arange(1, self.g_max + 1)
        n = np.bincount(self.fragments.g[self.mask], minlength=self.g_max + 1)[1:self.g_max + 1]
        return g, n


def cross_section(atoms, axis=0, area=None):
    """Area normal to ``axis`` (Angstrom^2): ``area`` if given, else the cell's (both other axes
    periodic), else :class:`~clusterdyn.errors.InputError`."""
    if area is not None:
        if not area > 0:
            raise InputError("area", area, "a positive area, Angstrom^2")
        return float(area)
    others = [d for d in range(3) if d != axis]
    if not all(atoms.pbc[d] for d in others):
        raise InputError("area", None, "the cross-section's area (the sample is not periodic across "
                         f"axis {'xyz'[axis]}, so the cell's is not the sample's)")
    cell = atoms.cell.array
    return float(np.linalg.norm(np.cross(cell[others[0]], cell[others[1]])))


def dispersed(atoms, frags=None, *, axis=0, side=1, g_max=G_MAX, b=None, gap=None, exclude=None, area=None):
    """Small fragments beyond the body's free surface (module docstring).

    Parameters
    ----------
    atoms : ase.Atoms
        A Cluster Dynamics configuration (``atoms.info['cd_r0']`` or a calculator gives r0).
    frags : Fragments, optional
        The configuration's fragments if already found (must match ``exclude``).
    axis : int, default 0
        Direction normal to the free surface.
    side : +1 or -1, default +1
        The free surface is the body's outermost extent toward ``+axis`` (+1) or ``-axis`` (-1).
    g_max : int, default 10
        Largest fragment counted as small.
    b : float, optional
        Bond distance in r0 for the fragments (default the calculator's rc).
    gap : float, optional
        Distance beyond the surface (Angstrom) past which a small fragment's centre of mass
        counts; default ``b r0``.
    exclude : (N,) bool array, optional
        Particles left out (a piston layer).
    area : float, optional
        Cross-section, Angstrom^2 (default: the cell's, see :func:`cross_section`).

    Returns
    -------
    Dispersed
    """
    if side not in (1, -1):
        raise InputError("side", side, "+1 or -1")
    if int(g_max) != g_max or g_max < 1:
        raise InputError("g_max", g_max, "a positive integer")
    if axis not in (0, 1, 2):
        raise InputError("axis", axis, "0, 1 or 2")
    A = cross_section(atoms, axis, area)
    f = frags if frags is not None else fragments(atoms, b, exclude=exclude)
    if gap is None:
        r0 = atoms.info.get("cd_r0")
        r0 = float(min(r0)) if r0 else float(atoms.calc.potentials[0].r0)
        gap = (f.b if f.b is not None else b) * r0
    if f.n_fragments == 0:
        raise InputError("atoms", "no particles", "a configuration with a body")
    small = f.g <= g_max
    body = f.largest
    x = atoms.positions[f.labels == body, axis]
    surface = float((side * x).max() * side)
    beyond = side * (f.com[:, axis] - surface) > gap
    mask = small & beyond
    large = beyond & ~small
    large[body] = False
    mass_all = float(f.mass.sum())
    m = float(f.mass[mask].sum())
    return Dispersed(f, mask, surface, int(mask.sum()), int(f.g[mask].sum()), m,
                     m / mass_all if mass_all > 0 else 0.0, A, int(g_max), float(gap), int(large.sum()),
                     int(f.g[large].sum()))


def layer_counts(atoms, width, *, axis=0, lo=None, hi=None, exclude=None):
    """Number of particles per layer of ``width`` along ``axis`` (the CD paper's fig. 20).

    Parameters
    ----------
    atoms : ase.Atoms
    width : float, Angstrom
        Layer thickness (e.g. the lattice's plane spacing, ``r0/sqrt 2`` along [100]).
    lo, hi : float, optional
        Range covered (default the particles' extent).
    exclude : (N,) bool array, optional
        Particles left out.

    Returns
    -------
    (centres, counts) : (L,) float64 Angstrom, (L,) int64
    """
    if not width > 0:
        raise InputError("width", width, "a positive layer thickness, Angstrom")
    x = atoms.positions[:, axis]
    if exclude is not None:
        x = x[~np.asarray(exclude, bool)]
    lo = float(x.min()) if lo is None else float(lo)
    hi = float(x.max()) if hi is None else float(hi)
    n = max(1, int(np.ceil((hi - lo) / width + 1e-9)))
    edges = lo + width * np.arange(n + 1)
    k = np.floor((x - lo) / width).astype(np.int64)
    k = k[(k >= 0) & (k < n)]
    return 0.5 * (edges[1:] + edges[:-1]), np.bincount(k, minlength=n)
