"""Cold curves P_x(delta), eps_x(delta) of a material (physics.md 1.1).

``delta = rho/rho0`` is the compression.  Both curves satisfy
``d eps_x / d delta = P_x / (rho0 delta^2)`` exactly, with ``eps_x(1) = 0``,
so the cluster pair potential derived from them is exactly conservative.

All quantities are in ASE units: density amu/Angstrom^3, pressure
eV/Angstrom^3, specific energy eV/amu, speed Angstrom/(ASE time).
"""

import math

import numpy as np
from scipy.interpolate import BPoly, CubicSpline

from ..errors import InputError, check_positive


class ColdCurve:
    """Base class: a cold curve with density ``rho0``.

    Subclasses implement :meth:`pressure`, :meth:`energy` and :meth:`dpressure`
    (all vectorised over ``delta``).
    """

    rho0 = None

    def pressure(self, delta):
        raise NotImplementedError

    def energy(self, delta):
        raise NotImplementedError

    def dpressure(self, delta):
        """dP_x/d delta (the bulk modulus is ``delta * dP/d delta``)."""
        raise NotImplementedError

    @property
    def K0(self):
        """Bulk modulus at rest, ``dP_x/d delta`` at delta = 1 (eV/Angstrom^3)."""
        return float(self.dpressure(1.0))

    @property
    def c0(self):
        """Bulk sound speed at rest, ``sqrt(K0/rho0)`` (Angstrom / ASE time)."""
        return math.sqrt(self.K0 / self.rho0)

    def sound_speed(self, delta):
        """Bulk sound speed at compression delta, ``sqrt(dP/d rho)``."""
        return np.sqrt(np.asarray(self.dpressure(delta)) / self.rho0)


class MurnaghanCurve(ColdCurve):
    """Tait/Murnaghan cold curve ``P = rho0 c0^2 / n (delta^n - 1)``.

    The CD paper calls it the Mie-Grueneisen form.  Closed-form energy
    ``eps = c0^2/n [ (delta^(n-1) - 1)/(n-1) + 1/delta - 1 ]`` (n != 1; for
    n = 1 the first term is ``ln(delta)``).

    Parameters
    ----------
    rho0 : float
        Density at rest, amu/Angstrom^3 (e.g. ``11.34 * units.g_cm3``).
    c0 : float
        Bulk sound speed at rest, Angstrom/ASE-time (e.g. ``1.972 * units.km_s``).
    n : float
        Exponent (> 0).
    """

    def __init__(self, rho0, c0, n):
        self.rho0 = check_positive("rho0", rho0)
        self._c0 = check_positive("c0", c0)
        self.n = check_positive("n", n)

    def pressure(self, delta):
        d = np.asarray(delta, dtype=float)
        return self.rho0 * self._c0 ** 2 / self.n * (d ** self.n - 1.0)

    def energy(self, delta):
        d = np.asarray(delta, dtype=float)
        n = self.n
        if abs(n - 1.0) < 1e-12:
            first = np.log(d)
        else:
            first = (d ** (n - 1.0) - 1.0) / (n - 1.0)
        return self._c0 ** 2 / n * (first + 1.0 / d - 1.0)

    def dpressure(self, delta):
        d = np.asarray(delta, dtype=float)
        return self.rho0 * self._c0 ** 2 * d ** (self.n - 1.0)

    @property
    def c0(self):
        return self._c0

    def __repr__(self):
        return f"MurnaghanCurve(rho0={self.rho0:.6g}, c0={self._c0:.6g}, n={self.n:g})"


