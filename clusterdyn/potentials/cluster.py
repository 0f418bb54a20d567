"""Cluster pair potentials from a cold curve (CD eq. 1-2, docs/theory.md 1.2).

For clusters of equilibrium distance ``r0`` in fcc close packing (12
neighbours, volume ``r0^3/sqrt(2)`` each, mass ``M = rho0 r0^3/sqrt(2)``) and
``delta(r) = (r0/r)^3``:

.. math::

    E(r) = \\frac{\\sqrt2 \\rho_0 r_0^3}{12} \\varepsilon_x(\\delta(r)), \\qquad
    f(r) = \\frac{\\sqrt2}{4} r^2 P_x(\\delta(r))  \\quad (f>0: \\text{repulsive})

so ``f = -dE/dr`` exactly.  Unlike pairs are two half-bonds in series
(:class:`MixedPairPotential`).  :class:`PairTable` turns any of them into the
cubic-Hermite table the numba kernels evaluate.
"""

import math

import numpy as np

from ..errors import InputError, check_positive
from ..materials import get_material

SQRT2 = math.sqrt(2.0)
#: smallest tabulated distance, as a fraction of r0 (closer is an instability).  Hot shocked
#: lattices push pairs well inside the densest cold-curve row (0.75 r0 for aluminium): at
#: 6 km/s thermal collisions reach 0.45 r0, at 20 km/s 0.30 r0 (aluminium, default sample), so
#: the table runs down to compression delta = 125.
R_MIN_FACTOR = 0.2
#: bins of a pair table, uniform in r^2 over [(R_MIN_FACTOR r0)^2, (rc r0)^2]; 10407 keeps the bin
#: width of the former 10000 bins from 0.3 r0 (at rc = 1.15: 2617 bins between r0 and rc, a bin
#: spans 2.5e-4 r0 at r0, 1.2e-3 r0 at 0.2 r0), so the interpolation error at r0 is unchanged
N_BINS = 10407
#: default cutoff, as a multiple of r0
DEFAULT_RC = 1.15


def check_rc(rc):
    """Validate a cutoff given as a multiple of r0: (1, sqrt 2)."""
    try:
        v = float(rc)
    except (TypeError, ValueError):
        raise InputError("rc", rc, "a number in (1, sqrt(2)) (multiple of r0)") from None
    if not (1.0 < v < SQRT2):
        raise InputError("rc", rc, "a multiple of r0 in (1, sqrt(2)) = (1, 1.41421); the method uses 1.1-1.2",
                         hint="only nearest neighbours of the fcc lattice may interact")
    return v


