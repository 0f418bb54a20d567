"""Drives and walls: ASE constraints that know the time (pistons with U(t), planar walls, tractions).

Every member of the family is an ASE constraint (``adjust_positions``,
``adjust_momenta``, ``adjust_forces``, ``adjust_potential_energy``), so it
works in clusterdyn's :class:`~clusterdyn.md.DampedVerlet` (inside its fused
fast path) and in ASE's own dynamics (``ase.md.verlet.VelocityVerlet``), and
mixes with ASE's constraints (``FixAtoms``).

* :class:`Piston` -- a layer of particles moving rigidly at a prescribed
  velocity history U(t) in any direction: a constant, a piecewise-linear
  :class:`Table` (also read from a CSV file), a :class:`SmoothRamp` or a
  Python callable.  A held layer (particles at rest) is
  ``Piston(indices, 0.0)``.  ``lateral="free"`` prescribes only the velocity
  along the piston's direction (a grip that lets its particles move across
  it, as in a uniaxial test).
* :class:`Wall` -- a planar rigid wall with any normal, as a smooth
  repulsive force on the particles (LAMMPS' ``fix wall/region ... harmonic``
  law), frictionless or sticking.
* :class:`Traction` -- a layer pressed along its normal by a prescribed
  stress (it moves rigidly along the normal) while driven at a prescribed
  tangential velocity; records the friction force and its normal position.

The time
--------
A drive reads the time from the dynamics it is bound to:
``t = nsteps * dt`` between steps.  :class:`~clusterdyn.md.DampedVerlet`
binds the drives of its Atoms itself.  In ASE's dynamics call
``drive.bind(dyn)`` once after making the dynamics (needed for a
time-dependent U(t) and for the impulse and work records; an unbound
constant piston behaves as a fixed-velocity layer, an unbound drive records
its force but accumulates nothing).

Where U(t) is evaluated
-----------------------
In the step from t_n to t_{n+1} = t_n + dt the layer drifts with the mean
of U over the step, ``(X(t_{n+1}) - X(t_n))/dt`` with X the integral of U
(exact for a :class:`Table`, the midpoint value U(t_n + dt/2) for a
callable, which is exact for a linear ramp; exact for a :class:`SmoothRamp`),
so the layer's displacement is
the integral of U to rounding.  After the forces at the new positions the
layer's momenta hold ``m U(t_{n+1})`` (what the kinetic energy and damping
see at the step's end).  Before the first and after the last time of a
table, U holds the first and last value.

Records (every drive)
---------------------
``force`` : (3,) eV/Angstrom
    The force the particles exert on the drive at the last step (for a
    piston or a traction the sum of the forces on its layer, for a wall
    minus the sum of the wall forces on the particles).
``impulse`` : (3,) amu Angstrom / ASE-time
    Momentum the drive has given to the other particles: minus the
    trapezoid time integral of ``force`` over the steps.
``work`` : float, eV
    Work the drive has done on the other particles: the trapezoid integral
    of ``-force . v_layer`` (zero for a fixed wall, whose energy is
    potential energy instead).  An energy ledger over all particles adds the
    layers' own kinetic energy change: ``E(t) - E(0) = sum(work) +
    dK_layers - dissipated``.

A force sample is taken once per time (the first ``adjust_forces`` call at
a new time; later calls at the same time, e.g. observers asking for forces,
apply the constraint but do not record again).

Checkpoints
-----------
``get_state()`` gives a dict of arrays and scalars (what
:mod:`clusterdyn.io.checkpoint` stores) with the history, the records and
the time state; :func:`from_state` rebuilds the drive.  A callable history
cannot be stored: checkpointing it raises :class:`~clusterdyn.errors.InputError`
(pass a :class:`Table` instead).  ``describe()`` gives a JSON-able summary in
display units (km/s, ns, um, GPa) for H5MD metadata.

The drives deliberately have no ``todict()``: ASE rebuilds only the
constraints it knows, so a ``.traj`` file with one would be unreadable.
"""

import copy
import csv
import math
import os

import numpy as np
from numba import njit

from .. import units
from ..errors import InputError, InstabilityError
from ._integrate import set_momenta, set_momenta_along, take_forces, take_forces_along

__all__ = ["Constant", "Table", "SmoothRamp", "Function", "Drive", "Piston", "Wall", "Traction",
           "from_state"]


# -- velocity (and stress) histories ----------------------------------------------------------

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


def _history_describe(h, scale, unit):
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


def _unit(v, name):
    a = np.array(v, dtype=float)
    n = float(np.linalg.norm(a)) if a.shape == (3,) else 0.0
    if a.shape != (3,) or not np.all(np.isfinite(a)) or not n > 0:
        raise InputError(name, v, "a finite non-zero 3-vector")
    return a / n


def _rows(indices, name="indices", allow_empty=False):
    idx = np.asarray(indices)
    if idx.dtype == bool:
        idx = np.nonzero(idx)[0]
    if idx.size and not np.issubdtype(idx.dtype, np.integer):
        raise InputError(name, indices, "particle indices (ints) or a boolean mask")
    idx = np.ascontiguousarray(idx, dtype=np.int64).ravel()
    if idx.size == 0 and not allow_empty:
        raise InputError(name, "[]", "at least one particle")
    if idx.size and (idx.min() < 0):
        raise InputError(name, int(idx.min()), "indices >= 0")
    return idx


def _masses(atoms):
    m = atoms.arrays.get("masses")
    return m if m is not None else atoms.get_masses()


def _is_f64(a):
    return isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 2 and a.shape[1] == 3 \
        and a.flags.c_contiguous


