"""Cold curves P_x(delta), eps_x(delta) of a material (docs/theory.md 1.1).

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


#: a tabulated cold curve's tail is fitted to its rows with delta >= this (the steep side of the
#: tension minimum, where the Murnaghan form applies; physics of docs/theory.md, "Cold curve")
TAIL_FIT_DELTA_MIN = 0.751
#: continuations beyond a tabulated curve's densest row
TAILS = ("murnaghan", "tait")


def fit_murnaghan(delta, pressure, delta_min=TAIL_FIT_DELTA_MIN):
    """Unweighted least-squares fit of ``P = A (delta^n - 1)`` in P to the rows with delta >= delta_min.

    For a given n the best A is linear (``A = sum P g / sum g^2``, ``g = delta^n - 1``),
    so the fit is a one-dimensional minimisation of the residual over n in (1, 30).

    Parameters
    ----------
    delta, pressure : array_like
        Rows of a cold curve (compression, pressure in any unit).
    delta_min : float, default 0.751
        Lightest row used.

    Returns
    -------
    (A, n) : A in the unit of ``pressure``.
    """
    from scipy.optimize import minimize_scalar
    d = np.asarray(delta, dtype=float)
    p = np.asarray(pressure, dtype=float)
    m = d >= delta_min
    if m.sum() < 3:
        raise InputError("delta", d.tolist(), f"at least 3 rows with delta >= {delta_min} for the tail fit")
    d, p = d[m], p[m]

    def best_a(n):
        g = d ** n - 1.0
        return float(np.dot(p, g) / np.dot(g, g))

    def resid(n):
        return float(np.sum((best_a(n) * (d ** n - 1.0) - p) ** 2))

    lo, hi = 1.0 + 1e-6, 30.0
    res = minimize_scalar(resid, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12})
    n = float(res.x)
    if not (lo + 1e-3 < n < hi - 1e-3):
        raise InputError("pressure", p.tolist(), "rows whose Murnaghan fit P = A (delta^n - 1) has 1 < n < 30")
    return best_a(n), n


class TabulatedCurve(ColdCurve):
    """Cold curve from rows (delta, eps_x, P_x), interpolated consistently.

    eps_x(delta) is a quintic Hermite interpolant that honours, at every row,
    the tabulated eps_x, its slope ``P_x/(rho0 delta^2)`` and a curvature
    from a cubic spline of P_x (so P_x and the sound speed are continuous).
    P_x is then ``rho0 delta^2 d eps/d delta``: both columns are honoured at the
    rows and the pair potential is exactly conservative.

    Beyond the densest row (delta1, P1) the curve continues with the table's
    own Murnaghan form: ``(A, n)`` from :func:`fit_murnaghan` (rows with
    delta >= ``fit_min``), and

    - ``tail="murnaghan"`` (default): ``P = P1 (delta^n - 1)/(delta1^n - 1)``,
      the fitted form scaled to meet the last row's value; P is continuous at
      delta1, its slope jumps (:attr:`tail_slopes`);
    - ``tail="tait"``: ``P = P1 + K1/n ((delta/delta1)^n - 1)`` with
      ``K1 = delta1 P'(delta1)``, matching value and slope at delta1 (same n).

    The energy continues in closed form (integral of ``P/(rho0 delta^2)``), so
    eps is continuous and the pair stays conservative.  Below the lightest row
    (tension) P continues linearly with its slope there.

    Parameters
    ----------
    delta, eps, pressure : array_like
        Rows, increasing delta; eps in eV/amu, pressure in eV/Angstrom^3.
        One row must be delta = 1 with eps = P = 0.
    rho0 : float
        Density at rest, amu/Angstrom^3.
    tail : {"murnaghan", "tait"}, default "murnaghan"
        Continuation beyond the densest row.
    fit_min : float, default 0.751
        Lightest row of the tail fit.

    Attributes
    ----------
    n_tail, A_tail : float
        Exponent and coefficient (eV/Angstrom^3) of the fitted Murnaghan form.
    tail : str
        The continuation in use.
    """

    def __init__(self, delta, eps, pressure, rho0, tail="murnaghan", fit_min=TAIL_FIT_DELTA_MIN):
        self.rho0 = check_positive("rho0", rho0)
        if tail not in TAILS:
            raise InputError("tail", tail, "one of " + ", ".join(repr(t) for t in TAILS))
        self.tail = tail
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
        # the tail beyond the densest row, from the table's own Murnaghan form
        self.A_tail, self.n_tail = fit_murnaghan(d, p, fit_min)
        self.fit_min = float(fit_min)
        d1, p1, k1 = d[-1], p[-1], d[-1] * dp[-1]
        if not (p1 > 0 and k1 > 0):
            raise InputError("pressure", p.tolist(), "a densest row in compression (P > 0, dP/d delta > 0)")
        #: the scaled Murnaghan tail's coefficient B: P = B (delta^n - 1)
        self._b_tail = p1 / (d1 ** self.n_tail - 1.0)
        self._tail = (d1, e[-1], p1, k1)
        # linear continuation in tension below the lightest row
        self._head = (d[0], e[0], p[0], dp[0])

    @property
    def tail_slopes(self):
        """dP/d delta at the densest row from the table side and from the tail side (eV/Angstrom^3)."""
        d1, _, _, k1 = self._tail
        return k1 / d1, float(self.dpressure(d1 * (1.0 + 1e-12)))

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
        n = self.n_tail
        x = d[hi]
        if self.tail == "murnaghan":
            # integral of B (delta^n - 1) / (rho0 delta^2) from d1 to x
            out[hi] = e1 + self._b_tail / self.rho0 * ((x ** (n - 1.0) - d1 ** (n - 1.0)) / (n - 1.0)
                                                       + 1.0 / x - 1.0 / d1)
        else:
            out[hi] = (e1 + (p1 - k1 / n) / self.rho0 * (1.0 / d1 - 1.0 / x)
                       + k1 / (n * self.rho0 * d1 ** n) * (x ** (n - 1.0) - d1 ** (n - 1.0)) / (n - 1.0))
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
        n = self.n_tail
        if self.tail == "murnaghan":
            out[hi] = self._b_tail * (d[hi] ** n - 1.0)
        else:
            out[hi] = p1 + k1 / n * ((d[hi] / d1) ** n - 1.0)
        d0, e0, p0, s0 = self._head
        out[lo] = p0 + s0 * (d[lo] - d0)
        return out if np.ndim(delta) else float(out[0])

    def dpressure(self, delta):
        d, lo, mid, hi = self._split(delta)
        out = np.empty_like(d)
        x = d[mid]
        out[mid] = self.rho0 * (2.0 * x * self._deps(x) + x ** 2 * self._d2eps(x))
        d1, e1, p1, k1 = self._tail
        n = self.n_tail
        if self.tail == "murnaghan":
            out[hi] = self._b_tail * n * d[hi] ** (n - 1.0)
        else:
            out[hi] = k1 / d1 * (d[hi] / d1) ** (n - 1.0)
        out[lo] = self._head[3]
        return out if np.ndim(delta) else float(out[0])

    def __repr__(self):
        return (f"TabulatedCurve({len(self.delta_rows)} rows, delta {self.delta_rows[0]:.3g}.."
                f"{self.delta_rows[-1]:.3g}, {self.tail} tail n={self.n_tail:.4g})")