class ClusterPotential:
    """Pair potential of clusters of one material (CD eq. 1-2).

    Parameters
    ----------
    material : Material or str
        Material with a cold curve (``get_material("Al")`` or its name).
    r0 : float
        Cluster size = equilibrium distance, Angstrom (``5 * units.um``).
    rc : float, default 1.15
        Cutoff as a multiple of r0, in (1, sqrt 2).

    Attributes
    ----------
    mass : float
        Cluster mass ``rho0 r0^3/sqrt(2)``, amu.
    cutoff : float
        ``rc * r0``, Angstrom.
    r_min : float
        Smallest tabulated distance ``R_MIN_FACTOR r0`` (0.2 r0).
    """

    def __init__(self, material, r0, rc=DEFAULT_RC):
        self.material = get_material(material)
        if self.material.curve is None:
            raise InputError("material", self.material.name, "a material with a cold curve (CD)")
        self.r0 = check_positive("r0", r0)
        self.rc = check_rc(rc)
        self.cutoff = self.rc * self.r0
        self.r_min = R_MIN_FACTOR * self.r0
        self.mass = self.material.rho0 * self.r0 ** 3 / SQRT2
        self.curve = self.material.curve

    # raw eq. (1)-(2) -------------------------------------------------
    def energy(self, r):
        """Raw pair energy E(r), eV (no cutoff, no shift)."""
        r = np.asarray(r, dtype=float)
        return SQRT2 * self.material.rho0 * self.r0 ** 3 / 12.0 * self.curve.energy((self.r0 / r) ** 3)

    def force(self, r):
        """Raw pair force f(r) = -dE/dr, eV/Angstrom, positive = repulsive."""
        r = np.asarray(r, dtype=float)
        return SQRT2 / 4.0 * r ** 2 * self.curve.pressure((self.r0 / r) ** 3)

    def stiffness(self, r=None):
        """Bond stiffness ``k = -df/dr`` at r (default r0), eV/Angstrom^2."""
        r = self.r0 if r is None else np.asarray(r, dtype=float)
        delta = (self.r0 / r) ** 3
        # f = sqrt2/4 r^2 P(delta);  df/dr = sqrt2/4 [2 r P - 3 r0^3 / r^2 P'(delta)]
        return -(SQRT2 / 4.0) * (2.0 * r * self.curve.pressure(delta)
                                 - 3.0 * self.r0 ** 3 / r ** 2 * self.curve.dpressure(delta))

    @property
    def c0(self):
        return self.curve.c0

    @property
    def gamma_base(self):
        """c0/r0: the damping rate for J = 1 (Gamma = c0/(J r0))."""
        return self.curve.c0 / self.r0

    def __repr__(self):
        return f"ClusterPotential({self.material.name}, r0={self.r0:.6g} A, rc={self.rc:g})"


class MixedPairPotential:
    """Bond between clusters of two materials: two half-bonds in series (docs/theory.md 1.2).

    ``r0_AB = (r0_A + r0_B)/2``; for a bond of length r the halves ``x_A + x_B = r``
    satisfy ``f_A(2 x_A) = f_B(2 x_B)`` (same force); then
    ``E_AB = [E_A(2 x_A) + E_B(2 x_B)]/2`` and ``f_AB = -dE_AB/dr`` exactly.
    Cutoff ``rc * r0_AB`` with the common ``rc`` of A and B.
    """

    def __init__(self, pa, pb):
        if abs(pa.rc - pb.rc) > 1e-12:
            raise InputError("rc", (pa.rc, pb.rc), "the same rc for both materials of a mixed pair")
        self.pa, self.pb = pa, pb
        self.r0 = 0.5 * (pa.r0 + pb.r0)
        self.rc = pa.rc
        self.cutoff = self.rc * self.r0
        self.r_min = R_MIN_FACTOR * self.r0

    def split(self, r):
        """Half lengths (x_A, x_B) with f_A(2 x_A) = f_B(2 x_B), x_A + x_B = r."""
        r = np.atleast_1d(np.asarray(r, dtype=float))
        lo = np.full_like(r, 1e-3) * r
        hi = r * (1.0 - 1e-3)
        # g(x) = f_A(2x) - f_B(2(r-x)) decreases monotonically in x
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            g = self.pa.force(2.0 * mid) - self.pb.force(2.0 * (r - mid))
            pos = g > 0
            lo = np.where(pos, mid, lo)
            hi = np.where(pos, hi, mid)
            if np.all(hi - lo <= 1e-15 * r):
                break
        xa = 0.5 * (lo + hi)
        return xa, r - xa

    def energy(self, r):
        xa, xb = self.split(r)
        out = 0.5 * (self.pa.energy(2.0 * xa) + self.pb.energy(2.0 * xb))
        return out if np.ndim(r) else float(out[0])

    def force(self, r):
        xa, xb = self.split(r)
        out = 0.5 * (self.pa.force(2.0 * xa) + self.pb.force(2.0 * xb))
        return out if np.ndim(r) else float(out[0])

    def __repr__(self):
        return f"MixedPairPotential({self.pa!r}, {self.pb!r})"