def _shuffle(index, ind, what):
    ind = np.asarray(ind)
    if ind.dtype == bool:
        ind = np.nonzero(ind)[0]
    index = np.asarray(index, dtype=np.int64)
    size = int(max(ind.max(initial=-1), index.max(initial=-1))) + 1
    new = np.full(size, -1, np.int64)
    new[ind] = np.arange(ind.shape[0])
    kept = new[index]
    kept = kept[kept >= 0]
    if not kept.size:
        raise IndexError(f"no {what} particle left")
    return kept


# -- the family ---------------------------------------------------------------------------------

class Drive:
    """Base of the family: the time, the force records, the step protocol.

    The dynamics' side of the protocol (what :class:`~clusterdyn.md.DampedVerlet`
    calls; ASE's dynamics reach the same through ``adjust_positions``):
    :meth:`bind` once; per step :meth:`begin_step` before the drift (the
    layer's momenta then give the step's drift velocity), :meth:`end_drift`
    after it, then ``adjust_forces`` at the new positions, :meth:`kick_extra`
    after the second half kick, ``adjust_momenta``.
    """

    kind = "Drive"

    def __init__(self):
        self._dyn = None
        self._time = 0.0
        self._step_of = None
        self._drifted = False
        self.t_sample = None
        self.force = np.zeros(3)
        self.impulse = np.zeros(3)
        self.work = 0.0
        self._power = 0.0

    # -- time ---------------------------------------------------------------------------
    def bind(self, dyn):
        """Read the time from ``dyn`` (``dyn.nsteps * dyn.dt``); returns self."""
        if not (hasattr(dyn, "nsteps") and hasattr(dyn, "dt")):
            raise InputError("dyn", type(dyn).__name__, "a dynamics with nsteps and dt (ase.md MolecularDynamics)")
        self._dyn = dyn
        self._step_of = None
        self._drifted = False
        return self

    @property
    def bound(self):
        return self._dyn is not None

    @property
    def time(self):
        """The time of the Atoms' current positions as the drive sees it (ASE time)."""
        d = self._dyn
        if d is None:
            return self._time
        n = d.nsteps
        if self._step_of == n and self._drifted:
            n += 1
        return n * d.dt

    def _step_number(self):
        d = self._dyn
        if d is None:
            return None
        return d.nsteps + (1 if (self._step_of == d.nsteps and self._drifted) else 0)

    def _in_drift(self):
        d = self._dyn
        return d is not None and self._step_of == d.nsteps and not self._drifted

    def begin_step(self):
        """Start the step from ``nsteps*dt`` to ``(nsteps+1)*dt`` of the bound dynamics."""
        d = self._dyn
        if d is None:
            raise InputError(self.kind, "unbound", "a drive bound to its dynamics (drive.bind(dyn))")
        n = d.nsteps
        self._step_of = n
        self._drifted = False
        self._begin(n * d.dt, (n + 1) * d.dt, d.dt)

    def end_drift(self):
        """The positions now belong to the step's end time."""
        self._drifted = True

    def _begin(self, t0, t1, dt):
        pass

    # -- records ------------------------------------------------------------------------
    def _how(self, t):
        """'replace', 'accumulate' or 'skip' for a force sample at time t."""
        if self._dyn is None or self.t_sample is None:
            return "replace"
        if t > self.t_sample:
            return "accumulate"
        if t == self.t_sample:
            return "skip"
        raise InputError("time", t, f">= {self.t_sample!r}, the time of the drive's last force sample",
                         hint="the drive's clock went back: a drive continues its time in a new dynamics "
                              "only if that dynamics continues the step count (restore nsteps), "
                              "else make a new drive")

    def _commit(self, how, t, R, P):
        if how == "accumulate":
            dt = t - self.t_sample
            self.impulse = self.impulse - 0.5 * dt * (self.force + R)
            self.work = self.work + 0.5 * dt * (self._power + P)
        self.t_sample = t
        self.force = R
        self._power = P

    def _records_state(self):
        return {"t_sample": self.t_sample, "force": np.array(self.force, dtype=float),
                "impulse": np.array(self.impulse, dtype=float), "work": float(self.work),
                "power": float(self._power)}

    def _restore_records(self, d):
        self.t_sample = None if d.get("t_sample") is None else float(d["t_sample"])
        self.force = np.array(d.get("force", np.zeros(3)), dtype=float)
        self.impulse = np.array(d.get("impulse", np.zeros(3)), dtype=float)
        self.work = float(d.get("work", 0.0))
        self._power = float(d.get("power", 0.0))

    # -- ASE constraint interface (defaults) ----------------------------------------------
    def adjust_positions(self, atoms, new):
        d = self._dyn
        if d is not None and not (self._step_of == d.nsteps and self._drifted):
            if not self._in_drift():
                self.begin_step()
            self.end_drift()

    def adjust_momenta(self, atoms, momenta):
        pass

    def adjust_forces(self, atoms, forces):
        pass

    def adjust_potential_energy(self, atoms):
        return 0.0

    def kick_extra(self, momenta, h):
        """Add ``h`` times the forces this drive added in its last ``adjust_forces`` (none here)."""

    def get_removed_dof(self, atoms):
        return 0

    def max_speed(self):
        """Largest speed the drive imposes (Angstrom/ASE-time), None if not known (a callable)."""
        return 0.0

    def copy(self):
        return copy.deepcopy(self)

    def __deepcopy__(self, memo):
        c = copy.copy(self)
        for k, v in self.__dict__.items():
            if k in ("_dyn", "_buf", "_zeros"):
                setattr(c, k, None)
            elif isinstance(v, np.ndarray):
                setattr(c, k, v.copy())
        c._step_of = None
        c._drifted = False
        if "_nt" in self.__dict__:
            c._nt = 0
        return c

    def get_state(self):
        raise NotImplementedError

    def describe(self):
        raise NotImplementedError


