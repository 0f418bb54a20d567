"""Layer drives: layers of particles moved rigidly by a prescribed velocity or stress.

* :class:`Piston` -- a layer moving at a prescribed velocity history U(t)
  (:mod:`clusterdyn.md.histories`) in any direction; ``Piston(indices, 0.0)``
  holds a layer at rest; ``lateral="free"`` prescribes only the velocity
  along the piston's direction (a grip).
* :class:`Traction` -- a layer pressed along its normal by a prescribed
  stress while driven at a prescribed tangential velocity.

The time, records and checkpoint protocol are :class:`~clusterdyn.md.drives.Drive`'s.
"""

import math

import numpy as np

from .. import units
from ..errors import InputError
from ._integrate import set_momenta_along, take_forces_along
from .drives import _Layer, _is_f64, _masses, _unit
from .histories import Constant, SmoothRamp, Table, as_history, describe_history, history_from_state
from .lammps_form import LammpsForm, group_lines, table_formulas, variable_lines

__all__ = ["Piston", "Traction"]


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
        return {"kind": self.kind, "index": self.index.copy(), "direction": self.direction.copy(),
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
             "velocity": describe_history(self.history, units.km_s, "km_s"),
             "lateral": self.lateral + (" (only the velocity along direction prescribed)" if self.free else
                                        " (the whole velocity prescribed)"),
             "evaluated": "layer drifts with the mean of U over each step; momenta at step ends hold U(t)",
             "impulse_N_s": (self.impulse / (units.N * units.s)).tolist(),
             "work_J": float(self.work / units.J)}
        return d

    def lammps_form(self, atoms, dt, k):
        """``fix move`` of the layer (group ``piston<k>``): ``move linear`` for a constant U, ``move
        variable`` for a :class:`~clusterdyn.md.histories.Table` (:meth:`_lammps_table`).  Refused:
        ``lateral='free'``, a callable or smooth-ramp U(t)."""
        if self.lateral != "fixed":
            raise InputError("atoms.constraints", repr(self), "pistons with lateral='fixed' (this export moves "
                             "the whole layer with fix move)")
        name = f"piston{k}"
        ids = np.asarray(self.index) + 1
        form = LammpsForm(groups=group_lines(name, ids), held=[name])
        if isinstance(self.history, Constant):
            v = (self.velocity_at(self.time) * units.VEL_TO_A_PER_PS).tolist()
            form.fixes.append(f"fix             move_{name} {name} move linear {v[0]!r} {v[1]!r} {v[2]!r}")
            form.meta[name] = {"kind": "Piston", "law": "constant", "n": int(ids.size), "velocity_A_per_ps": v}
        elif isinstance(self.history, Table):
            self._lammps_table(form, name, int(ids.size), dt)
        else:
            raise InputError("atoms.constraints", f"Piston with a {self.history.law} U(t) ({self.history!r})",
                             "a constant or Table history (pass a Table: a Python callable or a smooth "
                             "ramp has no LAMMPS form here)")
        return form

    def _lammps_table(self, form, name, n, dt):
        """``fix move variable`` with equal-style displacement ``X(t) - X(t0)`` (t = clusterdyn's time,
        ``time`` + the drive's time at export; exact for the piecewise-linear law, so the layer's
        positions are the same in both codes) and velocity ``(X(t) - X(t - dt))/dt``, the mean of U
        over the step just taken: the layer velocity clusterdyn's force pass sees (its half-step
        velocity, used by the pair damping), so the damping is the same too; LAMMPS' dumps therefore
        show that mean for the layer, not U(t) at the frame."""
        V = units.VEL_TO_A_PER_PS
        h = self.history
        vals = h.values[:, None] * self.direction[None, :] if h.values.ndim == 1 else h.values
        t_ps = h.times / units.PS
        t0_ps = self.time / units.PS
        if not dt > 0:
            raise InputError("dyn", None, "the dynamics (its time step) for a piston with a U(t) table")
        dt_ps = float(dt) * units.TIME_TO_PS
        svar = f"{name}_t"
        fixes = form.fixes
        fixes.append(f'variable        {svar} equal "time+{t0_ps!r}"')
        fixes.append(f'variable        {svar}m equal "time+{t0_ps!r}-{dt_ps!r}"')
        names = []
        for d, ax in enumerate("xyz"):
            _, x_terms = table_formulas(t_ps, vals[:, d] * V, t0_ps, f"v_{svar}")
            _, xm_terms = table_formulas(t_ps, vals[:, d] * V, t0_ps, f"v_{svar}m")
            fixes += variable_lines(f"{name}_d{ax}", x_terms)
            fixes += variable_lines(f"{name}_d{ax}m", xm_terms)
            fixes.append(f'variable        {name}_v{ax} equal "(v_{name}_d{ax}-v_{name}_d{ax}m)/{dt_ps!r}"')
            names.append((f"v_{name}_d{ax}", f"v_{name}_v{ax}"))
        fixes.append(f"fix             move_{name} {name} move variable "
                     + " ".join(q[0] for q in names) + " " + " ".join(q[1] for q in names))
        form.meta[name] = {"kind": "Piston", "law": "table", "n": n, "t0_ps": t0_ps,
                           "t_ps": t_ps.tolist(), "velocity_A_per_ps": (vals * V).tolist()}

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
        return {"kind": self.kind, "index": self.index.copy(), "normal": self.normal.copy(),
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
                "stress": describe_history(self.stress, units.GPa, "GPa"),
                "velocity": describe_history(self.history, units.km_s, "km_s"),
                "area_um2": None if self.area is None else self.area / units.um ** 2,
                "law": "rigid layer: free along normal under R.n - stress*area, tangential velocity prescribed",
                "impulse_N_s": (self.impulse / (units.N * units.s)).tolist(),
                "work_J": float(self.work / units.J)}

    def lammps_form(self, atoms, dt, k):
        """The rigid layer free along its normal (group ``traction<k>``, integrated by ``fix nve``):
        ``fix aveforce`` gives every particle of the layer the layer's mean force plus
        ``-stress(t) area / n`` along the normal (an equal-style variable of clusterdyn's time for a
        :class:`~clusterdyn.md.histories.Table` stress, exact for the piecewise-linear law; evaluated at
        the force pass, as :meth:`adjust_forces` does), ``fix setforce`` zeroes the tangential
        components (the tangential velocity stays zero).  With equal masses in the layer this is the
        rigid body's velocity Verlet of :meth:`adjust_forces`.  Refused in one line: a normal not along
        an axis, a tangential velocity, a stress law other than a constant or a Table, masses that
        differ within the layer, a layer already moving across its normal."""
        ax = int(np.argmax(np.abs(self.normal)))
        if abs(abs(self.normal[ax]) - 1.0) > 1e-12:
            raise InputError("atoms.constraints", repr(self), "a traction whose normal is along x, y or z "
                             "(fix aveforce/setforce act on components)")
        if self.history.max_abs() != 0.0:
            raise InputError("atoms.constraints", repr(self), "a traction without tangential velocity (a "
                             "prescribed tangential U(t) has no form with fix aveforce here)")
        m = _masses(atoms)[self.index]
        if m.size == 0 or np.ptp(m) > 1e-12 * m.max():
            raise InputError("atoms.constraints", repr(self), "a traction layer of equal masses (fix aveforce "
                             "gives every particle the same force)")
        self._resolve(atoms)
        name = f"traction{k}"
        ids = np.asarray(self.index) + 1
        n = int(ids.size)
        form = LammpsForm(groups=group_lines(name, ids))
        sign = -float(self.normal[ax])                       # the stress presses along -normal
        scale = sign * self.area / n                         # eV/Angstrom per particle per (eV/Angstrom^3)
        if isinstance(self.stress, Constant):
            expr = f"{float(self.stress.value) * scale!r}"
        elif isinstance(self.stress, Table):
            t_ps = self.stress.times / units.PS
            t0_ps = self.time / units.PS
            svar = f"{name}_t"
            form.fixes.append(f'variable        {svar} equal "time+{t0_ps!r}"')
            u_terms, _ = table_formulas(t_ps, self.stress.values * scale, t0_ps, f"v_{svar}")
            form.fixes += variable_lines(f"{name}_f", u_terms)
            expr = f"v_{name}_f"
        else:
            raise InputError("atoms.constraints", f"Traction with a {self.stress.law} stress ({self.stress!r})",
                             "a constant or Table stress (a callable has no LAMMPS form here)")
        comps = ["NULL"] * 3
        comps[ax] = expr
        zero = ["0.0"] * 3
        zero[ax] = "NULL"
        form.fixes.append(f"fix             ave_{name} {name} aveforce " + " ".join(comps))
        form.fixes.append(f"fix             tan_{name} {name} setforce " + " ".join(zero))
        form.meta[name] = {"kind": "Traction", "n": n, "axis": ax, "area_A2": float(self.area),
                           "stress": describe_history(self.stress, units.GPa, "GPa")}
        return form

    def __repr__(self):
        return (f"Traction({len(self.index)} particles, normal={self.normal.tolist()}, stress={self.stress!r}, "
                f"velocity={self.history!r})")