class PairTable:
    """Cubic-Hermite table of a pair law in ``s = r^2`` on ``[r_min^2, cutoff^2]`` for the kernels.

    Node values are E(r) - E(cutoff) (the energy shift, so total energy is
    continuous when a pair crosses the cutoff) and slopes ``dE/ds = -f/(2r)``;
    within a bin ``E = c0 + c1 t + c2 t^2 + c3 t^3`` with ``t = (s - s_k)/h_s``.
    The kernel's force is exactly ``-dE/dr = -2 r dE/ds`` of that cubic: the
    force on a pair is ``-2 (dE/ds) d`` along the separation ``d``, so the
    kernels need neither a square root nor a division per pair.  ``r0^2`` is
    a node (the force at rest is zero to round-off).
    """

    def __init__(self, law, n_bins=N_BINS):
        self.law = law
        self.cutoff = law.cutoff
        self.n_bins = int(n_bins)
        # r0^2 is a node; the grid reaches down to about (R_MIN_FACTOR r0)^2 with the
        # same bin count for every pair type
        s_c = law.cutoff ** 2
        s_0 = law.r0 ** 2
        s_lo = (R_MIN_FACTOR * law.r0) ** 2
        n_hi = max(1, int(round(self.n_bins * (s_c - s_0) / (s_c - s_lo))))
        n_lo = self.n_bins - n_hi
        self.hs = (s_c - s_0) / n_hi
        self.s_min = s_0 - n_lo * self.hs
        self.r_min = math.sqrt(self.s_min)
        sn = self.s_min + self.hs * np.arange(self.n_bins + 1)
        sn[-1] = s_c
        r = np.sqrt(sn)
        e = law.energy(r)
        f = law.force(r)
        self.e_shift = float(e[-1])
        self.f_cut = float(f[-1])
        e = e - self.e_shift
        d = -f / (2.0 * r) * self.hs          # dE/dt at nodes
        c = np.empty((self.n_bins, 4))
        c[:, 0] = e[:-1]
        c[:, 1] = d[:-1]
        c[:, 2] = 3.0 * (e[1:] - e[:-1]) - 2.0 * d[:-1] - d[1:]
        c[:, 3] = 2.0 * (e[:-1] - e[1:]) + d[:-1] + d[1:]
        self.coef = c

    def evaluate(self, r):
        """(E_shifted, f) from the table, for tests. r in [r_min, cutoff)."""
        r = np.asarray(r, dtype=float)
        x = (r * r - self.s_min) / self.hs
        k = np.clip(x.astype(int), 0, self.n_bins - 1)
        t = x - k
        c = self.coef[k]
        e = c[..., 0] + t * (c[..., 1] + t * (c[..., 2] + t * c[..., 3]))
        de = c[..., 1] + t * (2.0 * c[..., 2] + 3.0 * t * c[..., 3])
        return e, -2.0 * r * de / self.hs


def build_tables(potentials, n_bins=N_BINS):
    """Tables for every pair of materials.

    Parameters
    ----------
    potentials : sequence of ClusterPotential
        Index = material id.

    Returns
    -------
    coef_ttbk : (nt, nt, n_bins, 4) float64
    meta_ttm : (nt, nt, 7) float64
        r_min^2 (the table's first node in s = r^2), 1/h_s, cutoff^2, r_min^2, 1/r0_ab^2,
        E(cutoff) (the shift), r0_ab^2 per pair type.
    tables : nested list of PairTable
    """
    nt = len(potentials)
    tables = [[None] * nt for _ in range(nt)]
    for a in range(nt):
        for b in range(a, nt):
            law = potentials[a] if a == b else MixedPairPotential(potentials[a], potentials[b])
            tables[a][b] = tables[b][a] = PairTable(law, n_bins)
    coef = np.empty((nt, nt, n_bins, 4))
    meta = np.empty((nt, nt, 7))
    for a in range(nt):
        for b in range(nt):
            t = tables[a][b]
            coef[a, b] = t.coef
            meta[a, b] = (t.s_min, 1.0 / t.hs, t.cutoff ** 2, t.s_min, 1.0 / t.law.r0 ** 2, t.e_shift,
                          t.law.r0 ** 2)
    return coef, meta, tables