class _Layer(Drive):
    """A layer of particles moving rigidly with a velocity the drive sets (piston, traction)."""

    def __init__(self, indices):
        super().__init__()
        self.index = _rows(indices)
        self._vstep = None

    def _v_end(self, t):
        raise NotImplementedError

    def _v_drift(self):
        return self._vstep

    def adjust_momenta(self, atoms, momenta):
        v = self._v_drift() if self._in_drift() else self._v_end(self.time)
        m = _masses(atoms)
        if _is_f64(momenta) and m.dtype == np.float64:
            set_momenta(momenta, m, self.index, v)
        else:
            momenta[self.index] = m[self.index, None] * v[None, :]

    def adjust_positions(self, atoms, new):
        d = self._dyn
        if d is None:
            self._unbound_positions()
            return
        if self._step_of == d.nsteps and self._drifted:       # moved already in this step: hold
            new[self.index] = atoms.positions[self.index]
            return
        if not self._in_drift():
            self.begin_step()
        m = _masses(atoms)[self.index, None]
        v = self._v_drift()
        new[self.index] = atoms.positions[self.index] + d.dt * ((m * v[None, :]) * (1.0 / m))
        self.end_drift()

    def _unbound_positions(self):
        pass

    def _take(self, forces):
        if _is_f64(forces):
            R = np.empty(3)
            take_forces(forces, self.index, R)
        else:
            R = np.asarray(forces[self.index].sum(axis=0), dtype=float).copy()
            forces[self.index] = 0.0
        return R

    def get_removed_dof(self, atoms):
        return 3 * len(self.index)

    def index_shuffle(self, atoms, ind):
        self.index = _shuffle(self.index, ind, self.kind.lower())


class Piston(_Layer):
    """A layer of particles moving rigidly at a prescribed velocity U(t).

    The layer's forces are recorded (:attr:`force`, the reaction of the
    sample on the piston) and zeroed; its momenta are held at ``m U``; in a
    step the layer drifts with the mean of U over the step (see the module
    docstring).  ``Piston(indices, 0.0)`` holds a layer at rest.

    With ``lateral="free"`` only the velocity along ``direction`` is
    prescribed (a grip): each particle of the layer keeps its own velocity
    across ``direction``, which the forces change as for any particle; only
    the force components along ``direction`` are taken (and recorded), and
    the layer drifts along ``direction`` with the mean of U.  ``"fixed"``
    (the default) prescribes the whole velocity (``U`` along ``direction``,
    zero across it, or the vector U).

    Parameters
    ----------
    indices : array of int or bool mask
        Particles of the layer (rows of the Atoms).
    velocity : float, (3,) array, Table, SmoothRamp, Function or callable
        U(t) in Angstrom/ASE-time: a number (speed along ``direction``), a
        3-vector, a :class:`Table` (of speeds along ``direction`` or of
        3-vectors; e.g. ``Table.read_csv("u.csv")``), a :class:`SmoothRamp`, or
        a callable ``t -> speed or 3-vector`` (not storable in checkpoints).
        With ``lateral="free"`` a speed along ``direction`` (vectors refused).
    direction : (3,) array, default (1, 0, 0)
        Direction of scalar speeds (normalised); ignored for vector values.
    lateral : "fixed" or "free", default "fixed"
        Whether the velocity across ``direction`` is prescribed too (zero) or
        left to the forces, particle by particle.
    """

    kind = "Piston"
    LATERAL = ("fixed", "free")

    def __init__(self, indices, velocity, direction=(1.0, 0.0, 0.0), lateral="fixed"):
        super().__init__(indices)
        self.direction = _unit(direction, "direction")
        if lateral not in self.LATERAL:
            raise InputError("lateral", lateral, "'fixed' (the whole velocity prescribed) or 'free' (only the "
                             "velocity along direction)")
        self.lateral = lateral
        self.history = as_history(velocity, "velocity")
        if lateral == "free":
            vec = (isinstance(self.history, (Constant, SmoothRamp)) and self.history.value.shape != ()) or \
                  (isinstance(self.history, Table) and self.history.values.ndim != 1)
            if vec:
                raise InputError("velocity", velocity, "a speed along direction (numbers) for lateral='free'")
        self._const = self._vec(self.history.value) if isinstance(self.history, Constant) else None

    @property
    def free(self):
        """True when only the velocity along :attr:`direction` is prescribed."""
        return self.lateral == "free"

    def _vec(self, u):
        u = np.asarray(u, dtype=float)
        if u.ndim == 0:
            return self.direction * float(u) + 0.0        # + 0.0: no negative zeros
        if self.free:
            raise InputError("velocity", u.tolist(), "a speed along direction (a number) for lateral='free'")
        return u + 0.0

    def _v_end(self, t):
        return self._const if self._const is not None else self._vec(self.history.at(t))

    def _begin(self, t0, t1, dt):
        self._vstep = self._const if self._const is not None else self._vec(self.history.mean(t0, t1))

    def _unbound_positions(self):
        if self._const is None:
            raise InputError("Piston", "unbound", "a piston with a time-dependent U(t) bound to its dynamics: "
                             "piston.bind(dyn) after making the dynamics")

    @property
    def velocity(self):
        """U at the drive's current time, (3,) Angstrom/ASE-time."""
        return self._v_end(self.time)

    def velocity_at(self, t):
        """U(t), (3,) Angstrom/ASE-time."""
        return self._v_end(t)

    def adjust_momenta(self, atoms, momenta):
        if not self.free:
            return super().adjust_momenta(atoms, momenta)
        v = self._v_drift() if self._in_drift() else self._v_end(self.time)
        u = float(np.dot(v, self.direction))
        m = _masses(atoms)
        if _is_f64(momenta) and m.dtype == np.float64:
            set_momenta_along(momenta, m, self.index, self.direction, u)
        else:
            p = np.asarray(momenta[self.index], dtype=float)
            n = self.direction
            momenta[self.index] = (p - (p @ n)[:, None] * n[None, :]) + (m[self.index] * u)[:, None] * n[None, :]

    def adjust_positions(self, atoms, new):
        if not self.free:
            return super().adjust_positions(atoms, new)
        d = self._dyn
        if d is None:
            self._unbound_positions()
            return
        n = self.direction
        old = atoms.positions[self.index]
        step = new[self.index] - old
        across = step - (step @ n)[:, None] * n[None, :]
        if self._step_of == d.nsteps and self._drifted:       # moved along n already in this step
            new[self.index] = old + across
            return
        if not self._in_drift():
            self.begin_step()
        m = _masses(atoms)[self.index, None]
        u = float(np.dot(self._v_drift(), n))
        new[self.index] = old + across + d.dt * ((m * u) * (1.0 / m)) * n[None, :]
        self.end_drift()

    def _take(self, forces):
        if not self.free:
            return super()._take(forces)
        R = np.empty(3)
        if _is_f64(forces):
            take_forces_along(forces, self.index, self.direction, R)
        else:
            f = np.ascontiguousarray(forces[self.index], dtype=float)
            take_forces_along(f, np.arange(len(self.index), dtype=np.int64), self.direction, R)
            forces[self.index] = f
        return R

    def adjust_forces(self, atoms, forces):
        R = self._take(forces)
        t = self.time
        how = self._how(t)
        if how != "skip":
            self._commit(how, t, R, -float(np.dot(R, self._v_end(t))))

    def get_removed_dof(self, atoms):
        return len(self.index) if self.free else 3 * len(self.index)

    def max_speed(self):
        m = self.history.max_abs()
        return m

    def get_state(self):
        return {"kind": "Piston", "index": self.index.copy(), "direction": self.direction.copy(),
                "history": self.history.get_state(), "lateral": self.lateral, **self._records_state()}

    @classmethod
    def _from_state(cls, d):
        if "history" in d:
            h = history_from_state(d["history"])
        else:                                  # files written before U(t): a constant velocity
            h = Constant(d["velocity"])
        p = cls(d["index"], h, d.get("direction", (1.0, 0.0, 0.0)), lateral=str(d.get("lateral", "fixed")))
        p._restore_records(d)
        return p

    def describe(self):
        d = {"kind": "Piston", "n_particles": int(self.index.size),
             "direction": self.direction.tolist(),
             "velocity": _history_describe(self.history, units.km_s, "km_s"),
             "lateral": self.lateral + (" (only the velocity along direction prescribed)" if self.free else
                                        " (the whole velocity prescribed)"),
             "evaluated": "layer drifts with the mean of U over each step; momenta at step ends hold U(t)",
             "impulse_N_s": (self.impulse / (units.N * units.s)).tolist(),
             "work_J": float(self.work / units.J)}
        return d

    def __repr__(self):
        lat = ", lateral='free'" if self.free else ""
        return (f"Piston({len(self.index)} particles, velocity={self.history!r}, "
                f"direction={self.direction.tolist()}{lat})")


