"""DampedVerlet: velocity Verlet with the anti-dusting pair damping of CD eq. (6).

.. math::

    m \\dot v_i = \\sum_k f(r_k - r_i) - \\sum_k \\eta_{ik} (v_i - v_k),
    \\qquad \\eta = m\\Gamma,\\ \\Gamma = c_0/(J a)

for pairs within the cutoff.  The damping force is evaluated in the same
pair loop as the conservative one (one neighbour walk per step) with the
half-step velocities of velocity Verlet, like LAMMPS' dpd/ext/tstat at zero
temperature.  With ``J=None`` the dynamics runs the conservative kernel only:
the damping term is not in the compiled loop at all.
"""

import math
import time

import numpy as np
from ase.md.md import MolecularDynamics

from ..calculators.cluster import ClusterDynamics
from ..errors import InputError, InstabilityError
from ..buffers import grown, permute
from ..parallel import use_threads
from . import _integrate as I
from .drives import Drive, _Layer

#: default time step as a fraction of r0/(c0 + u_max); see :func:`default_timestep`
TIMESTEP_FACTOR = 0.03
#: a particle moving more than this many r0 in one step stops the run
MAX_STEP_DISPLACEMENT = 0.25
#: grid points of the scan for the distance below which a pair's stiffness limits the time step
SAFE_GRID = 400


def stability_limit(calc, r_over_r0=1.0):
    """Velocity-Verlet stability limit of an fcc cluster lattice, ASE time.

    ``dt_max = 2/omega_max`` with ``omega_max^2 = 8 k/m`` (k = -f'(r) at the
    given r/r0, 1 = at rest), the smallest over the materials.  About
    0.58 r0/c0 at rest; it shrinks as compression stiffens the bonds.
    """
    lim = math.inf
    for p in calc.potentials:
        k = float(p.stiffness(r_over_r0 * p.r0))
        if k > 0:
            lim = min(lim, 2.0 / math.sqrt(8.0 * k / p.mass))
    return lim


def pair_stability_limit(calc, a, b, r):
    """Stability limit ``2/omega_max`` of a lattice whose bonds are as stiff as the
    (a, b) pair law at distance r (``omega_max^2 = 8 k/m`` with the lighter
    cluster's mass); unlike pairs use their series law.  ``r`` may be an array."""
    law = calc.law(a, b)
    if a == b:
        k = np.asarray(law.stiffness(r), dtype=float)
    else:
        h = 1e-4 * law.r0
        k = -(np.asarray(law.force(r + h), dtype=float) - np.asarray(law.force(r - h), dtype=float)) / (2.0 * h)
    m = min(calc.masses_t[a], calc.masses_t[b])
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = np.where(k > 0, 2.0 / np.sqrt(np.where(k > 0, 8.0 * k / m, 1.0)), np.inf)
    return float(lim) if lim.ndim == 0 else lim


def default_timestep(calc, u_max=0.0, factor=TIMESTEP_FACTOR):
    """``factor * min(r0 / (c0 + u_max))`` over the materials (ASE time).

    The default factor 0.03 is 1/19 of the stability limit at rest
    (:func:`stability_limit`, 0.58 r0/c0).  The margin is set by accuracy,
    not stability: velocity Verlet's energy error is an O((omega dt)^2)
    offset, and 0.03 keeps it below 1e-3 of the kinetic energy of a thermal
    lattice (0.1 would give 0.75%).  At u = 3 km/s in aluminium it gives
    0.019 r0/c0, the step of the method's reference runs; the ``u_max`` term
    keeps the margin in shocks, where compression raises the sound speed
    (measured by ``clusterdyn study stability``).
    """
    return factor * min(p.r0 / (p.c0 + abs(u_max)) for p in calc.potentials)


