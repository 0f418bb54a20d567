"""Drives and walls: ASE constraints that know the time (pistons with U(t), planar walls, tractions).

This module holds the family's protocol (:class:`Drive`, the layer base) and
:func:`from_state`; the members live beside it, one concept per module:

* :mod:`clusterdyn.md.histories` -- the U(t) laws (:class:`~clusterdyn.md.histories.Constant`,
  :class:`~clusterdyn.md.histories.Table`, :class:`~clusterdyn.md.histories.SmoothRamp`,
  :class:`~clusterdyn.md.histories.Function`);
* :mod:`clusterdyn.md.layer_drives` -- layers moved rigidly (:class:`~clusterdyn.md.layer_drives.Piston`,
  grips, :class:`~clusterdyn.md.layer_drives.Traction`);
* :mod:`clusterdyn.md.wall` -- the planar wall and its kernels (:class:`~clusterdyn.md.wall.Wall`).

Every member of the family is an ASE constraint (``adjust_positions``,
``adjust_momenta``, ``adjust_forces``, ``adjust_potential_energy``), so it
works in clusterdyn's :class:`~clusterdyn.md.DampedVerlet` (inside its fused
fast path) and in ASE's own dynamics (``ase.md.verlet.VelocityVerlet``), and
mixes with ASE's constraints (``FixAtoms``).

* :class:`~clusterdyn.md.layer_drives.Piston` -- a layer of particles moving rigidly at a prescribed
  velocity history U(t) in any direction: a constant, a piecewise-linear
  :class:`~clusterdyn.md.histories.Table` (also read from a CSV file), a :class:`~clusterdyn.md.histories.SmoothRamp` or a
  Python callable.  A held layer (particles at rest) is
  ``Piston(indices, 0.0)``.  ``lateral="free"`` prescribes only the velocity
  along the piston's direction (a grip that lets its particles move across
  it, as in a uniaxial test).
* :class:`~clusterdyn.md.wall.Wall` -- a planar rigid wall with any normal, as a smooth
  repulsive force on the particles (LAMMPS' ``fix wall/region ... harmonic``
  law), frictionless or sticking.
* :class:`~clusterdyn.md.layer_drives.Traction` -- a layer pressed along its normal by a prescribed
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
(exact for a :class:`~clusterdyn.md.histories.Table`, the midpoint value U(t_n + dt/2) for a
callable, which is exact for a linear ramp; exact for a :class:`~clusterdyn.md.histories.SmoothRamp`),
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
(pass a :class:`~clusterdyn.md.histories.Table` instead).  ``describe()`` gives a JSON-able summary in
display units (km/s, ns, um, GPa) for H5MD metadata.

LAMMPS
------
``lammps_form(atoms, dt, k)`` gives the drive's own commands for a LAMMPS
deck (:class:`~clusterdyn.md.lammps_form.LammpsForm`, what
:mod:`clusterdyn.io.lammps` writes) or refuses in one line the setting
that has none.  So a drive lives in one class: its physics, its
``describe()``, its state (``kind`` names it for :func:`from_state`: every
subclass that sets its own ``kind`` is found there) and its LAMMPS form.

The drives deliberately have no ``todict()``: ASE rebuilds only the
constraints it knows, so a ``.traj`` file with one would be unreadable.
"""

import copy

import copy

import numpy as np

from ..errors import InputError
from ._integrate import set_momenta, take_forces

__all__ = ["Drive", "from_state"]


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
    #: state kind -> class, filled by every subclass that names its own ``kind`` (:func:`from_state`)
    _KINDS = {}

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if "kind" in cls.__dict__:
            Drive._KINDS[cls.kind] = cls

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
        """The drive's state for a checkpoint (a dict with ``kind``, what :func:`from_state` reads)."""
        raise NotImplementedError

    def describe(self):
        """A JSON-able summary in display units (H5MD metadata, :mod:`clusterdyn.io.metadata`)."""
        raise NotImplementedError

    def lammps_form(self, atoms, dt, k):
        """The drive's LAMMPS commands (a :class:`~clusterdyn.md.lammps_form.LammpsForm`) as constraint
        ``k`` of ``atoms`` in a run of time step ``dt`` (ASE time); InputError, one line, naming what
        has no faithful LAMMPS form.  The base has none."""
        raise InputError("atoms.constraints", repr(self), f"drives with a LAMMPS form ({self.kind} has none)")


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


def from_state(d):
    """Rebuild a drive from its :meth:`Drive.get_state` dict (with its records and time state)."""
    if not isinstance(d, dict) or "kind" not in d:
        raise InputError("state", type(d).__name__, "a drive's get_state() dict")
    kind = d["kind"]
    if kind == "RigidWall":                    # files written before the drive family: a held layer
        p = Drive._KINDS["Piston"](d["index"], 0.0)
        p._restore_records(d)
        return p
    cls = Drive._KINDS.get(kind)
    if cls is None:
        raise InputError("kind", kind, "one of " + ", ".join(Drive._KINDS))
    return cls._from_state(d)