class Traction(_Layer):
    """A layer pressed along its normal by a prescribed stress and driven tangentially.

    The layer moves rigidly.  Along ``normal`` it is a free rigid body of
    mass M (the layer's mass) under the force ``R . normal - stress * area``
    (R the force of the body on the layer), integrated with the dynamics'
    velocity-Verlet steps; across ``normal`` it moves at the prescribed
    tangential velocity U_t(t) (evaluated as for :class:`Piston`).  The
    layer's own forces are recorded in :attr:`force` and zeroed.

    Parameters
    ----------
    indices : array of int or bool mask
        Particles of the layer.
    normal : (3,) array
        Outward normal of the body at the layer (from the body towards the
        layer); normalised.
    stress : float, Table, Function or callable
        Normal pressure, eV/Angstrom^3 (``units.GPa``); positive presses the
        layer along ``-normal`` into the body with force ``stress * area``.
    velocity : float, (3,) array, Table, Function or callable, default 0
        Tangential velocity U_t(t), Angstrom/ASE-time: a speed along
        ``tangent`` or a vector perpendicular to ``normal``.
    tangent : (3,) array, optional
        Direction of scalar speeds (perpendicular to ``normal``); needed when
        ``velocity`` is a non-zero scalar history.
    area : float, optional
        Area the stress acts on, Angstrom^2.  Default: derived at the first
        force evaluation as the area of the cell face spanned by the two
        periodic cell vectors perpendicular to ``normal``; if there are no
        such vectors an area must be given.
    normal_velocity : float, default 0
        The layer's initial velocity along ``normal``.

    Attributes
    ----------
    friction : (3,) eV/Angstrom
        Tangential part of :attr:`force` (the friction the body exerts on the layer).
    normal_position : float, Angstrom
        The layer's centre of mass along ``normal`` at the last force sample.
    normal_velocity : float, Angstrom/ASE-time
        The layer's velocity along ``normal`` (at the step's end).
    """

    kind = "Traction"

    def __init__(self, indices, normal, stress, velocity=0.0, tangent=None, area=None, normal_velocity=0.0):
        super().__init__(indices)
        self.normal = _unit(normal, "normal")
        self.stress = as_history(stress, "stress")
        if isinstance(self.stress, Constant) and self.stress.value.shape != ():
            raise InputError("stress", stress, "a number (normal pressure), a Table of numbers or a callable")
        if isinstance(self.stress, Table) and self.stress.values.ndim != 1:
            raise InputError("stress", "Table of vectors", "a Table of numbers (normal pressure)")
        self.history = as_history(velocity, "velocity")
        self.tangent = None
        if tangent is not None:
            self.tangent = _unit(tangent, "tangent")
            if abs(float(np.dot(self.tangent, self.normal))) > 1e-12:
                raise InputError("tangent", tangent, "a direction perpendicular to normal")
        scalar = (isinstance(self.history, Constant) and self.history.value.shape == ()) or \
                 (isinstance(self.history, Table) and self.history.values.ndim == 1)
        if scalar and self.tangent is None and self.history.max_abs() != 0.0:
            raise InputError("tangent", None, "a tangential direction for a scalar velocity")
        if isinstance(self.history, (Constant, Table)) and not scalar:
            vals = np.atleast_2d(self.history.value if isinstance(self.history, Constant) else self.history.values)
            vn = np.abs(vals @ self.normal)
            if np.any(vn > 1e-12 * np.maximum(np.linalg.norm(vals, axis=1), 1e-300)):
                raise InputError("velocity", velocity, "a tangential velocity (perpendicular to normal)")
        if area is not None:
            try:
                area = float(area)
            except (TypeError, ValueError):
                raise InputError("area", area, "a positive area (Angstrom^2) or None") from None
            if not (area > 0 and math.isfinite(area)):
                raise InputError("area", area, "a positive area (Angstrom^2) or None")
        self.area = area
        self.normal_velocity = float(normal_velocity)
        self._vn_half = self.normal_velocity
        self._an = 0.0
        self.mass = None
        self.friction = np.zeros(3)
        self.normal_position = float("nan")

    def _ut(self, u):
        u = np.asarray(u, dtype=float)
        if u.ndim == 0:
            if u == 0.0:
                return np.zeros(3)
            if self.tangent is None:
                raise InputError("tangent", None, "a tangential direction for a scalar velocity")
            return self.tangent * float(u)
        if abs(float(np.dot(u, self.normal))) > 1e-12 * max(float(np.linalg.norm(u)), 1e-300):
            raise InputError("velocity", u.tolist(), "a tangential velocity (perpendicular to normal)")
        return u

    def stress_at(self, t):
        s = np.asarray(self.stress.at(t), dtype=float)
        if s.shape != ():
            raise InputError("stress", s.tolist(), "a number (normal pressure)")
        return float(s)

    def _v_end(self, t):
        return self.normal_velocity * self.normal + self._ut(self.history.at(t))

    def _begin(self, t0, t1, dt):
        self._vn_half = self.normal_velocity + 0.5 * dt * self._an
        self._vstep = self._vn_half * self.normal + self._ut(self.history.mean(t0, t1))

    def _unbound_positions(self):
        raise InputError("Traction", "unbound", "a traction bound to its dynamics: traction.bind(dyn) "
                         "after making the dynamics")

    def _resolve(self, atoms):
        if self.mass is None:
            self.mass = float(_masses(atoms)[self.index].sum())
        if self.area is None:
            self.area = self._derive_area(atoms)

    def _derive_area(self, atoms):
        cell = atoms.cell.array
        pbc = atoms.pbc
        best = None
        for i in range(3):
            for j in range(i + 1, 3):
                if pbc[i] and pbc[j]:
                    c = np.cross(cell[i], cell[j])
                    a = float(np.linalg.norm(c))
                    if a > 0 and abs(abs(float(np.dot(c / a, self.normal))) - 1.0) < 1e-9:
                        best = a
        if best is None:
            raise InputError("area", None, "an area in Angstrom^2: it is derived only when two periodic "
                             "cell vectors span the plane perpendicular to normal")
        return best

    def adjust_forces(self, atoms, forces):
        self._resolve(atoms)
        R = self._take(forces)
        t = self.time
        how = self._how(t)
        if how == "skip":
            return
        an = (float(np.dot(R, self.normal)) - self.stress_at(t) * self.area) / self.mass
        if how == "accumulate" and self._step_of is not None:
            self.normal_velocity = self._vn_half + 0.5 * self._dyn.dt * an
        self._an = an
        self.friction = R - float(np.dot(R, self.normal)) * self.normal
        m = _masses(atoms)[self.index]
        self.normal_position = float(np.dot(m @ atoms.positions[self.index], self.normal) / self.mass)
        self._commit(how, t, R, -float(np.dot(R, self._v_end(t))))

    def max_speed(self):
        return self.history.max_abs()

    def get_state(self):
        return {"kind": "Traction", "index": self.index.copy(), "normal": self.normal.copy(),
                "tangent": None if self.tangent is None else self.tangent.copy(),
                "stress": self.stress.get_state(), "history": self.history.get_state(),
                "area": self.area, "normal_velocity": float(self.normal_velocity),
                "acceleration": float(self._an), "mass": self.mass,
                "friction": self.friction.copy(), "normal_position": float(self.normal_position),
                **self._records_state()}

    @classmethod
    def _from_state(cls, d):
        tr = cls(d["index"], d["normal"], history_from_state(d["stress"]), history_from_state(d["history"]),
                 tangent=d.get("tangent"), area=d.get("area"), normal_velocity=d.get("normal_velocity", 0.0))
        tr._an = float(d.get("acceleration", 0.0))
        tr.mass = None if d.get("mass") is None else float(d["mass"])
        tr.friction = np.array(d.get("friction", np.zeros(3)), dtype=float)
        tr.normal_position = float(d.get("normal_position", float("nan")))
        tr._vn_half = tr.normal_velocity
        tr._restore_records(d)
        return tr

    def describe(self):
        return {"kind": "Traction", "n_particles": int(self.index.size), "normal": self.normal.tolist(),
                "tangent": None if self.tangent is None else self.tangent.tolist(),
                "stress": _history_describe(self.stress, units.GPa, "GPa"),
                "velocity": _history_describe(self.history, units.km_s, "km_s"),
                "area_um2": None if self.area is None else self.area / units.um ** 2,
                "law": "rigid layer: free along normal under R.n - stress*area, tangential velocity prescribed",
                "impulse_N_s": (self.impulse / (units.N * units.s)).tolist(),
                "work_J": float(self.work / units.J)}

    def __repr__(self):
        return (f"Traction({len(self.index)} particles, normal={self.normal.tolist()}, stress={self.stress!r}, "
                f"velocity={self.history!r})")