class RegionOfInterest:
    """An axis-aligned box; particles that leave it can be removed from a run.

    A particle is inside when ``lo <= x <= hi`` on every axis (NaN is outside).
    Used by :class:`DampedVerlet` (``region=``): every ``remove_interval``
    steps the particles outside are taken out of the Atoms, and the kinetic
    energy, pair energy and momentum they carry away are booked in
    :meth:`DampedVerlet.energy_ledger`.

    Parameters
    ----------
    lo, hi : (3,) array-like, Angstrom
        Corners; ``-inf`` / ``inf`` (or None for the whole vector) leave an
        axis unbounded.  Periodic axes must be unbounded.
    """

    def __init__(self, lo=None, hi=None):
        self.lo = self._corner("lo", lo, -np.inf)
        self.hi = self._corner("hi", hi, np.inf)
        if np.any(self.hi < self.lo):
            raise InputError("hi", self.hi.tolist(), f">= lo = {self.lo.tolist()} on every axis")

    @staticmethod
    def _corner(name, v, default):
        if v is None:
            return np.full(3, default)
        try:
            a = np.array(v, dtype=float).reshape(3)
        except (TypeError, ValueError):
            raise InputError(name, v, "three numbers (Angstrom; +-inf for an unbounded axis)") from None
        if np.any(np.isnan(a)):
            raise InputError(name, v, "three numbers (Angstrom; +-inf for an unbounded axis), no NaN")
        return a

    def inside(self, positions):
        """(N,) bool: particles within the box."""
        return ~self.outside(positions)[0]

    def outside(self, positions):
        """((N,) bool, count): particles outside the box (one pass)."""
        x = np.ascontiguousarray(positions, dtype=np.float64)
        out = np.empty(x.shape[0], np.bool_)
        return out, int(I.outside_box(x.reshape(-1, 3), self.lo, self.hi, out))

    def todict(self):
        return {"kind": "RegionOfInterest", "lo": self.lo.tolist(), "hi": self.hi.tolist()}

    @classmethod
    def fromdict(cls, d):
        return cls(d["lo"], d["hi"])

    def __repr__(self):
        return f"RegionOfInterest(lo={self.lo.tolist()}, hi={self.hi.tolist()})"


#: rows moved at a time by :func:`_compact`
COMPACT_ROWS = 65536


