"""Histories of a prescribed quantity in time: the U(t) laws of pistons and tractions.

A history gives ``at(t)``, the exact ``mean(t0, t1)`` over a step (what a
layer drifts with), ``max_abs()`` and a storable ``get_state()``
(:func:`history_from_state` rebuilds it): :class:`Constant`, a
piecewise-linear :class:`Table` (also read from a CSV file), a
:class:`SmoothRamp` and a Python callable (:class:`Function`, not storable).
:func:`describe_history` gives one in display units for H5MD metadata.
Times are ASE time; values are what the drive prescribes (a velocity in
Angstrom/ASE-time or a stress in eV/Angstrom^3).
"""

import csv
import math
import os

import numpy as np

from .. import units
from ..errors import InputError

__all__ = ["Constant", "Table", "SmoothRamp", "Function", "as_history", "history_from_state",
           "describe_history"]


def _value(v, what):
    a = np.array(v, dtype=float)
    if a.shape not in ((), (3,)) or not np.all(np.isfinite(a)):
        raise InputError(what, v, "a finite number or 3-vector")
    return a


class Constant:
    """A history that does not change: ``at(t) = value`` (a number or a 3-vector)."""

    law = "constant"

    def __init__(self, value):
        self.value = _value(value, "value")

    def at(self, t):
        return self.value

    def mean(self, t0, t1):
        return self.value

    def max_abs(self):
        return float(np.linalg.norm(self.value))

    def get_state(self):
        return {"law": "constant", "value": self.value.copy()}

    def __repr__(self):
        return f"Constant({self.value.tolist()})"