# -- the wall ------------------------------------------------------------------------------------

@njit(cache=True)
def _wall_candidates(x_nc, rows, n_c, p0, reach, touched):
    """Rows with ``d = x . n - p0 < reach`` into ``touched``; returns (count, smallest d)."""
    n0 = n_c[0]
    n1 = n_c[1]
    n2 = n_c[2]
    dmin = np.inf
    nt = 0
    if rows.shape[0] == 0:
        for i in range(x_nc.shape[0]):
            d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
            dmin = min(dmin, d)
            if d < reach:
                touched[nt] = i
                nt += 1
    else:
        for q in range(rows.shape[0]):
            i = rows[q]
            d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
            dmin = min(dmin, d)
            if d < reach:
                touched[nt] = i
                nt += 1
    return nt, dmin


@njit(cache=True)
def wall_harmonic(x_nc, f_nc, rows, types_n, point_c, n_c, K_t, dc_t, stick, touched, extra_nc):
    """Add the harmonic wall force to ``f`` and list the touched particles.

    For particle i (all rows, or ``rows`` when it has entries) at distance
    ``d = x_i . n - point . n`` from the plane, if ``d < dc``: force
    ``2 K (dc - d) n`` and energy ``K (dc - d)^2`` (K, dc of its type).  With
    ``stick`` the tangential part of ``f_i`` is removed as well.  The change
    made to ``f_i`` goes to ``extra_nc[q]`` with ``touched[q] = i``.  One
    streaming pass finds the particles within the largest d_c (and the
    smallest d); the forces are then computed on those alone.
    Returns (touched count, energy, sum of the changes (3), smallest d, its particle).
    """
    n0 = n_c[0]
    n1 = n_c[1]
    n2 = n_c[2]
    p0 = point_c[0] * n0 + point_c[1] * n1 + point_c[2] * n2
    nc, dmin = _wall_candidates(x_nc, rows, n_c, p0, dc_t.max(), touched)
    nt = 0
    e = 0.0
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for q in range(nc):
        i = touched[q]
        d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
        t = types_n[i]
        dc = dc_t[t]
        if d < dc:
            K = K_t[t]
            g = dc - d
            e += K * g * g
            fw = 2.0 * K * g
            ex = fw * n0
            ey = fw * n1
            ez = fw * n2
            if stick:
                fn = f_nc[i, 0] * n0 + f_nc[i, 1] * n1 + f_nc[i, 2] * n2
                ex -= f_nc[i, 0] - fn * n0
                ey -= f_nc[i, 1] - fn * n1
                ez -= f_nc[i, 2] - fn * n2
            f_nc[i, 0] += ex
            f_nc[i, 1] += ey
            f_nc[i, 2] += ez
            touched[nt] = i
            extra_nc[nt, 0] = ex
            extra_nc[nt, 1] = ey
            extra_nc[nt, 2] = ez
            fx += ex
            fy += ey
            fz += ez
            nt += 1
    imin = -1
    if dmin < 0.0:                       # name the particle (a failing step only)
        for q in range(x_nc.shape[0] if rows.shape[0] == 0 else rows.shape[0]):
            i = q if rows.shape[0] == 0 else rows[q]
            if x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0 == dmin:
                imin = i
                break
    return nt, e, fx, fy, fz, dmin, imin