def _compact(a, keep):
    """The rows ``keep`` (ascending) of ``a``, moved to its front in place: a view of its first
    ``len(keep)`` rows.  Nothing of the array's size is allocated (rows are moved a block at a
    time; row keep[t] >= t, so a block reads only rows no earlier block has written), which keeps
    removing particles from raising the peak memory; the memory of the removed rows is not given
    back (the Atoms' arrays keep their size at the start of the run)."""
    k = keep.size
    if not a.flags.c_contiguous:
        return np.ascontiguousarray(a[keep])
    for s in range(0, k, COMPACT_ROWS):
        e = min(s + COMPACT_ROWS, k)
        a[s:e] = a[keep[s:e]]
    return a[:k]


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
        particles mix (debris clouds: docs/performance.md, "Sorting the
        Atoms").  Particle indices change (every array and the constraints'
        indices follow, as for ``region``); ``atoms.arrays['id']`` names the
        particles (added, ``0..N-1``, when the Atoms have none) and the H5MD
        writer orders its rows by it.  None (default): the order is never
        changed.  Needs the ClusterDynamics calculator.
    trajectory, logfile, loginterval :
        As for ASE's MolecularDynamics.

    Attributes
    ----------
    forces : (N, 3) array
        Total forces of the last step (with damping if on; piston rows zeroed).
    potential_energy : float
        Shifted pair energy of the current positions, eV.  The steps' force
        loop leaves the energy out; it is computed (one conservative pass)
        when first read after a step.
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
        self.sort_interval = self._sort_interval(atoms, sort_interval)
        #: sorts of the Atoms done (:meth:`sort_atoms`)
        self.nsorts = 0
        self.region = region
        self.remove_interval = remove_interval
        #: what the removed particles took away since the start: count, mass (amu), kinetic and
        #: pair energy (eV), momentum (3,) (amu Angstrom / ASE time)
        self.removed = {"count": 0, "mass": 0.0, "kinetic": 0.0, "potential": 0.0, "momentum": np.zeros(3)}
        self.J = J
        self._take_calc(calc, limit)
        speeds = [c.max_speed() for c in atoms.constraints if isinstance(c, Drive)]
        u_max = max([s for s in speeds if s is not None] + [0.0])
        if timestep is None:
            if not isinstance(calc, ClusterDynamics):
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
        super().__init__(atoms, ts, trajectory=trajectory, logfile=logfile, loginterval=loginterval,
                         **kwargs)
        self.check_interval = int(check_interval)
        self._own_forces = False
        self._fbuf = None
        self.timings = {"forces": 0.0, "integrate": 0.0}
        #: energy the pair damping has removed, eV (dt times the dissipated power
        #: ``sum eta |v_i - v_j|^2`` of each step's force pass, half-step velocities)
        self.damping_loss = 0.0
        self._dissipation = 0.0
        self._ledger0 = None
        #: HOOK (boundary law, docs/theory.md 1.11): force terms with a history, attached with
        #: :meth:`attach_term`, evaluated once per force pass; none by default (nothing runs)
        self.terms = []
        self._drives()

    def attach_term(self, term):
        """HOOK: add a force term with its own history (e.g. :class:`clusterdyn.md.boundary.BoundaryTerm`).

        It is evaluated in every force pass (in the step's pass, with the half-step momenta
        before any kick, its history advanced), its forces added before the constraints see
        them, its stored energy counted in :attr:`potential_energy`, its dissipation in the
        ledger (``term_dissipated``) and its state in checkpoints (:meth:`get_state`)."""
        if any(t.name == term.name for t in self.terms):
            raise InputError("term", term.name, "a term not attached yet")
        self.terms.append(term)
        self.forces = None
        self._epot = None
        return term

    @staticmethod
    def _calc_limit(atoms, calc, J):
        """The calculator checked for these Atoms and damping ``J`` (ClusterDynamics, set up,
        when J is given); returns its stability limit (None for another calculator)."""
        if isinstance(calc, ClusterDynamics):
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
        self.stability_limit = limit
        self._eta = calc.damping_matrix(self.J) if self.J is not None else None
        self._safe = {}
        self.forces = None
        self._epot = None

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
        if not isinstance(atoms.calc, ClusterDynamics):
            raise InputError("atoms.calc", type(atoms.calc).__name__, "a ClusterDynamics calculator with sort_interval")
        cls._renumbering(atoms, "sort_interval=")
        return int(interval)

    def set_sort_interval(self, interval):
        """Sort the Atoms every ``interval`` steps from now on (None: never), as the
        ``sort_interval`` argument does (checked the same way)."""
        self.sort_interval = self._sort_interval(self.atoms, interval)

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

    def _compute_forces(self, kick=None):
        """Forces at the current positions (constraints applied).

        ``kick = h``: the second half kick, ``momenta += h * forces``: the
        calculator's forces are kicked first (inside the ClusterDynamics loop),
        then the constraints adjust the forces, then the drives that added
        forces (walls) kick their rows with what they added.  Kicks are linear,
        so this is the kick with the total forces; its order of operations is
        the same in every path (fused or not, fresh or restarted).
        """
        atoms = self.atoms
        drives = self._drives()
        # the step these positions belong to: a step's force pass (the one with the second half
        # kick) evaluates the positions of the step under way, which errors name
        at = self.nsteps if kick is None else self.nsteps + 1
        t0 = time.perf_counter()
        for t in self.terms:      # HOOK: the terms read the half-step momenta before the kick
            t.evaluate(atoms, self._invm_n, self.dt, mode=1 if kick is not None else 0)
        if isinstance(self.calc, ClusterDynamics):
            damping = None
            if self._eta is not None:
                damping = (atoms.arrays["momenta"], self._invm_n, self._eta)
            # one force buffer, rewritten at each step (nothing reads the old forces once the first
            # half kick is done); it grows, never shrinks: removing particles takes a view of it
            n = len(atoms)
            self._fbuf = grown(self._fbuf, n)
            out = self.calc.compute(atoms, damping=damping, step=at, out=self._fbuf[:n],
                                    virial=False, energy=False,
                                    kick=None if kick is None else (atoms.arrays["momenta"], kick))
            forces = out["forces"]
            self.potential_energy = out["energy"]
            self._dissipation = out.get("dissipation", 0.0)
            if self.stability_limit is not None and self.nsteps % self.check_interval == 0:
                self._check_stiffness(at)
        else:
            forces = np.ascontiguousarray(atoms.get_forces(apply_constraint=False), dtype=float)
            self.potential_energy = atoms.get_potential_energy() + sum(t.energy for t in self.terms)
            if kick is not None:
                I.kick(atoms.arrays["momenta"], forces, kick)
        for t in self.terms:      # HOOK: the terms' forces (and their half kick)
            t.scatter(forces, atoms.arrays["momenta"] if kick is not None else None, 0.0 if kick is None else kick)
        for c in atoms.constraints:
            c.adjust_forces(atoms, forces)
        if kick is not None:
            for d in drives:
                d.kick_extra(atoms.arrays["momenta"], kick)
        self._own_forces = True
        self.timings["forces"] += time.perf_counter() - t0
        return forces

    @property
    def potential_energy(self):
        if self._epot is None and self.forces is not None and isinstance(self.calc, ClusterDynamics):
            self._epot = (self.calc.compute(self.atoms, step=self.nsteps, virial=False, forces=False)["energy"]
                          + self._constraint_energy() + sum(t.energy for t in self.terms))
        return self._epot

    @potential_energy.setter
    def potential_energy(self, value):
        self._epot = value

    def _safe_distance(self, a, b):
        """Distance above which the (a, b) pair law's stability limit exceeds the time step.

        Scanned once per pair type and time step on a grid of SAFE_GRID points
        from the table's smallest distance to r0 (plus one grid spacing), so a
        step pays one comparison; the exact limit is evaluated only below it.
        """
        key = (a, b, self.dt)
        r = self._safe.get(key)
        if r is None:
            table = self.calc.tables[a][b]
            lo = table.r_min
            grid = np.linspace(lo, table.law.r0, SAFE_GRID)
            lim = pair_stability_limit(self.calc, a, b, grid)
            bad = grid[self.dt > lim]
            r = (bad.max() if bad.size else lo) + (grid[1] - grid[0])
            self._safe[key] = r
        return r

    def _check_stiffness(self, at):
        """The time step against the limit set by the closest pair's own bond stiffness (at step ``at``)."""
        st = self.calc.last_stats
        x = st["min_r_over_r0"]
        if x >= 1.0 or not math.isfinite(x):
            return
        mid = self.atoms.arrays.get("material")
        if mid is None or len(self.calc.potentials) == 1:
            a, b = 0, 0  # one pair law: the closest pair is named only if the check fails
        else:
            i, j = st["closest"]
            a, b = int(mid[i]), int(mid[j])
        r = x * self.calc.law(a, b).r0
        if r > self._safe_distance(a, b):
            return
        lim = pair_stability_limit(self.calc, a, b, r)
        if self.dt > lim:
            raise InstabilityError(
                "time step above the stability limit at the current compression "
                f"(closest pair at r = {x:.3f} r0); lower the time step", step=at,
                particles=st["closest"], quantity="timestep", value=self.dt, limit=lim)

    def _refresh_properties(self):
        # forces are kept by the dynamics; observers that need ASE properties ask the calculator
        if self.forces is None:
            self._invm_n = self._invm()
            self.forces = self._compute_forces()

    def step(self, forces=None):
        """One velocity-Verlet step; returns the forces at the new positions (with ClusterDynamics
        the dynamics' own buffer, rewritten by the next step: copy it to keep it).

        With the ClusterDynamics calculator and drives of
        :mod:`clusterdyn.md.drives` only (any mix of pistons, walls and
        tractions, or none), the first half kick and the drift run fused with
        the calculator's gathers and the second half kick inside its force
        pass (the fast path).  The drives set their layers' momenta before the
        first kick (their forces are zero, so the kick leaves them) and after
        the second; a wall's forces, added by ``adjust_forces``, get their
        half kick on the touched rows after the calculator's.  Other ASE
        constraints (``FixAtoms`` ...) take the separate passes, with the
        drift through ``atoms.set_positions`` so that their
        ``adjust_positions`` applies.
        """
        atoms = self.atoms
        if atoms.calc is not self.calc:
            self._adopt_calc(atoms.calc)
        if self.forces is None or forces is not None:
            self._invm_n = self._invm()
            self.forces = self._compute_forces() if forces is None else forces
            self._own_forces = forces is None
        invm = self._invm_n
        t0 = time.perf_counter()
        use_threads(len(atoms))
        p = atoms.arrays["momenta"]
        h = 0.5 * self.dt
        cons = atoms.constraints
        drives = self._drives()
        foreign = len(drives) != len(cons)
        for d in drives:
            d.begin_step()
        for c in cons:
            c.adjust_momenta(atoms, p)
        res = None
        if self._own_forces and not foreign and isinstance(self.calc, ClusterDynamics):
            res = self.calc._advance(atoms, p, self.forces, invm, h, self.dt, self._eta is not None)
        if res is not None:
            v2max, k = res
        else:
            I.kick(p, self.forces, h)
            if foreign:
                new = atoms.positions + self.dt * p * invm[:, None]
                atoms.set_positions(new)
                v2 = (p * p).sum(axis=1) * invm ** 2
                k = int(np.argmax(v2))
                v2max = v2[k]
            else:
                v2max, k = I.drift(atoms.arrays["positions"], p, invm, self.dt)
        for d in drives:
            d.end_drift()
        self._check_speed(v2max, k)
        self.timings["integrate"] += time.perf_counter() - t0
        self.forces = self._compute_forces(kick=h)
        self.damping_loss += self.dt * self._dissipation
        t0 = time.perf_counter()
        for c in cons:
            c.adjust_momenta(atoms, p)
        self.timings["integrate"] += time.perf_counter() - t0
        if self.region is not None and (self.nsteps + 1) % self.remove_interval == 0:
            self.remove_outside()
        if self.sort_interval is not None and (self.nsteps + 1) % self.sort_interval == 0:
            self.sort_atoms()
        return self.forces

    def sort_atoms(self):
        """Reorder the Atoms into the neighbour list's row (cell) order now; returns True if done.

        New particle k is the particle of the list's sorted row k: every array of
        the Atoms, the constraints' indices, the forces and the list's own
        per-particle state (reference positions, bricks) are permuted in place
        (nothing of N's size is allocated: the scratch is the list's, free between
        builds, :meth:`NeighborList.scratch`), and the list stays valid: no rebuild, and the steps until
        the next build are the same bit for bit (in ``id`` order) as without
        the sort.  The next build's cell sort is stable in the new order, so
        from there the pair sums may add in another order (rounding).  False
        when the list has not been built over the current particles yet, and
        when the Atoms are in its row order already (no build since the last
        sort: nothing to move).
        """
        atoms = self.atoms
        nl = getattr(self.calc, "nl", None)
        n = len(atoms)
        if (not isinstance(self.calc, ClusterDynamics) or nl is None or nl.perm_n is None or nl.ref_nc is None
                or nl.ref_nc.shape[0] != n or nl.in_order):
            return False
        self._renumbering(atoms, "sort_atoms()", add_id=False)
        if self.forces is None:
            self._refresh_properties()
        scratch = nl.scratch(n)             # the list's key scratch: free between builds
        order = nl.perm_n                   # new particle k: the list's sorted row k
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
        self.calc.renumbered(order)
        nl.renumber(scratch)
        self.nsorts += 1
        return True

    def remove_outside(self):
        """Take the particles outside :attr:`region` out of the Atoms now; returns how many.

        Their kinetic energy, momentum and pair energy (potential energy before
        minus after: their bonds to the rest and among themselves) are added to
        :attr:`removed`; the forces are recomputed on the particles left.
        Particles of pistons and tractions are never removed.

        With the Cluster Dynamics calculator the pair energy is that of the listed pairs
        with a removed particle (one pass over the list,
        :meth:`~clusterdyn.calculators.ClusterDynamics.pairs_touching`), plus the
        constraints' energy before minus after, and the neighbour list is compacted, not
        rebuilt (:meth:`~clusterdyn.calculators.ClusterDynamics.removed`).  Without
        constraints, the same pass takes those pairs' forces (and damping, at the step's
        velocities) out of the step's forces, which then are the forces of the particles left,
        with no force pass over them; with constraints (which may adjust the forces), the
        forces are computed afresh.  With another calculator, the potential energy before minus
        after, and the forces afresh.
        """
        atoms = self.atoms
        if self.region is None:
            return 0
        out, nout = self.region.outside(atoms.arrays["positions"])
        if nout == 0:
            return 0
        for d in self._drives():
            if isinstance(d, _Layer):
                out[d.index] = False
        if not out.any():
            return 0
        if self.forces is None:
            self._refresh_properties()
        gone = np.flatnonzero(out)
        keep = np.flatnonzero(~out)
        if keep.size == 0:
            raise InputError("region", repr(self.region), "a region that keeps at least one particle",
                             hint=f"all {len(atoms)} particles are outside at step {self.nsteps}")
        p = atoms.arrays["momenta"]
        m = atoms.get_masses()
        k_gone = 0.5 * float(((p[gone] ** 2).sum(axis=1) / m[gone]).sum())
        p_gone = p[gone].sum(axis=0)
        cd = isinstance(self.calc, ClusterDynamics)
        lost = None
        if cd and not atoms.constraints and self._own_forces and not self.terms:
            # the step's forces less the pairs of the removed particles: no pass over the rest
            lost = self.calc.pairs_touching(atoms, out, forces=self.forces, damped=self._eta is not None)
        incremental = lost is not None
        if cd and lost is None:
            lost = self.calc.pairs_touching(atoms, out)
        if cd:
            u_before = lost[0] + self._constraint_energy()
        else:
            u_before = self.potential_energy
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
        self._invm_n = self._invm()
        self._epot = None
        if incremental:
            self.forces = _compact(self.forces, keep)
            self._dissipation -= lost[1]
        else:
            self.forces = self._compute_forces()
        self._own_forces = True
        # (Cluster Dynamics: the pairs left are not summed, so their energy is not needed)
        u_after = self._constraint_energy() if cd else self.potential_energy
        r = self.removed
        r["count"] += int(gone.size)
        r["mass"] += float(m[gone].sum())
        r["kinetic"] += k_gone
        r["potential"] += float(u_before - u_after)
        r["momentum"] = r["momentum"] + p_gone
        return int(gone.size)

    def _check_speed(self, v2max, k):
        if not math.isfinite(v2max):
            raise InstabilityError("non-finite velocity", step=self.nsteps + 1, particles=(k,),
                                   quantity="speed", value=float("nan"))
        if isinstance(self.calc, ClusterDynamics):
            r0 = min(p.r0 for p in self.calc.potentials)
            disp = math.sqrt(v2max) * self.dt
            if disp > MAX_STEP_DISPLACEMENT * r0:
                raise InstabilityError(
                    "a particle moves too far in one step for the pair forces to be resolved; "
                    "lower the time step", step=self.nsteps + 1, particles=(k,),
                    quantity="displacement per step / r0", value=disp / r0, limit=MAX_STEP_DISPLACEMENT)

    def run(self, steps=50, progress=False, desc=None):
        """Run ``steps`` steps; ``progress=True`` shows a tqdm bar with time left."""
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

    def start_ledger(self):
        """Take the present state as the start of :meth:`energy_ledger` (done at the first step)."""
        if self.forces is None:
            self._refresh_properties()
        self._ledger0 = {"kinetic": self.get_kinetic_energy(), "potential": self.potential_energy,
                         "layers": self._layer_kinetic(), "work": self._drive_sum("work"),
                         "dissipated": self._drive_sum("dissipated"), "damping_loss": self.damping_loss,
                         "removed_kinetic": self.removed["kinetic"], "removed_potential": self.removed["potential"],
                         "removed_px": float(self.removed["momentum"][0]),
                         "removed_py": float(self.removed["momentum"][1]),
                         "removed_pz": float(self.removed["momentum"][2]),
                         "term_dissipated": self._term_dissipated()}

    def _term_dissipated(self):
        return float(sum(t.dissipated for t in self.terms))

    def _drive_sum(self, name):
        return float(sum(getattr(d, name, 0.0) for d in self._drives()))

    def energy_ledger(self):
        """Where the energy went since the ledger's start (eV).

        ``kinetic``, ``potential`` (pairs and walls) now; ``drive_work`` (work
        of pistons and tractions on the other particles), ``layer_kinetic``
        (the change of the driven layers' own kinetic energy), ``damping_loss``
        (pair damping), ``wall_dissipated`` (sticking walls), ``removed_kinetic``
        and ``removed_potential`` (the energy the particles removed outside the
        ``region`` took away) and ``removed_momentum`` ((3,), amu Angstrom /
        ASE time), all since the start; ``energy_in`` = initial kinetic energy
        + the absolute drive work; ``residual`` = change of (kinetic +
        potential) minus (drive work + layer kinetic - damping loss - wall
        dissipated - removed kinetic - removed potential): zero for an exact
        integrator, velocity Verlet's O(dt^2) error otherwise.
        """
        if self._ledger0 is None:
            self.start_ledger()
        L0 = self._ledger0
        K, U = self.get_kinetic_energy(), self.potential_energy
        work = self._drive_sum("work") - L0["work"]
        layers = self._layer_kinetic() - L0["layers"]
        loss = self.damping_loss - L0["damping_loss"]
        diss = self._drive_sum("dissipated") - L0["dissipated"]
        rk = self.removed["kinetic"] - L0.get("removed_kinetic", 0.0)
        ru = self.removed["potential"] - L0.get("removed_potential", 0.0)
        rp = self.removed["momentum"] - np.array([L0.get("removed_p" + a, 0.0) for a in "xyz"])
        td = self._term_dissipated() - L0.get("term_dissipated", 0.0)
        change = K + U - L0["kinetic"] - L0["potential"]
        out = {"kinetic": K, "potential": U, "kinetic0": L0["kinetic"], "potential0": L0["potential"],
                "drive_work": work, "layer_kinetic": layers, "damping_loss": loss, "wall_dissipated": diss,
                "removed_kinetic": rk, "removed_potential": ru, "removed_momentum": rp,
                "energy_in": L0["kinetic"] + abs(work),
                "residual": change - (work + layers - loss - diss - rk - ru - td)}
        if self.terms:
            out["term_dissipated"] = td
        return out

    # -- checkpoint state (files: clusterdyn.io.checkpoint.save_run / load_run) ----------------
    def get_state(self, copy=True):
        """Everything a bit-identical restart needs besides the Atoms and their constraints
        (which :func:`clusterdyn.io.checkpoint.save_run` stores with the drives' own state).
        ``copy=False``: the list's reference positions and the forces as they are, not copied
        (for a writer that stores them at once: a checkpoint then adds no N-sized copies)."""
        nl = getattr(self.calc, "nl", None)
        st = {"nsteps": self.nsteps, "dt": self.dt, "J": -1.0 if self.J is None else self.J,
              "damping_loss": self.damping_loss, "dissipation": self._dissipation}
        if self.region is not None or self.removed["count"]:
            r = self.removed
            st["removed"] = {"count": r["count"], "mass": r["mass"], "kinetic": r["kinetic"],
                             "potential": r["potential"], "momentum": np.array(r["momentum"], dtype=float)}
        if self.region is not None:
            st["region"] = dict(self.region.todict(), remove_interval=self.remove_interval)
        if self.sort_interval is not None:
            st["sort_interval"] = self.sort_interval
        if self._ledger0 is not None:
            st["ledger0"] = dict(self._ledger0)
        if self.terms:            # HOOK: the terms' history
            st["terms"] = {t.name: t.get_state() for t in self.terms}
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
        if "removed" in st:
            r = st["removed"]
            self.removed = {"count": int(r["count"]), "mass": float(r["mass"]), "kinetic": float(r["kinetic"]),
                            "potential": float(r["potential"]),
                            "momentum": np.array(r["momentum"], dtype=float).reshape(3)}
        if "region" in st:
            reg = RegionOfInterest.fromdict(st["region"])
            iv = int(st["region"].get("remove_interval", self.remove_interval))
            if self.region is None:
                self.region, self.remove_interval = reg, iv
            elif (not np.array_equal(reg.lo, self.region.lo) or not np.array_equal(reg.hi, self.region.hi)
                  or iv != self.remove_interval):
                raise InputError("region", repr(self.region), f"the checkpoint's {reg!r} every {iv} steps",
                                 hint="a restart keeps the run's region of interest")
        if "sort_interval" in st:
            iv = int(st["sort_interval"])
            if self.sort_interval is None:
                self.set_sort_interval(iv)
            elif iv != self.sort_interval:
                raise InputError("sort_interval", self.sort_interval, f"the checkpoint's {iv}",
                                 hint="a restart keeps the run's sort interval")
        if "ledger0" in st:
            self._ledger0 = {k: float(x) for k, x in st["ledger0"].items()}
        if "terms" in st:         # HOOK: the terms' history (terms not attached yet are rebuilt)
            from .boundary import BoundaryTerm
            have = {t.name: t for t in self.terms}
            for name, ts in st["terms"].items():
                if name in have:
                    have[name].set_state(ts)
                elif ts.get("kind") == "BoundaryTerm":
                    self.attach_term(BoundaryTerm.from_state(ts))
        nl = getattr(self.calc, "nl", None)
        if nl is not None and "nl_ref" in st:
            nl.build(np.asarray(st["nl_ref"]), self.atoms.cell.array, self.atoms.pbc)
        if "forces" in st:
            self._invm_n = self._invm()
            self.forces = np.array(st["forces"])
            self.potential_energy = float(st["potential_energy"])
