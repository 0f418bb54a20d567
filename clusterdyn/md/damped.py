"""DampedVerlet: velocity Verlet with the anti-dusting pair damping of CD eq. (6).

.. math::

    m \\dot v_i = \\sum_k f(r_k - r_i) - \\sum_k \\eta_{ik} (v_i - v_k),
    \\qquad \\eta = m\\Gamma,\\ \\Gamma = c_0/(J a)

for pairs within the cutoff.  The damping force is evaluated in the same
pair loop as the conservative one (one neighbour walk per step) with the
half-step velocities of velocity Verlet, like LAMMPS' dpd/ext/tstat at zero
temperature.  With ``J=None`` the dynamics runs the conservative kernel only:
the damping term is not in the compiled loop at all.

With the Cluster Dynamics calculator the step runs on its engine
(:class:`clusterdyn.engine.CDEngine`): the first half kick and the drift fused with the
gathers of the pair pass, the second half kick inside it.  With any other ASE calculator (and
no damping) it is plain velocity Verlet.  What else acts in a step (removal outside a region,
sorting, extra force terms) is attached as pieces (:mod:`clusterdyn.md.pieces`); the energy
balance is :class:`clusterdyn.md.ledger.EnergyLedger`.
"""

import math
import time
import warnings

import numpy as np
from ase.md.md import MolecularDynamics

from .. import units
from ..buffers import grown, permute
from ..calculators.cluster import ClusterDynamics
from ..errors import InputError, InstabilityError
from ..parallel import use_threads
from . import _integrate as I
from .drives import Drive, _Layer
from .ledger import EnergyLedger
from .pieces import PIECE_KINDS
from .region import RegionOfInterest, Removal, _compact
from .sorting import Sorting
from .stability import (TIMESTEP_FACTOR, StiffnessCheck, default_timestep, pair_stability_limit,  # noqa: F401
                        stability_limit)

#: a particle moving more than this many r0 in one step stops the run
MAX_STEP_DISPLACEMENT = 0.25


#: a time step below this fraction of the stability limit is warned about
TINY_STEP = 1e-3
#: masses within this factor of the clusters' are accepted
MASS_FACTOR = 10.0


def _on_engine(calc):
    """Whether ``calc`` runs on a Cluster Dynamics engine (the fused steps; damping, sorts and
    the default time step need one)."""
    return isinstance(calc, ClusterDynamics)