@njit(cache=True)
def wall_energy(x_nc, rows, types_n, point_c, n_c, K_t, dc_t, touched):
    """Energy of the harmonic wall, sum of ``K (dc - d)^2`` over particles with ``d < dc``."""
    n0 = n_c[0]
    n1 = n_c[1]
    n2 = n_c[2]
    p0 = point_c[0] * n0 + point_c[1] * n1 + point_c[2] * n2
    nc, dmin = _wall_candidates(x_nc, rows, n_c, p0, dc_t.max(), touched)
    e = 0.0
    for q in range(nc):
        i = touched[q]
        d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
        t = types_n[i]
        if d < dc_t[t]:
            g = dc_t[t] - d
            e += K_t[t] * g * g
    return e


@njit(cache=True)
def kick_rows(p_nc, touched, extra_nc, nt, h):
    """p[touched[q]] += h * extra[q] for q < nt."""
    for q in range(nt):
        i = touched[q]
        p_nc[i, 0] += h * extra_nc[q, 0]
        p_nc[i, 1] += h * extra_nc[q, 1]
        p_nc[i, 2] += h * extra_nc[q, 2]


@njit(cache=True)
def stick_rows(p_nc, m_n, touched, nt, n_c, dp_c):
    """Remove the tangential momentum of the touched rows; dp (3) gets the momentum change,
    returns the kinetic energy removed."""
    de = 0.0
    for q in range(nt):
        i = touched[q]
        pn = p_nc[i, 0] * n_c[0] + p_nc[i, 1] * n_c[1] + p_nc[i, 2] * n_c[2]
        tx = p_nc[i, 0] - pn * n_c[0]
        ty = p_nc[i, 1] - pn * n_c[1]
        tz = p_nc[i, 2] - pn * n_c[2]
        de += 0.5 * (tx * tx + ty * ty + tz * tz) / m_n[i]
        p_nc[i, 0] -= tx
        p_nc[i, 1] -= ty
        p_nc[i, 2] -= tz
        dp_c[0] -= tx
        dp_c[1] -= ty
        dp_c[2] -= tz
    return de