class TabulatedCurve(ColdCurve):
    """Cold curve from rows (delta, eps_x, P_x), interpolated consistently.

    eps_x(delta) is a quintic Hermite interpolant that honours, at every row,
    the tabulated eps_x, its slope ``P_x/(rho0 delta^2)`` and a curvature
    from a cubic spline of P_x (so P_x and the sound speed are continuous).
    P_x is then ``rho0 delta^2 d eps/d delta``: both columns are honoured at the
    rows and the pair potential is exactly conservative.

    Beyond the densest row the curve continues with a Tait tail
    ``P = P1 + K1/n1 ((delta/delta1)^n1 - 1)`` matching value and slope
    (``K1 = delta1 P'(delta1)``), with ``n1 = 1 + P''(delta1) delta1^2 / K1``
    from the curvature of the last three rows, clipped to [2, 8]
    (:attr:`n_tail`).  Below the lightest row (tension) P continues linearly
    with its slope there.

    Parameters
    ----------
    delta, eps, pressure : array_like
        Rows, increasing delta; eps in eV/amu, pressure in eV/Angstrom^3.
        One row must be delta = 1 with eps = P = 0.
    rho0 : float
        Density at rest, amu/Angstrom^3.
    """

    def __init__(self, delta, eps, pressure, rho0):
        self.rho0 = check_positive("rho0", rho0)
        d = np.asarray(delta, dtype=float)
        e = np.asarray(eps, dtype=float)
        p = np.asarray(pressure, dtype=float)
        order = np.argsort(d)
        d, e, p = d[order], e[order], p[order]
        if len(d) < 4:
            raise InputError("delta", f"{len(d)} rows", "at least 4 rows")
        if np.any(np.diff(d) <= 0):
            raise InputError("delta", d.tolist(), "distinct values")
        i1 = np.argmin(abs(d - 1.0))
        if abs(d[i1] - 1.0) > 1e-9 or abs(e[i1]) > 1e-12 * max(1.0, abs(e).max()) or p[i1] != 0.0:
            raise InputError("rows", "(delta=1 row)", "a row with delta = 1, eps = 0, P = 0")
        self.delta_rows, self.eps_rows, self.p_rows = d, e, p
        spline = CubicSpline(d, p)
        dp = spline(d, 1)
        slope = p / (self.rho0 * d ** 2)
        curv = dp / (self.rho0 * d ** 2) - 2.0 * p / (self.rho0 * d ** 3)
        self._eps = BPoly.from_derivatives(d, np.column_stack([e, slope, curv]))
        self._deps = self._eps.derivative()
        self._d2eps = self._deps.derivative()
        # Tait tail beyond the densest row
        d1, p1, k1 = d[-1], p[-1], d[-1] * dp[-1]
        # curvature from the last three rows (second divided difference)
        x0, xa, xb = d[-3], d[-2], d[-1]
        y0, ya, yb = p[-3], p[-2], p[-1]
        p2 = 2.0 * (y0 / ((x0 - xa) * (x0 - xb)) + ya / ((xa - x0) * (xa - xb))
                    + yb / ((xb - x0) * (xb - xa)))
        self.n_tail = float(np.clip(1.0 + p2 * d1 ** 2 / k1, 2.0, 8.0))
        self._tail = (d1, e[-1], p1, k1)
        # linear continuation in tension below the lightest row
        self._head = (d[0], e[0], p[0], dp[0])

    def _split(self, delta):
        d = np.atleast_1d(np.asarray(delta, dtype=float))
        if np.any(~np.isfinite(d)) or np.any(d <= 0):
            raise InputError("delta", d[(~np.isfinite(d)) | (d <= 0)][:3].tolist(), "finite values > 0")
        lo = d < self._head[0]
        hi = d > self._tail[0]
        mid = ~(lo | hi)
        return d, lo, mid, hi

    def energy(self, delta):
        d, lo, mid, hi = self._split(delta)
        out = np.empty_like(d)
        out[mid] = self._eps(d[mid])
        d1, e1, p1, k1 = self._tail
        n1 = self.n_tail
        x = d[hi]
        out[hi] = (e1 + (p1 - k1 / n1) / self.rho0 * (1.0 / d1 - 1.0 / x)
                   + k1 / (n1 * self.rho0 * d1 ** n1) * (x ** (n1 - 1.0) - d1 ** (n1 - 1.0)) / (n1 - 1.0))
        d0, e0, p0, s0 = self._head
        x = d[lo]
        a = p0 - s0 * d0
        out[lo] = e0 + (a * (1.0 / d0 - 1.0 / x) + s0 * np.log(x / d0)) / self.rho0
        return out if np.ndim(delta) else float(out[0])

    def pressure(self, delta):
        d, lo, mid, hi = self._split(delta)
        out = np.empty_like(d)
        out[mid] = self.rho0 * d[mid] ** 2 * self._deps(d[mid])
        d1, e1, p1, k1 = self._tail
        out[hi] = p1 + k1 / self.n_tail * ((d[hi] / d1) ** self.n_tail - 1.0)
        d0, e0, p0, s0 = self._head
        out[lo] = p0 + s0 * (d[lo] - d0)
        return out if np.ndim(delta) else float(out[0])

    def dpressure(self, delta):
        d, lo, mid, hi = self._split(delta)
        out = np.empty_like(d)
        x = d[mid]
        out[mid] = self.rho0 * (2.0 * x * self._deps(x) + x ** 2 * self._d2eps(x))
        d1, e1, p1, k1 = self._tail
        out[hi] = k1 / d1 * (d[hi] / d1) ** (self.n_tail - 1.0)
        out[lo] = self._head[3]
        return out if np.ndim(delta) else float(out[0])

    def __repr__(self):
        return (f"TabulatedCurve({len(self.delta_rows)} rows, delta {self.delta_rows[0]:.3g}.."
                f"{self.delta_rows[-1]:.3g}, Tait tail n1={self.n_tail:.3g})")