class DampedVerlet(MolecularDynamics):
    """Velocity Verlet for clusters, with optional pair damping (CD eq. 5-6).

    Parameters
    ----------
    atoms : ase.Atoms
        With a :class:`~clusterdyn.calculators.ClusterDynamics` calculator (any ASE
        calculator works when ``J=None``).
    timestep : float, optional
        ASE time units.  Default :func:`default_timestep` with the fastest
        drive of ``atoms.constraints`` (its ``max_speed()``; a callable U(t) states none:
        give the time step then).  Must be below the stability limit.
    J : float or None, default 50
        Damping Gamma = c0/(J r0), J in 10..100 in the method; ``None`` = off.
    check_interval : int, default 1
        Steps between stiffness checks (time step against the limit at the
        current smallest pair distance).
    region : RegionOfInterest, optional
        Remove the particles that leave it (checked every ``remove_interval``
        steps, at the end of a step).  The Atoms shrink (every array and the
        constraints' indices follow; particles of pistons and tractions are
        kept); :attr:`removed` and :meth:`energy_ledger` book the kinetic
        energy, pair energy (the potential energy before minus after) and
        momentum they take away; the forces are recomputed without them.
        Output writers that map particles by ``atoms.arrays['id']`` (the
        H5MD writer) keep fixed-size frames with fill values; an ``id`` array
        is added (``0..N-1``) when the Atoms have none.
    remove_interval : int, default 10
        Steps between the region checks.
    sort_interval : int or None, default None
        Every ``sort_interval`` steps (at the end of a step), sort the Atoms into
        the neighbour list's cell order (:meth:`sort_atoms`), as LAMMPS'
        ``atom_modify sort``: the per-particle passes of a step then read
        memory nearly in sequence, which keeps the speed of samples whose
        particles mix (debris clouds: CHANGELOG.md, "Sorting the
        Atoms").  Particle indices change (every array and the constraints'
        indices follow, as for ``region``); ``atoms.arrays['id']`` names the
        particles (added, ``0..N-1``, when the Atoms have none) and the H5MD
        writer orders its rows by it.  None (default): the order is never
        changed.  Needs the ClusterDynamics calculator.
    trajectory, logfile, loginterval :
        As for ASE's MolecularDynamics (``append_trajectory=True`` appends).  Each
        trajectory frame carries the potential energy and the conservative
        forces (without damping) on a SinglePointCalculator, and the material
        ids as ASE ``tags`` (which ``.traj`` keeps: ``arrays['material']`` it
        drops), so that ``ase.io.read`` gives Atoms a ClusterDynamics takes
        again (it reads the ids from the tags when ``arrays['material']`` is
        missing; the names and r0 travel in ``atoms.info``).

    Attributes
    ----------
    forces : (N, 3) array
        Total forces of the last step (with damping if on; piston rows zeroed).
    potential_energy : float
        Shifted pair energy of the current positions plus that of the constraints and attached
        force terms, eV.  The steps' force pass takes the pair energy only on the steps after
        which an observer is called (where the calculator is also given the step's results, so
        that an H5MD frame needs no pass); otherwise it is computed (one conservative pass) when
        first read after a step.
    pieces : list of :class:`~clusterdyn.md.pieces.Piece`
        What acts at fixed points of a step besides Verlet and damping (removal, sorting, extra
        force terms): :meth:`attach_piece`.
    """

    def __init__(self, atoms, timestep=None, J=50, *, check_interval=1, region=None, remove_interval=10,
                 sort_interval=None, trajectory=None, logfile=None, loginterval=1, **kwargs):
        calc = atoms.calc
        if J is not None:
            try:
                J = float(J)
            except (TypeError, ValueError):
                raise InputError("J", J, "a positive number (Gamma = c0/(J r0)) or None for no damping") from None
            if not (J > 0 and math.isfinite(J)):
                raise InputError("J", J, "a positive number (Gamma = c0/(J r0)) or None for no damping")
        limit = self._calc_limit(atoms, calc, J)
        if region is not None and not isinstance(region, RegionOfInterest):
            raise InputError("region", region, "a RegionOfInterest (or None)")
        if region is not None:
            per = np.asarray(atoms.pbc, dtype=bool)
            if np.any(np.isfinite(region.lo[per])) or np.any(np.isfinite(region.hi[per])):
                raise InputError("region", repr(region), "no bound along the periodic axes "
                                 f"{[ax for ax, p in zip('xyz', per) if p]}")
            self._renumbering(atoms, "region=")
        try:
            remove_interval = int(remove_interval)
        except (TypeError, ValueError):
            raise InputError("remove_interval", remove_interval, "a positive number of steps") from None
        if remove_interval < 1:
            raise InputError("remove_interval", remove_interval, "a positive number of steps")
        self.pieces = []
        self._remove_interval = remove_interval
        self.J = J
        self._take_calc(calc, limit)
        speeds = [c.max_speed() for c in atoms.constraints if isinstance(c, Drive)]
        u_max = max([s for s in speeds if s is not None] + [0.0])
        if timestep is None:
            if not _on_engine(calc):
                raise InputError("timestep", None, "a time step (no default without ClusterDynamics)")
            if None in speeds:
                raise InputError("timestep", None, "a time step: the default needs the drives' largest speed, "
                                 "which a callable U(t) does not state (give timestep= or a Table)")
            timestep = default_timestep(calc, u_max)
        try:
            ts = float(timestep)
        except (TypeError, ValueError):
            raise InputError("timestep", timestep, "a positive time (ASE units)") from None
        if not (ts > 0 and math.isfinite(ts)):
            raise InputError("timestep", timestep, "a positive time (ASE units)")
        if self.stability_limit is not None and ts > self.stability_limit:
            raise InputError("timestep", ts, f"<= {self.stability_limit:.6g} (velocity-Verlet stability "
                             "limit 2/omega_max of the lattice at rest)",
                             hint=f"the default is {default_timestep(calc, u_max):.6g}")
        if _on_engine(calc):
            self._check_masses(atoms, calc)
            if self.stability_limit is not None and ts < TINY_STEP * self.stability_limit:
                warnings.warn(f"DampedVerlet: timestep {ts / units.PS:.4g} ps is {ts / self.stability_limit:.2g} of "
                              f"the stable step {self.stability_limit / units.PS:.4g} ps: the run takes "
                              f"{self.stability_limit / ts:.2g} times more steps than it needs (clusters are "
                              "micrometres, not atoms: leave timestep=None for the default "
                              f"{default_timestep(calc, u_max) / units.PS:.4g} ps)", stacklevel=2)
        append = bool(kwargs.pop("append_trajectory", False))
        super().__init__(atoms, ts, trajectory=None, logfile=logfile, loginterval=loginterval,
                         **kwargs)
        self._trajectory = None
        if trajectory is not None:
            if hasattr(trajectory, "write"):
                self._trajectory = trajectory
            else:
                from ase.io.trajectory import Trajectory
                self._trajectory = self.closelater(Trajectory(trajectory, mode="a" if append else "w"))
            self.trajectory = self._trajectory
            self.attach(self._write_trajectory, interval=loginterval)
        self.check_interval = int(check_interval)
        self._own_forces = False
        self._fbuf = None
        self.timings = {"forces": 0.0, "integrate": 0.0}
        #: energy the pair damping has removed, eV (dt times the dissipated power
        #: ``sum eta |v_i - v_j|^2`` of each step's force pass, half-step velocities)
        self.damping_loss = 0.0
        self._dissipation = 0.0
        self.ledger = EnergyLedger(self)
        self._removal = self._sorting = None
        if region is not None:
            self._removal = self.attach_piece(Removal(region, remove_interval))
        if sort_interval is not None:
            self.set_sort_interval(sort_interval)
        self._drives()

    def _write_trajectory(self):
        """A trajectory frame: energy and conservative forces, material ids as tags."""
        atoms = self.atoms
        snap = atoms.copy()
        if "material" in atoms.arrays:
            snap.set_tags(np.asarray(atoms.arrays["material"], dtype=int))
        props = {}
        if atoms.calc is not None:
            props["energy"] = atoms.calc.get_property("energy", atoms)
            props["forces"] = atoms.calc.get_property("forces", atoms)
        self._trajectory.write(snap, **props)

    @staticmethod
    def _check_masses(atoms, calc):
        """Refuse masses far from the clusters' ``rho0 r0^3/sqrt(2)`` (Atoms built without
        clusterdyn.build keep the atomic masses of their symbols, 1e-14 of a cluster's): a factor
        MASS_FACTOR either way is allowed (porous samples scale their masses)."""
        m = atoms.get_masses()
        if not len(m):
            return
        want = np.array([p.mass for p in calc.potentials])[calc._check_types(atoms)]
        ratio = m / want
        bad = np.flatnonzero(~((ratio > 1.0 / MASS_FACTOR) & (ratio < MASS_FACTOR)))
        if bad.size:
            k = int(bad[0])
            raise InputError("atoms masses", f"{m[k]:.4g} amu (particle {k}, {bad.size} such)",
                             f"cluster masses within a factor {MASS_FACTOR:g} of rho0 r0^3/sqrt(2) = "
                             f"{want[k]:.4g} amu for its material",
                             hint="Atoms not made by clusterdyn.build keep their symbols' atomic masses: "
                                  "set them with atoms.set_masses(...) (docs/ase_users.md)")

    # -- pieces ----------------------------------------------------------------------
    def attach_piece(self, piece):
        """Attach a :class:`~clusterdyn.md.pieces.Piece` (kept in the order of its ``order``
        attribute, 0 by default: force terms first, then removal, then sorting); returns it."""
        piece.bind(self)
        self.pieces.append(piece)
        self.pieces.sort(key=lambda q: getattr(q, "order", 0))
        self._epot = None
        return piece

    @property
    def region(self):
        """The :class:`RegionOfInterest` whose leavers are removed, or None."""
        return None if self._removal is None else self._removal.region

    @property
    def remove_interval(self):
        return self._remove_interval if self._removal is None else self._removal.interval

    _remove_interval = 10

    @property
    def removed(self):
        """What the removed particles took away since the start (:attr:`Removal.removed`)."""
        if self._removal is None:
            return {"count": 0, "mass": 0.0, "kinetic": 0.0, "potential": 0.0, "momentum": np.zeros(3)}
        return self._removal.removed

    @property
    def sort_interval(self):
        return None if self._sorting is None else self._sorting.interval

    @property
    def nsorts(self):
        """Sorts of the Atoms done (:meth:`sort_atoms`)."""
        return 0 if self._sorting is None else self._sorting.nsorts

    def set_sort_interval(self, interval):
        """Sort the Atoms every ``interval`` steps from now on (None: never), as the
        ``sort_interval`` argument does (checked the same way)."""
        interval = self._sort_interval(self.atoms, interval)
        if interval is None:
            if self._sorting is not None:
                self.pieces.remove(self._sorting)
                self._sorting = None
        elif self._sorting is None:
            self._sorting = self.attach_piece(Sorting(interval))
        else:
            self._sorting.interval = interval

    def remove_outside(self):
        """Take the particles outside :attr:`region` out of the Atoms now; returns how many
        (:meth:`clusterdyn.md.region.Removal.remove`; 0 without a region)."""
        return 0 if self._removal is None else self._removal.remove()

    def start_ledger(self):
        """Take the present state as the start of :meth:`energy_ledger` (done at the first step)."""
        self.ledger.start()

    def energy_ledger(self):
        """Where the energy went since the ledger's start (eV): :class:`~clusterdyn.md.ledger.EnergyLedger`."""
        return self.ledger.report()

    # -- the calculator ------------------------------------------------------------------
    @staticmethod
    def _calc_limit(atoms, calc, J):
        """The calculator checked for these Atoms and damping ``J`` (ClusterDynamics, set up,
        when J is given); returns its stability limit (None for another calculator)."""
        if _on_engine(calc):
            calc.setup(atoms)
            return stability_limit(calc)
        if J is not None:
            raise InputError("atoms.calc", type(calc).__name__,
                             "a ClusterDynamics calculator when damping is on (J given)")
        return None

    def _adopt_calc(self, calc):
        """Take up a calculator put on the Atoms after the dynamics was made (as ASE's
        dynamics use whatever ``atoms.calc`` is), checked as at construction (damping and
        sorts need ClusterDynamics), and the time step against the new calculator's
        stability limit.  The forces are recomputed with it."""
        limit = self._calc_limit(self.atoms, calc, self.J)
        self._sort_interval(self.atoms, self.sort_interval)
        if limit is not None and self.dt > limit:
            raise InputError("atoms.calc", type(calc).__name__, f"a calculator whose stability limit "
                             f"({limit:.6g}) is at least the dynamics' time step {self.dt:.6g}")
        self._take_calc(calc, limit)

    def _take_calc(self, calc, limit):
        """Use ``calc`` (checked, with its stability limit ``limit``): its damping matrix for
        :attr:`J`, and nothing kept of the previous calculator's (forces, energy, safe distances)."""
        self.calc = calc
        #: the calculator when it runs on a Cluster Dynamics engine (the fused steps), else None
        self._cd = calc if _on_engine(calc) else None
        self.stability_limit = limit
        self._eta = calc.damping_matrix(self.J) if self.J is not None else None
        self._stiffness = None
        self.forces = None
        self._epot = None
        self._pair_energy = None

    @classmethod
    def _sort_interval(cls, atoms, interval):
        """``interval`` checked (a positive whole number of steps, or None) and the Atoms readied
        for sorts (:meth:`_renumbering`); returns it as an int, or None."""
        if interval is None:
            return None
        try:
            ok = int(interval) == interval and int(interval) >= 1
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise InputError("sort_interval", interval, "a positive whole number of steps, or None")
        if not _on_engine(atoms.calc):
            raise InputError("atoms.calc", type(atoms.calc).__name__, "a ClusterDynamics calculator with sort_interval")
        cls._renumbering(atoms, "sort_interval=")
        return int(interval)

    @staticmethod
    def _renumbering(atoms, what, add_id=True):
        """Ready the Atoms for runs that change particle indices (``what``: removals or sorts):
        every constraint must follow them (``index_shuffle``), and an ``id`` array (``0..N-1``)
        names the particles when the Atoms have none."""
        for c in atoms.constraints:
            if not hasattr(c, "index_shuffle"):
                raise InputError("atoms.constraints", type(c).__name__,
                                 f"constraints that follow renumbered particles (index_shuffle) with {what}")
        if add_id and "id" not in atoms.arrays:
            atoms.new_array("id", np.arange(len(atoms), dtype=np.int64))

    def _drives(self):
        """The drives among the constraints, bound to this dynamics (binds new ones)."""
        ds = []
        for c in self.atoms.constraints:
            if isinstance(c, Drive):
                if c._dyn is not self:
                    c.bind(self)
                ds.append(c)
        return ds

    def _constraint_energy(self):
        e = 0.0
        for c in self.atoms.constraints:
            if hasattr(c, "adjust_potential_energy"):
                e += c.adjust_potential_energy(self.atoms)
        return e

    def todict(self):
        d = super().todict()
        d.update({"J": self.J, "stability_limit": self.stability_limit})
        if self.sort_interval is not None:
            d["sort_interval"] = self.sort_interval
        if self.region is not None:
            d.update({"region": self.region.todict(), "remove_interval": self.remove_interval})
        return d

    @property
    def masses(self):
        """The Atoms' masses as a column ((N, 1), amu): ASE's MolecularDynamics attribute, made
        when asked (the integrator keeps only the inverse masses, so a sort or a removal has one
        array fewer to follow)."""
        return self.atoms.get_masses()[:, None]

    @masses.setter
    def masses(self, value):
        # ASE's MolecularDynamics.__init__ sets it from the Atoms: accepted when it is theirs
        m = self.atoms.get_masses()
        if np.shape(value) not in (m.shape, (m.shape[0], 1)) or not np.array_equal(np.ravel(value), m):
            raise InputError("masses", "an array other than the Atoms' masses",
                             "the Atoms' masses (DampedVerlet integrates with atoms.get_masses(): set them there)")

    def _invm(self):
        m = self.atoms.get_masses()
        if np.any(m <= 0):
            raise InputError("masses", m[m <= 0][:3].tolist(), "positive masses")
        return 1.0 / m

    def _extra_energy(self):
        """The potential energy of the constraints and of the attached force terms, eV."""
        e = self._constraint_energy()
        for q in self.pieces:
            if q.adds_forces:
                e += q.energy(self.atoms)
        return e

    # -- forces ----------------------------------------------------------------------
    def _compute_forces(self, kick=None, advanced=False):
        """Forces at the current positions (constraints applied).

        ``kick = h``: the second half kick, ``momenta += h * forces``: the
        calculator's forces are kicked first (inside the engine's pass), then the attached
        force terms add and kick theirs, then the constraints adjust the forces, then the drives
        that added forces (walls) kick their rows with what they added.  Kicks are linear, so
        this is the kick with the total forces; its order of operations is the same in every
        path (fused or not, fresh or restarted).  ``advanced``: the engine's :meth:`advance`
        made these positions (its gathers are used).
        """
        atoms = self.atoms
        drives = self._drives()
        # the step these positions belong to: a step's force pass (the one with the second half
        # kick) evaluates the positions of the step under way, which errors name
        at = self.nsteps if kick is None else self.nsteps + 1
        t0 = time.perf_counter()
        for q in self.pieces:
            if q.adds_forces:
                q.before_forces(atoms, kick)
        if self._cd is not None:
            forces = self._engine_forces(at, kick, advanced)
        else:
            forces = np.ascontiguousarray(atoms.get_forces(apply_constraint=False), dtype=float)
            self._pair_energy = None
            self.potential_energy = atoms.get_potential_energy()
            if kick is not None:
                I.kick(atoms.arrays["momenta"], forces, kick)
        for q in self.pieces:
            if q.adds_forces:
                q.add_forces(atoms, forces, kick)
        for c in atoms.constraints:
            c.adjust_forces(atoms, forces)
        if kick is not None:
            for d in drives:
                d.kick_extra(atoms.arrays["momenta"], kick)
        self._own_forces = True
        self.timings["forces"] += time.perf_counter() - t0
        return forces

    def _engine_forces(self, at, kick, advanced):
        """The engine's pass for :meth:`_compute_forces` (step ``at``)."""
        atoms = self.atoms
        damping = None
        if self._eta is not None:
            damping = (atoms.arrays["momenta"], self._invm_n, self._eta)
        # one force buffer, rewritten at each step (nothing reads the old forces once the first
        # half kick is done); it grows, never shrinks: removing particles takes a view of it
        n = len(atoms)
        self._fbuf = grown(self._fbuf, n)
        frame = self._observed(at)
        # an observed damped step keeps the conservative forces apart in the same pair loop
        out = self.calc.compute(atoms, damping=damping, step=at, out=self._fbuf[:n], virial=False, energy=frame,
                                advanced=advanced, kick=None if kick is None else (atoms.arrays["momenta"], kick),
                                conservative=frame and damping is not None)
        self._epot = None
        self._pair_energy = out["energy"]
        self._dissipation = out.get("dissipation", 0.0)
        if frame:
            # an observer reads this step: the calculator gets the pass's energy and conservative
            # forces (undamped: the step's own), so that it needs no pass of its own
            self.calc.publish(atoms, out["energy"], out["forces"] if damping is None else out["conservative"])
        if self.stability_limit is not None and self.nsteps % self.check_interval == 0:
            if self._stiffness is None or self._stiffness.dt != self.dt:
                self._stiffness = StiffnessCheck(self.calc, self.dt)
            self._stiffness(self.calc.last_stats, atoms.arrays.get("material"), at)
        return out["forces"]

    @property
    def potential_energy(self):
        if self._epot is None and self.forces is not None and self._cd is not None:
            e = self._pair_energy
            if e is None:
                e = self.calc.compute(self.atoms, step=self.nsteps, virial=False, forces=False)["energy"]
            self._epot = e + self._extra_energy()
        return self._epot

    @potential_energy.setter
    def potential_energy(self, value):
        self._epot = value

    def _observed(self, n):
        """Whether an observer is called after step ``n`` (ASE's rule, ``call_observers``)."""
        for _, interval, _, _ in self.observers:
            if (interval > 0 and n % interval == 0) or (interval <= 0 and n == -interval):
                return True
        return False

    def _refresh_properties(self):
        # forces are kept by the dynamics; observers that need ASE properties ask the calculator
        if self.forces is None:
            self._invm_n = self._invm()
            self.forces = self._compute_forces()

    # -- the step ----------------------------------------------------------------------
    def step(self, forces=None):
        """One velocity-Verlet step; returns the forces at the new positions (with ClusterDynamics
        the dynamics' own buffer, rewritten by the next step: copy it to keep it).

        With the ClusterDynamics calculator and drives of
        :mod:`clusterdyn.md.drives` only (any mix of pistons, walls and
        tractions, or none), the first half kick and the drift run fused with
        the engine's gathers and the second half kick inside its force
        pass (the fast path).  The drives set their layers' momenta before the
        first kick (their forces are zero, so the kick leaves them) and after
        the second; a wall's forces, added by ``adjust_forces``, get their
        half kick on the touched rows after the calculator's.  Other ASE
        constraints (``FixAtoms`` ...) take the separate passes, with the
        drift through ``atoms.set_positions`` so that their
        ``adjust_positions`` applies.  The attached pieces end the step.
        """
        atoms = self.atoms
        if atoms.calc is not self.calc:
            self._adopt_calc(atoms.calc)
        if self.forces is None or forces is not None:
            self._invm_n = self._invm()
            self.forces = self._compute_forces() if forces is None else forces
            self._own_forces = forces is None
        t0 = time.perf_counter()
        use_threads(len(atoms))
        p = atoms.arrays["momenta"]
        h = 0.5 * self.dt
        cons = atoms.constraints
        drives = self._drives()
        for d in drives:
            d.begin_step()
        for c in cons:
            c.adjust_momenta(atoms, p)
        res = self._kick_drift(p, h, fused=self._own_forces and len(drives) == len(cons))
        for d in drives:
            d.end_drift()
        self._check_speed(*res[:2])
        self.timings["integrate"] += time.perf_counter() - t0
        self.forces = self._compute_forces(kick=h, advanced=res[2])
        self.damping_loss += self.dt * self._dissipation
        t0 = time.perf_counter()
        for c in cons:
            c.adjust_momenta(atoms, p)
        self.timings["integrate"] += time.perf_counter() - t0
        for q in self.pieces:
            q.end_step()
        return self.forces

    def _kick_drift(self, p, h, fused):
        """The first half kick and the drift: fused with the engine's gathers when ``fused`` (no
        foreign constraint) and the engine is ready, else the separate passes.  Returns (max v^2,
        its particle, fused)."""
        atoms = self.atoms
        invm = self._invm_n
        eng = None if self._cd is None or not fused else self.calc.engine
        res = None if eng is None else eng.advance(atoms.arrays["positions"], p, self.forces, invm, h, self.dt,
                                                   self._eta is not None)
        if res is not None:
            return res[0], res[1], True
        I.kick(p, self.forces, h)
        if len(self._drives()) != len(atoms.constraints):
            atoms.set_positions(atoms.positions + self.dt * p * invm[:, None])
            v2 = (p * p).sum(axis=1) * invm ** 2
            k = int(np.argmax(v2))
            return v2[k], k, False
        v2max, k = I.drift(atoms.arrays["positions"], p, invm, self.dt)
        return v2max, k, False

    # -- renumbering the particles (sorting, removal) ----------------------------------
    def sort_atoms(self):
        """Reorder the Atoms into the neighbour list's row (cell) order now; returns True if done.

        New particle k is the particle of the list's sorted row k: every array of
        the Atoms, the constraints' indices, the forces, the attached pieces and the
        engine's list (reference positions, bricks) follow, permuted in place
        (nothing of N's size is allocated: the scratch is the list's, free between
        builds), and the list stays valid: no rebuild, and the steps until
        the next build are the same bit for bit (in ``id`` order) as without
        the sort.  The next build's cell sort is stable in the new order, so
        from there the pair sums may add in another order (rounding).  False
        when the list has not been built over the current particles yet, and
        when the Atoms are in its row order already (no build since the last
        sort: nothing to move).
        """
        atoms = self.atoms
        n = len(atoms)
        ready = None if self._cd is None or self.calc.engine is None else self.calc.engine.sort_order(n)
        if ready is None:
            return False
        order, scratch = ready              # new particle k: the list's sorted row k
        self._renumbering(atoms, "sort_atoms()", add_id=False)
        if self.forces is None:
            self._refresh_properties()
        cons = list(atoms.constraints)
        atoms.set_constraint()
        for c in cons:
            c.index_shuffle(atoms, order)
        for name in list(atoms.arrays):
            permute(atoms.arrays[name], order, scratch)
        atoms.set_constraint(cons)
        for a in (self.forces, self._invm_n):
            if a is not None and a.shape[0] == n:
                permute(a, order, scratch)
        for q in self.pieces:
            q.reindexed(order)
        self.calc.engine.reindex(order, scratch)
        self.calc.reindexed()
        if self._sorting is not None:
            self._sorting.nsorts += 1
        return True

    def take_out(self, out, keep):
        """Take the particles where ``out`` is True out of the Atoms (``keep``: the others'
        indices, ascending); returns the potential energy (eV) before and after.

        With the Cluster Dynamics calculator the pair energy is that of the listed pairs
        with a removed particle (one pass over the list,
        :meth:`~clusterdyn.calculators.ClusterDynamics.pairs_touching`), plus the
        constraints' and force terms' energy before minus after, and the engine's list is
        compacted, not rebuilt.  Without constraints and force terms, the same pass takes those
        pairs' forces (and damping, at the step's velocities) out of the step's forces, which
        then are the forces of the particles left, with no force pass over them; otherwise the
        forces are computed afresh.  With another calculator, the potential energy before minus
        after, and the forces afresh.
        """
        atoms = self.atoms
        cd = self._cd is not None
        lost = None
        if cd and not atoms.constraints and self._own_forces and not any(q.adds_forces for q in self.pieces):
            # the step's forces less the pairs of the removed particles: no pass over the rest
            lost = self.calc.pairs_touching(atoms, out, forces=self.forces, damped=self._eta is not None)
        incremental = lost is not None
        if cd and lost is None:
            lost = self.calc.pairs_touching(atoms, out)
        u_before = lost[0] + self._extra_energy() if cd else self.potential_energy
        cons = list(atoms.constraints)
        atoms.set_constraint()
        for c in cons:
            c.index_shuffle(atoms, keep)
        for name in list(atoms.arrays):
            atoms.arrays[name] = _compact(atoms.arrays[name], keep)
        atoms.set_constraint(cons)
        if cd:
            self.calc.removed(~out)
        elif atoms.calc is not None and hasattr(atoms.calc, "reset"):
            atoms.calc.reset()
        for q in self.pieces:
            q.compacted(keep)
        self._invm_n = self._invm()
        self._epot = self._pair_energy = None
        if incremental:
            self.forces = _compact(self.forces, keep)
            self._dissipation -= lost[1]
        else:
            self.forces = self._compute_forces()
        self._own_forces = True
        # (Cluster Dynamics: the pairs left are not summed, so their energy is not needed)
        u_after = self._extra_energy() if cd else self.potential_energy
        return u_before, u_after

    def _check_speed(self, v2max, k):
        if not math.isfinite(v2max):
            raise InstabilityError("non-finite velocity", step=self.nsteps + 1, particles=(k,),
                                   quantity="speed", value=float("nan"))
        if self._cd is not None:
            r0 = min(p.r0 for p in self.calc.potentials)
            disp = math.sqrt(v2max) * self.dt
            if disp > MAX_STEP_DISPLACEMENT * r0:
                raise InstabilityError(
                    "a particle moves too far in one step for the pair forces to be resolved; "
                    "lower the time step", step=self.nsteps + 1, particles=(k,),
                    quantity="displacement per step / r0", value=disp / r0, limit=MAX_STEP_DISPLACEMENT)

    def run(self, steps=50, progress=False, desc=None):
        """Run ``steps`` steps; ``progress=True`` shows a tqdm bar with time left."""
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise InputError("steps", steps, "a whole number of steps >= 0")
        if not progress:
            return super().run(steps)
        from tqdm.auto import tqdm
        with tqdm(total=steps, desc=desc or type(self).__name__, unit="step", leave=False) as bar:
            conv = steps == 0
            for i, conv in enumerate(self.irun(steps)):
                if i:
                    bar.update(1)
        return conv

    def get_kinetic_energy(self):
        return I.kinetic(self.atoms.arrays["momenta"], self._invm())

    def get_total_energy(self):
        """Kinetic + (shifted) potential energy of the current step, eV."""
        if self.forces is None:
            self._refresh_properties()
        return self.get_kinetic_energy() + self.potential_energy

    def _layer_kinetic(self):
        """Kinetic energy of the driven layers (pistons and tractions), eV."""
        p = self.atoms.arrays["momenta"]
        m = self.atoms.get_masses()
        e = 0.0
        for d in self._drives():
            if isinstance(d, _Layer):
                idx = d.index
                e += 0.5 * float((p[idx] ** 2).sum(axis=1).dot(1.0 / m[idx]))
        return e

    def _drive_sum(self, name):
        return float(sum(getattr(d, name, 0.0) for d in self._drives()))


    # -- checkpoint state (files: clusterdyn.io.checkpoint.save_run / load_run) ----------------
    def get_state(self, copy=True):
        """Everything a bit-identical restart needs besides the Atoms and their constraints
        (which :func:`clusterdyn.io.checkpoint.save_run` stores with the drives' own state).
        ``copy=False``: the list's reference positions and the forces as they are, not copied
        (for a writer that stores them at once: a checkpoint then adds no N-sized copies)."""
        nl = getattr(self.calc, "nl", None)
        st = {"nsteps": self.nsteps, "dt": self.dt, "J": -1.0 if self.J is None else self.J,
              "damping_loss": self.damping_loss, "dissipation": self._dissipation}
        if self._removal is not None:
            st.update(self._removal.get_state())
        if self.sort_interval is not None:
            st["sort_interval"] = self.sort_interval
        if self.ledger.start_values is not None:
            st["ledger0"] = dict(self.ledger.start_values)
        others = {q.name: q.get_state() for q in self.pieces if q is not self._removal and q is not self._sorting}
        if others:
            st["pieces"] = others
        if nl is not None and nl.ref_nc is not None:
            if getattr(nl, "compacted", False):
                # a list compacted by removals keeps the old build's row order, not the order a
                # build from its reference positions (the restart's) gives: build it so here too,
                # and the two runs add their pair sums in the same order
                nl.build(nl.ref_nc, self.atoms.cell.array, self.atoms.pbc)
            st["nl_ref"] = nl.ref_nc.copy() if copy else nl.ref_nc
        if self.forces is not None:
            st["forces"] = self.forces.copy() if copy else self.forces
            st["potential_energy"] = self.potential_energy
        return st

    def set_state(self, st):
        self.nsteps = int(st["nsteps"])
        self.dt = float(st["dt"])
        self.damping_loss = float(st.get("damping_loss", 0.0))
        self._dissipation = float(st.get("dissipation", 0.0))
        if "region" in st:
            reg = RegionOfInterest.fromdict(st["region"])
            iv = int(st["region"].get("remove_interval", self.remove_interval))
            if self._removal is None:
                self._removal = self.attach_piece(Removal(reg, iv))
            elif (not np.array_equal(reg.lo, self.region.lo) or not np.array_equal(reg.hi, self.region.hi)
                  or iv != self.remove_interval):
                raise InputError("region", repr(self.region), f"the checkpoint's {reg!r} every {iv} steps",
                                 hint="a restart keeps the run's region of interest")
        if "removed" in st and self._removal is not None:
            r = st["removed"]
            self._removal.removed = {"count": int(r["count"]), "mass": float(r["mass"]),
                                     "kinetic": float(r["kinetic"]), "potential": float(r["potential"]),
                                     "momentum": np.array(r["momentum"], dtype=float).reshape(3)}
        if "sort_interval" in st:
            iv = int(st["sort_interval"])
            if self.sort_interval is None:
                self.set_sort_interval(iv)
            elif iv != self.sort_interval:
                raise InputError("sort_interval", self.sort_interval, f"the checkpoint's {iv}",
                                 hint="a restart keeps the run's sort interval")
        if "ledger0" in st:
            self.ledger.start_values = {k: float(x) for k, x in st["ledger0"].items()}
        have = {q.name: q for q in self.pieces}
        for name, qs in st.get("pieces", {}).items():
            if name in have:
                have[name].set_state(qs)
            elif str(qs.get("kind", "")) in PIECE_KINDS:       # a checkpoint loaded without its scene
                self.attach_piece(PIECE_KINDS[str(qs["kind"])].from_state(qs))
            else:
                raise InputError("checkpoint piece", name, "a piece attached to the dynamics or one "
                                 f"rebuilt from its state ({', '.join(sorted(PIECE_KINDS))})")
        nl = getattr(self.calc, "nl", None)
        if nl is not None and "nl_ref" in st:
            nl.build(np.asarray(st["nl_ref"]), self.atoms.cell.array, self.atoms.pbc)
        if "forces" in st:
            self._invm_n = self._invm()
            self.forces = np.array(st["forces"])
            self.potential_energy = float(st["potential_energy"])