def _per_type(v, name, unit):
    if v is None:
        return None
    a = np.atleast_1d(np.array(v, dtype=float))
    if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a)) or not np.all(a > 0):
        raise InputError(name, v, f"a positive number ({unit}) or one per material id, or None for the default")
    return a


class Wall(Drive):
    """A planar rigid wall with any normal, as a smooth repulsive force (harmonic).

    A particle at distance ``d = (x - point) . normal`` from the plane (on the
    side the normal points to) feels, for ``d < d_c``,

    .. math::  E = K (d_c - d)^2, \\qquad \\mathbf f = 2 K (d_c - d)\\, \\mathbf n

    exactly LAMMPS' ``fix wall/region ... harmonic K sigma d_c`` on a plane
    region (so the export is faithful).  Defaults from the calculator's pair
    law (:class:`~clusterdyn.calculators.ClusterDynamics`), per material a:
    ``2 K_a = k_a`` with ``k_a = -f'(r0_a)`` the cluster-cluster bond stiffness
    (the wall is as stiff as one bond) and ``d_c = r0_a / 2`` (a cluster
    touches the wall where a neighbour at r0 would touch it).

    Frictionless by default.  ``sticking=True``: particles within ``d_c``
    have the tangential part of their force removed and their tangential
    momentum set to zero at every constraint call (no slip while touching);
    the momentum removed counts in :attr:`impulse` and the kinetic energy
    removed in :attr:`dissipated`.

    The wall's energy enters ``atoms.get_potential_energy()`` (and
    DampedVerlet's energies) through ``adjust_potential_energy``, so the
    total energy is conserved.  A fixed wall does no work (:attr:`work` stays 0).
    A particle behind the plane (d < 0) stops the run with
    :class:`~clusterdyn.errors.InstabilityError` (the time step does not
    resolve the impact, or the wall is too soft for it).

    Parameters
    ----------
    point : (3,) array, Angstrom
        A point of the plane.
    normal : (3,) array
        Normal pointing to the particles' side; normalised.
    stiffness : float or (n_materials,) array, optional
        K, eV/Angstrom^2 (LAMMPS' epsilon of the harmonic style).
    cutoff : float or (n_materials,) array, optional
        d_c, Angstrom.
    sticking : bool, default False
    indices : array of int or bool mask, optional
        Particles the wall acts on (default: all).
    """

    kind = "Wall"

    def __init__(self, point, normal, stiffness=None, cutoff=None, sticking=False, indices=None):
        super().__init__()
        p = np.array(point, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError("point", point, "a finite 3-vector (Angstrom)")
        self.point = p
        self.normal = _unit(normal, "normal")
        self.stiffness = _per_type(stiffness, "stiffness", "eV/Angstrom^2")
        self.cutoff = _per_type(cutoff, "cutoff", "Angstrom")
        if not isinstance(sticking, (bool, np.bool_)):
            raise InputError("sticking", sticking, "True or False")
        self.sticking = bool(sticking)
        self.index = None if indices is None else _rows(indices)
        self.energy = 0.0
        self.dissipated = 0.0
        self._K_t = None
        self._dc_t = None
        self._zeros = None
        self._buf = None
        self._nt = 0

    _NO_ROWS = np.zeros(0, np.int64)

    def resolve(self, atoms):
        """Fix K and d_c per material id (defaults from ``atoms.calc``); returns (K_t, dc_t)."""
        if self._K_t is not None:
            return self._K_t, self._dc_t
        K, dc = self.stiffness, self.cutoff
        if (K is None or dc is None) and hasattr(atoms.calc, "wall_defaults"):
            K_d, dc_d = atoms.calc.wall_defaults(atoms)      # e.g. MCA: from modulus and size
            K = np.asarray(K_d, float) if K is None else K
            dc = np.asarray(dc_d, float) if dc is None else dc
        if K is None or dc is None:
            calc = atoms.calc
            if hasattr(calc, "setup") and hasattr(calc, "potentials"):
                calc.setup(atoms)
            pots = getattr(calc, "potentials", None)
            if not pots:
                raise InputError("stiffness" if K is None else "cutoff", None,
                                 "a value: the defaults (2K = -f'(r0), d_c = r0/2) need a ClusterDynamics "
                                 "calculator's pair law")
            if K is None:
                K = np.array([0.5 * float(p.stiffness(p.r0)) for p in pots])
            if dc is None:
                dc = np.array([0.5 * float(p.r0) for p in pots])
        nt = max(K.size, dc.size)
        if K.size not in (1, nt) or dc.size not in (1, nt):
            raise InputError("stiffness", K.tolist(), f"one value or one per material ({nt}) like cutoff")
        self._K_t = np.ascontiguousarray(np.broadcast_to(K, (nt,)), dtype=float)
        self._dc_t = np.ascontiguousarray(np.broadcast_to(dc, (nt,)), dtype=float)
        return self._K_t, self._dc_t

    def _types(self, atoms):
        n = len(atoms)
        if self._K_t.size == 1:
            if self._zeros is None or self._zeros.shape[0] != n:
                self._zeros = np.zeros(n, np.int64)
            return self._zeros
        mid = atoms.arrays.get("material")
        if mid is None:
            raise InputError("atoms.arrays['material']", None, "material ids for a wall with per-material K")
        mid = np.ascontiguousarray(mid, dtype=np.int64)
        if n and (mid.min() < 0 or mid.max() >= self._K_t.size):
            raise InputError("atoms.arrays['material']", f"ids {mid.min()}..{mid.max()}",
                             f"ids in 0..{self._K_t.size - 1} (one wall stiffness per material)")
        return mid

    def _rows_arg(self):
        return self._NO_ROWS if self.index is None else self.index

    def adjust_forces(self, atoms, forces):
        K_t, dc_t = self.resolve(atoms)
        types = self._types(atoms)
        x = np.ascontiguousarray(atoms.arrays["positions"], dtype=float)
        n = len(atoms)
        if self._buf is None or self._buf[0].shape[0] != n:
            self._buf = (np.empty(n, np.int64), np.empty((n, 3)))
        touched, extra = self._buf
        f = forces if _is_f64(forces) else np.ascontiguousarray(forces, dtype=float)
        nt, e, fx, fy, fz, dmin, imin = wall_harmonic(x, f, self._rows_arg(), types, self.point, self.normal,
                                                      K_t, dc_t, self.sticking, touched, extra)
        if f is not forces:
            forces[:] = f
        self._nt = nt
        self.energy = e
        if dmin < 0.0:
            raise InstabilityError("a particle crossed behind the wall plane (the wall force did not stop it: "
                                   "lower the time step or stiffen the wall)", step=self._step_number(),
                                   particles=(imin,), quantity="distance from the wall plane",
                                   value=float(dmin), limit=0.0)
        t = self.time
        how = self._how(t)
        if how != "skip":
            self._commit(how, t, -np.array([fx, fy, fz]), 0.0)

    def kick_extra(self, momenta, h):
        if self._nt:
            kick_rows(momenta, self._buf[0], self._buf[1], self._nt, h)

    def adjust_momenta(self, atoms, momenta):
        if not self.sticking or not self._nt:
            return
        m = _masses(atoms)
        p = momenta if _is_f64(momenta) else np.ascontiguousarray(momenta, dtype=float)
        dp = np.zeros(3)
        de = stick_rows(p, np.ascontiguousarray(m, dtype=float), self._buf[0], self._nt, self.normal, dp)
        if p is not momenta:
            momenta[:] = p
        self.impulse = self.impulse + dp
        self.dissipated += de

    def adjust_potential_energy(self, atoms):
        K_t, dc_t = self.resolve(atoms)
        x = np.ascontiguousarray(atoms.arrays["positions"], dtype=float)
        scratch = np.empty(len(atoms), np.int64)
        return float(wall_energy(x, self._rows_arg(), self._types(atoms), self.point, self.normal, K_t, dc_t,
                                 scratch))

    def index_shuffle(self, atoms, ind):
        if self.index is not None:
            self.index = _shuffle(self.index, ind, "wall")
        self._nt = 0

    def get_state(self):
        K = self._K_t if self._K_t is not None else self.stiffness
        dc = self._dc_t if self._dc_t is not None else self.cutoff
        return {"kind": "Wall", "point": self.point.copy(), "normal": self.normal.copy(),
                "stiffness": None if K is None else np.array(K), "cutoff": None if dc is None else np.array(dc),
                "sticking": self.sticking, "index": None if self.index is None else self.index.copy(),
                "dissipated": float(self.dissipated), **self._records_state()}

    @classmethod
    def _from_state(cls, d):
        w = cls(d["point"], d["normal"], d.get("stiffness"), d.get("cutoff"), bool(d.get("sticking", False)),
                d.get("index"))
        w.dissipated = float(d.get("dissipated", 0.0))
        w._restore_records(d)
        return w

    def describe(self):
        K = self._K_t if self._K_t is not None else self.stiffness
        dc = self._dc_t if self._dc_t is not None else self.cutoff
        return {"kind": "Wall", "point_um": (self.point / units.um).tolist(), "normal": self.normal.tolist(),
                "law": "harmonic: E = K (d_c - d)^2 for d < d_c (LAMMPS fix wall/region harmonic)",
                "K_eV_per_A2": None if K is None else np.asarray(K).tolist(),
                "K_N_per_m": None if K is None else (np.asarray(K) / (units.J / units.m ** 2)).tolist(),
                "d_c_um": None if dc is None else (np.asarray(dc) / units.um).tolist(),
                "default_rule": "2K = -f'(r0), d_c = r0/2 of each material's pair law",
                "sticking": self.sticking,
                "n_particles": None if self.index is None else int(self.index.size),
                "impulse_N_s": (self.impulse / (units.N * units.s)).tolist(),
                "dissipated_J": float(self.dissipated / units.J)}

    def __repr__(self):
        return (f"Wall(point={self.point.tolist()}, normal={self.normal.tolist()}, "
                f"{'sticking' if self.sticking else 'frictionless'})")


_KINDS = {"Piston": Piston, "Wall": Wall, "Traction": Traction}


def from_state(d):
    """Rebuild a drive from its :meth:`Drive.get_state` dict (with its records and time state)."""
    if not isinstance(d, dict) or "kind" not in d:
        raise InputError("state", type(d).__name__, "a drive's get_state() dict")
    kind = d["kind"]
    if kind == "RigidWall":                    # files written before the drive family: a held layer
        p = Piston(d["index"], 0.0)
        p._restore_records(d)
        return p
    cls = _KINDS.get(kind)
    if cls is None:
        raise InputError("kind", kind, "one of " + ", ".join(_KINDS))
    return cls._from_state(d)