class Table:
    """A piecewise-linear history through points ``(times[k], values[k])``.

    Held at the first value before ``times[0]`` and at the last value after
    ``times[-1]``.

    Parameters
    ----------
    times : (K,) array, ASE time
        Strictly increasing.
    values : (K,) or (K, 3) array
        Values at those times (ASE units: Angstrom/ASE-time for a velocity,
        eV/Angstrom^3 for a stress).
    """

    law = "table"

    def __init__(self, times, values):
        t = np.array(times, dtype=float)
        if t.ndim != 1 or t.size < 1 or not np.all(np.isfinite(t)):
            raise InputError("times", times, "a 1-D array of finite times (at least one)")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            k = int(np.argmin(np.diff(t)))
            raise InputError("times", t.tolist() if t.size <= 8 else f"array with times[{k + 1}] <= times[{k}]",
                             "strictly increasing times")
        v = np.array(values, dtype=float)
        if v.shape not in ((t.size,), (t.size, 3)) or not np.all(np.isfinite(v)):
            raise InputError("values", f"array of shape {v.shape}",
                             f"finite values of shape ({t.size},) or ({t.size}, 3), one per time")
        self.times = t
        self.values = v

    def _segment(self, t):
        """Index k with times[k] <= t < times[k+1]; -1 before the table, K-1 after it."""
        return int(np.searchsorted(self.times, t, side="right")) - 1

    def _at_k(self, k, t):
        if k < 0:
            return self.values[0]
        if k >= self.times.size - 1:
            return self.values[-1]
        t0, t1 = self.times[k], self.times[k + 1]
        v0, v1 = self.values[k], self.values[k + 1]
        return v0 + (v1 - v0) * ((t - t0) / (t1 - t0))

    def at(self, t):
        return self._at_k(self._segment(t), t)

    def integral(self, t0, t1):
        """The integral of the history from t0 to t1 (exact for the piecewise-linear law)."""
        k0, k1 = self._segment(t0), self._segment(t1)
        if k0 == k1:
            return 0.5 * (self._at_k(k0, t0) + self._at_k(k0, t1)) * (t1 - t0)
        knots = self.times[k0 + 1:k1 + 1]
        ts = np.concatenate(([t0], knots, [t1]))
        vs = [self._at_k(k0, t0)] + [self.values[k] for k in range(k0 + 1, k1 + 1)] + [self._at_k(k1, t1)]
        total = 0.0
        for j in range(len(ts) - 1):
            total = total + 0.5 * (vs[j] + vs[j + 1]) * (ts[j + 1] - ts[j])
        return total

    def mean(self, t0, t1):
        """Mean over [t0, t1]: the average of the end values within one segment (so a
        constant table gives its value exactly), the exact integral / (t1 - t0) across knots."""
        k0, k1 = self._segment(t0), self._segment(t1)
        if k0 == k1:
            return 0.5 * (self._at_k(k0, t0) + self._at_k(k0, t1))
        return self.integral(t0, t1) / (t1 - t0)

    def max_abs(self):
        v = self.values
        return float(np.abs(v).max() if v.ndim == 1 else np.linalg.norm(v, axis=1).max())

    def get_state(self):
        return {"law": "table", "times": self.times.copy(), "values": self.values.copy()}

    # -- CSV ------------------------------------------------------------------------------
    #: accepted time columns and their unit (ASE time per unit)
    TIME_COLUMNS = {"t_s": units.s, "t_ms": units.ms, "t_us": units.us, "t_ns": units.ns, "t_ps": units.ps}
    #: accepted velocity units (column suffixes)
    VELOCITY_UNITS = {"m_s": units.m_s, "km_s": units.km_s, "mm_us": units.km_s, "um_ns": units.km_s}
    #: accepted stress units (column suffixes)
    STRESS_UNITS = {"GPa": units.GPa, "MPa": units.MPa, "Pa": units.Pa}
    _ALLOWED_COLUMNS = ("a time column t_s|t_ms|t_us|t_ns|t_ps and either u_<v> (velocity along the "
                        "drive's direction), ux_<v>,uy_<v>,uz_<v> (velocity vector) with v = m_s|km_s|"
                        "mm_us|um_ns, or sigma_<p> (stress) with p = GPa|MPa|Pa")

    @classmethod
    def read_csv(cls, path):
        """A table from a CSV file with a header naming the columns and their units.

        The header has one time column (``t_s``, ``t_ms``, ``t_us``, ``t_ns``
        or ``t_ps``) and either one velocity column ``u_<unit>`` (a speed
        along the drive's direction), three columns ``ux_<unit>, uy_<unit>,
        uz_<unit>`` (a velocity vector), with unit ``m_s``, ``km_s``,
        ``mm_us`` or ``um_ns``, or one stress column ``sigma_GPa``,
        ``sigma_MPa`` or ``sigma_Pa``.  E.g.::

            t_us,u_km_s
            0,0
            0.1,2.5
            1.0,2.5

        Lines starting with ``#`` are comments.  Any other header is refused
        (InputError naming the columns); values are converted to ASE units.
        """
        path = os.fspath(path)
        if not os.path.isfile(path):
            raise InputError("path", path, "an existing CSV file")
        with open(path, newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
        if not rows:
            raise InputError("path", path, "a CSV file with a header and rows", hint="empty file")
        header = [h.strip() for h in rows[0]]
        tcols = [h for h in header if h in cls.TIME_COLUMNS]
        rest = [h for h in header if h not in cls.TIME_COLUMNS]
        scale, vcols = None, None
        if len(tcols) == 1 and len(rest) == 1 and rest[0].startswith("u_") \
                and rest[0][2:] in cls.VELOCITY_UNITS:
            vcols, scale = rest, cls.VELOCITY_UNITS[rest[0][2:]]
        elif len(tcols) == 1 and len(rest) == 1 and rest[0].startswith("sigma_") \
                and rest[0][6:] in cls.STRESS_UNITS:
            vcols, scale = rest, cls.STRESS_UNITS[rest[0][6:]]
        elif len(tcols) == 1 and len(rest) == 3:
            suffix = {h[3:] for h in rest}
            if (sorted(h[:3] for h in rest) == ["ux_", "uy_", "uz_"] and len(suffix) == 1
                    and next(iter(suffix)) in cls.VELOCITY_UNITS):
                vcols = sorted(rest)
                scale = cls.VELOCITY_UNITS[next(iter(suffix))]
        if vcols is None:
            raise InputError("columns", ",".join(header), cls._ALLOWED_COLUMNS, hint=path)
        try:
            data = np.array([[float(r[header.index(c)]) for c in [tcols[0]] + vcols] for r in rows[1:]])
        except (ValueError, IndexError):
            raise InputError("path", path, "rows of numbers, one per header column") from None
        if data.shape[0] == 0:
            raise InputError("path", path, "at least one data row")
        t = data[:, 0] * cls.TIME_COLUMNS[tcols[0]]
        v = data[:, 1:] * scale
        return cls(t, v[:, 0] if v.shape[1] == 1 else v)

    def __repr__(self):
        return f"Table({self.times.size} points, t = {self.times[0]:.6g}..{self.times[-1]:.6g})"


class SmoothRamp:
    """A history rising from 0 to ``value`` over ``ramp_time`` with zero slope at both ends, then held.

    .. math::  U(t) = U_1 \\tfrac12 \\left(1 - \\cos\\frac{\\pi t}{t_r}\\right),\\ 0 \\le t < t_r;
               \\qquad U(t) = U_1,\\ t \\ge t_r;\\qquad U(t) = 0,\\ t < 0

    (a half cosine: the load starts without a jerk, so a quasi-static test
    launches no stress wave from its start).  ``mean(t0, t1)`` is the exact
    integral over the interval divided by its length, so a layer driven by it
    is displaced by exactly the integral of U.

    Parameters
    ----------
    value : float or (3,) array
        U_1, the value after the ramp (e.g. Angstrom/ASE-time).
    ramp_time : float
        t_r, ASE time, >= 0 (0: a step to ``value`` at t = 0).
    """

    law = "smooth_ramp"

    def __init__(self, value, ramp_time):
        self.value = _value(value, "value")
        try:
            tr = float(ramp_time)
        except (TypeError, ValueError):
            raise InputError("ramp_time", ramp_time, "a time >= 0 (ASE units)") from None
        if not (tr >= 0 and math.isfinite(tr)):
            raise InputError("ramp_time", ramp_time, "a time >= 0 (ASE units)")
        self.ramp_time = tr

    def fraction(self, t):
        """U(t) / U_1: 0 before t = 0, the half cosine up to ramp_time, 1 after."""
        tr = self.ramp_time
        if t >= tr:
            return 1.0
        if t <= 0:
            return 0.0
        return 0.5 * (1.0 - math.cos(math.pi * t / tr))

    def at(self, t):
        return self.value * self.fraction(t)

    def _mean_fraction(self, t0, t1):
        tr = self.ramp_time
        if t0 >= tr:
            return 1.0
        if t1 <= 0.0:
            return 0.0
        if t0 < 0.0 or t1 > tr:                   # split at the ends of the ramp
            a, b = max(t0, 0.0), min(t1, tr)
            return (self._mean_fraction(a, b) * (b - a) + max(t1 - tr, 0.0)) / (t1 - t0)
        # mean of (1 - cos(pi t/tr))/2 over [t0, t1], written without cancellation:
        # sin(a1) - sin(a0) = 2 cos(a_mid) sin(h), h = (a1 - a0)/2
        h = 0.5 * math.pi * (t1 - t0) / tr
        am = 0.5 * math.pi * (t0 + t1) / tr
        return 0.5 * (1.0 - math.cos(am) * (math.sin(h) / h if h > 0 else 1.0))

    def mean(self, t0, t1):
        if t1 == t0:
            return self.at(t0)
        return self.value * self._mean_fraction(t0, t1)

    def max_abs(self):
        return float(np.linalg.norm(self.value))

    def get_state(self):
        return {"law": "smooth_ramp", "value": self.value.copy(), "ramp_time": float(self.ramp_time)}

    def __repr__(self):
        return f"SmoothRamp({self.value.tolist()}, ramp_time={self.ramp_time:.6g})"


class Function:
    """A history given by a Python callable ``f(t) -> value`` (t in ASE time).

    ``mean(t0, t1)`` is the midpoint value (exact for a linear ramp).  Not
    storable in a checkpoint (pass a :class:`Table` instead).
    """

    law = "callable"

    def __init__(self, f):
        if not callable(f):
            raise InputError("f", f, "a callable t -> value")
        self.f = f

    def at(self, t):
        return _value(self.f(t), f"value of {getattr(self.f, '__name__', 'the callable')}(t={t!r})")

    def mean(self, t0, t1):
        return self.at(t0 + 0.5 * (t1 - t0))

    def max_abs(self):
        return None

    def get_state(self):
        raise InputError("history", f"callable {getattr(self.f, '__name__', repr(self.f))}",
                         "a constant or a Table to be stored in a checkpoint "
                         "(a Python callable cannot be saved: pass Table(times, values))")

    def __repr__(self):
        return f"Function({getattr(self.f, '__name__', repr(self.f))})"


def as_history(value, name):
    """A history from a number, 3-vector, :class:`Table`, :class:`Constant`, :class:`SmoothRamp`,
    :class:`Function` or callable."""
    if isinstance(value, (Constant, Table, SmoothRamp, Function)):
        return value
    if callable(value):
        return Function(value)
    try:
        return Constant(value)
    except InputError:
        raise InputError(name, value, "a number, a 3-vector, a Table, or a callable t -> value") from None


def history_from_state(d):
    law = d.get("law")
    if law == "constant":
        return Constant(d["value"])
    if law == "table":
        return Table(d["times"], d["values"])
    if law == "smooth_ramp":
        return SmoothRamp(d["value"], d["ramp_time"])
    raise InputError("history law", law, "'constant', 'table' or 'smooth_ramp'")


def describe_history(h, scale, unit):
    """A history in display units (value / scale, times in ns)."""
    if isinstance(h, Constant):
        return {"law": "constant", f"value_{unit}": (h.value / scale).tolist()}
    if isinstance(h, Table):
        return {"law": "piecewise linear in t, held at the end values outside the table",
                "t_ns": (h.times / units.ns).tolist(), f"value_{unit}": (h.values / scale).tolist()}
    if isinstance(h, SmoothRamp):
        return {"law": "half-cosine ramp from 0 to the value over the ramp time, then held",
                "ramp_time_ns": h.ramp_time / units.ns, f"value_{unit}": (h.value / scale).tolist()}
    return {"law": "callable (not stored)", "callable": getattr(h.f, "__name__", repr(h.f))}

