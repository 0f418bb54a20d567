"""MCADynamics: velocity Verlet for translations and rotations, and the MCA pair state.

Each step (``dt``), with momenta ``p`` and angular velocities ``omega``:

1. half kick ``p += dt/2 F``, ``omega += dt/2 T/J`` (spheres: ``J = m d^2/10``;
   2D cylinders about z: ``J = m d^2/8``; isotropic J, so no gyroscopic term);
   the drives (:mod:`clusterdyn.md.drives`) set their layers' momenta for the
   drift;
2. drift ``R += dt p/m``, ``theta += dt omega``;
3. trial forces from the calculator at the new positions (state unchanged);
4. *commit*: the trial pair forces become the state, then the response
   functions the materials use run (radial return, damage, fracture,
   healing); if they changed anything the forces are evaluated again at the
   same positions (the state is never changed inside a property call);
5. the pair damping (optional) at the half-step velocities; the drives take
   their forces (and record them); half kick with the new forces, the
   drives set their layers' momenta for the step's end.  The damping forces
   serve both half kicks around a time (as in
   :class:`~clusterdyn.md.DampedVerlet`), so the forces a drive records are
   those that moved the particles and its impulse is the momentum it gave.

Stored elastic energy (docs/mca.md, "Energy"): the work of the pair forces, accumulated
trapezoidally, ``W += -1/2 (F_n + F_{n+1}) . dR - 1/2 (T_n + T_{n+1}) . dtheta``;
``kinetic + rotational + stored`` is conserved to O(dt^2) without damping.

Dissipation and driving live here, not in the calculator: viscous damping of
the relative velocity at the contact point of every pair (``damping`` = fraction
of the critical damping of a pair), and the drives of :mod:`clusterdyn.md.drives`
(ASE constraints on the Atoms: :class:`~clusterdyn.md.Piston` with a velocity
history U(t), e.g. a :class:`~clusterdyn.md.SmoothRamp`, and
``lateral="free"`` for a grip whose automata move freely across it;
:class:`~clusterdyn.md.Traction` for a layer pressed at a prescribed stress).
They act on velocities only: the angular velocities of their automata are
left to the torques unless ``hold_layer_rotation=True`` (jaws glued to the
sample: the automata of every piston and traction layer do not rotate).  The
drives' force records include the pair damping on their layers.
"""

import math

import numpy as np
from ase.md.md import MolecularDynamics

from .. import units
from ..errors import InputError, InstabilityError
from ..md.drives import Drive, _Layer
from ..md.layer_drives import Traction
from ..neighbors import NeighborList
from . import kernels as K
from .response import brittle, degrading, healing, plastic, plastic_degrading

#: time step = COURANT * d_min / c_L,max by default; STABILITY_COURANT is the measured limit
COURANT = 0.15
STABILITY_COURANT = 0.4


def wave_speeds(material):
    """(c_L, c_S) of a material, Angstrom per ASE time unit."""
    Kb, G, rho = material.K, material.G, material.rho0
    return math.sqrt((Kb + 4.0 * G / 3.0) / rho), math.sqrt(G / rho)


def default_timestep(atoms, materials=None, courant=COURANT):
    """``dt = C d / c_L`` minimised over automata (C = 0.15; measured limit: C = 0.4 runs, 0.5 diverges at nu = 0)."""
    from .state import mca_materials_of
    mats = mca_materials_of(atoms, materials)
    cl = np.array([wave_speeds(m)[0] for m in mats])
    d = 2.0 * np.asarray(atoms.arrays["radius"])
    mid = np.asarray(atoms.arrays["material"])
    return float(courant * np.min(d / cl[mid]))


class MCADynamics(MolecularDynamics):
    """Movable Cellular Automata dynamics (ASE MolecularDynamics).

    Parameters
    ----------
    atoms : Atoms with an :class:`~clusterdyn.mca.calculator.MCA` calculator
        Drives (:mod:`clusterdyn.md.drives`: pistons, tractions, walls) and
        velocity constraints such as ASE's ``FixAtoms`` go on
        ``atoms.constraints``; they are bound to this dynamics (their time is
        ``nsteps * dt``) and act through ``adjust_forces`` and
        ``adjust_momenta`` (the drift follows the momenta).
    timestep : float, ASE time; default :func:`default_timestep` (C = 0.15)
    damping : float, fraction of critical damping of the relative pair velocity
        (0 = off, for wave and conservation problems; ~0.1-0.5 quasi-static)
    contact_every : int, steps between searches for new contacts (only when the
        sample can fracture or has pre-cracks)
    check_timestep : raise InstabilityError if ``timestep`` exceeds the measured limit
    hold_layer_rotation : bool, default False
        The automata of every piston and traction layer keep ``omega = 0`` (a
        grip glued to the sample); otherwise a drive leaves angular velocities alone.
    state : dict, optional
        :meth:`get_state` of a run to continue (no tessellation is made).
    contact : :class:`~clusterdyn.mca.contact.SegmentContact`, optional
        The segment method and friction law between bodies (2D; ``atoms.arrays['body']``):
        its normal force joins the conservative forces, its friction is evaluated like the
        pair damping (half-step velocities, both half kicks around a time) and its work
        accumulates in ``contact.friction_work``; pairs across bodies leave the pair table.
    remesh_strain : float in (0, 0.5) or None (default: off)
        Large strain (docs/theory.md 2.7): re-tessellate (:meth:`remesh`) when a linked
        pair's strain exceeds it; the exact-volume sync (:meth:`_volume_sync`) then runs at
        every commit.  3D bodies without periodic axes.
    remesh_every : int, steps between re-tessellations (0 = off), alone or with ``remesh_strain``
    h_link : float, new pairs of a re-tessellation link when their overlap
        ``r - (r_i + r_j)`` is below ``h_link (r_i + r_j)`` (default 0.5)

    Notes
    -----
    The energy ledger of any run is :meth:`ledger`.
    In 2D plane strain (``dim=2``) the drives' directions must lie in the x-y
    plane; a :class:`~clusterdyn.md.Traction` without an area gets the
    periodic cell length across its normal times the unit thickness (1 Angstrom).
    """

    def __init__(self, atoms, timestep=None, *, damping=0.0, contact_every=25, check_timestep=True,
                 hold_layer_rotation=False, state=None, contact=None, remesh_strain=None,
                 remesh_every=0, h_link=0.5, trajectory=None, logfile=None, loginterval=1, **kw):
        calc = atoms.calc
        from .calculator import MCA
        if not isinstance(calc, MCA):
            raise InputError("atoms.calc", type(calc).__name__, "an MCA calculator")
        if state is not None:          # restart: the pair table comes from the checkpoint
            from .state import MCAState
            calc.state = MCAState.from_dict(atoms, state, calc.materials, calc.interfaces, calc.dim)
        self.state = calc.setup(atoms)
        calc.attach_dynamics(self)
        st = self.state
        self.contact = contact
        if contact is not None:
            contact.bind(atoms, st)
        dt_def = default_timestep(atoms, st.materials)
        if timestep is None:
            timestep = dt_def
        limit = dt_def * STABILITY_COURANT / COURANT
        if not timestep > 0:
            raise InputError("timestep", timestep, "a positive time step")
        if check_timestep and timestep > limit:
            raise InstabilityError(
                "time step above the stability limit of MCA (dt = C d/c_L with C <= "
                f"{STABILITY_COURANT}); use timestep=None for the default C = {COURANT}",
                quantity="timestep", value=timestep, limit=limit)
        super().__init__(atoms, timestep, trajectory=trajectory, logfile=logfile,
                         loginterval=loginterval, **kw)
        if not 0.0 <= damping:
            raise InputError("damping", damping, "a fraction of critical damping >= 0")
        if not isinstance(hold_layer_rotation, (bool, np.bool_)):
            raise InputError("hold_layer_rotation", hold_layer_rotation, "True or False")
        self.damping = float(damping)
        self.hold_layer_rotation = bool(hold_layer_rotation)
        self.contact_every = int(contact_every)
        self.check_timestep = bool(check_timestep)
        self.stored_work = 0.0
        self.dissipated = 0.0
        self.plastic_work = 0.0
        self.switch_energy = 0.0
        self.split_work = 0.0
        self.volume_energy = 0.0
        self.volume_syncs = 0
        self.volume_tol = 5e-5
        self.remesh_count = 0
        self.remesh_log = []
        if remesh_strain is not None and not 0.0 < remesh_strain < 0.5:
            raise InputError("remesh_strain", remesh_strain, "None (off) or a pair strain in (0, 0.5)")
        if not (isinstance(remesh_every, (int, np.integer)) and remesh_every >= 0):
            raise InputError("remesh_every", remesh_every, "an integer number of steps >= 0 (0 = off)")
        if not 0.0 <= h_link:
            raise InputError("h_link", h_link, "an overlap fraction >= 0")
        if (remesh_strain is not None or remesh_every) and st.dim != 3:
            raise InputError("remesh_strain", remesh_strain, "None in 2D (the large-strain switching is 3D)")
        if (remesh_strain is not None or remesh_every) and contact is not None:
            raise InputError("remesh_strain", remesh_strain, "None with a segment contact (2D bodies)")
        self.remesh_strain = None if remesh_strain is None else float(remesh_strain)
        self.remesh_every = int(remesh_every)
        self.h_link = float(h_link)
        n = len(atoms)
        for name in ("omega", "theta"):
            if name not in atoms.arrays:
                atoms.new_array(name, np.zeros((n, 3)))
        self._nl = None
        self._S_mean = None
        self._F = None
        self._setup_masses()
        self._evaluate(commit=False)
        if self.remeshing and state is None and st.step == 0:
            self.remesh()                # the body's own closure from the first step (docs/mca.md)
            self.remesh_count = 0
            self.switch_energy = 0.0
            self.remesh_log = []
        self._Fd = self._Td = None
        if self.damping > 0:        # the first half kick's damping: present velocities
            self._Fd, self._Td = self._damping_forces(atoms.get_velocities(), atoms.arrays["omega"])
        kt0, kr0 = self.kinetic_energy()
        self._E_initial = kt0 + kr0 + self.elastic_energy()
        self._Ff = self._Tf = None
        if self._friction_on:       # the first half kick's friction: present velocities, history kept
            self._Ff, self._Tf = contact.friction(atoms, st, atoms.get_velocities(), atoms.arrays["omega"],
                                                  self.dt, advance=False)
        if state is not None:
            self._restore_counters(state)
        self._drives()

    @property
    def _friction_on(self):
        return self.contact is not None and self.contact.friction_on

    # ------------------------------------------------------------------ drives
    def _drives(self):
        """The drives among the constraints, bound to this dynamics (binds and checks new ones)."""
        ds = []
        for c in self.atoms.constraints:
            if isinstance(c, Drive):
                if c._dyn is not self:
                    self._check_drive(c)
                    c.bind(self)
                ds.append(c)
        return ds

    def _check_drive(self, c):
        if self.state.dim != 2:
            return
        for name in ("direction", "normal", "tangent"):
            v = getattr(c, name, None)
            if v is not None and abs(float(v[2])) > 1e-12:
                raise InputError(f"{c.kind}.{name}", np.asarray(v).tolist(),
                                 "a direction in the x-y plane (2D plane strain)")
        if isinstance(c, Traction) and c.area is None:
            cell, pbc = self.atoms.cell.array, self.atoms.pbc
            across = [a for a in (0, 1) if abs(float(c.normal[a])) < 1e-12]
            if len(across) != 1 or not pbc[across[0]]:
                raise InputError("Traction.area", None, "an area (Angstrom^2, per unit thickness in 2D): it is "
                                 "derived only for a normal along x or y with the other in-plane axis periodic")
            c.area = float(cell[across[0], across[0]]) * 1.0      # unit thickness

    def _layer_rows(self):
        rows = [d.index for d in self._drives() if isinstance(d, _Layer)]
        return np.concatenate(rows) if rows else np.zeros(0, np.int64)

    def _constrained(self, forces):
        """A copy of ``forces`` adjusted by the constraints (drives take and record theirs)."""
        cons = self.atoms.constraints
        if not cons:
            return forces
        f = np.array(forces, dtype=np.float64, order="C")
        for c in cons:
            c.adjust_forces(self.atoms, f)
        return f

    def _constrain_motion(self, p, w):
        for c in self.atoms.constraints:
            c.adjust_momenta(self.atoms, p)
        if self.hold_layer_rotation:
            w[self._layer_rows()] = 0.0

    # ------------------------------------------------------------------ helpers
    def _setup_masses(self):
        atoms = self.atoms
        m = atoms.get_masses()
        d = 2.0 * atoms.arrays["radius"]
        self.J = m * d * d / (8.0 if self.state.dim == 2 else 10.0)
        if self.damping > 0:
            st = self.state
            i_p, j_p = st.pair_rows(atoms)[:2]
            mid = st.mat_id_n[st.pair_rows(atoms)[5]]
            M = st.K_m[mid] + 4.0 * st.G_m[mid] / 3.0
            k_p = 0.5 * (M[i_p] + M[j_p]) * st.S_p / st.r0_p
            mred = m[i_p] * m[j_p] / (m[i_p] + m[j_p])
            self._c_p = 2.0 * self.damping * np.sqrt(k_p * mred)

    def todict(self):
        d = super().todict()
        d.update({"damping": self.damping, "contact_every": self.contact_every,
                  "hold_layer_rotation": self.hold_layer_rotation})
        return d

    @property
    def time(self):
        return self.state.time

    def _evaluate(self, commit=True):
        atoms = self.atoms
        calc = atoms.calc
        st = self.state
        out = calc.evaluate(atoms, st)
        if commit:
            changed = self.commit(out)
            if changed:
                f_trial = out["f_nc"]
                out = calc.evaluate(atoms, st)
                out["f_trial"] = f_trial
        if self.contact is not None:
            fc = self.contact.normal(atoms, st)
            out["f_nc"] = out["f_nc"] + fc
            if "f_trial" in out:
                out["f_trial"] = out["f_trial"] + fc
        self._F = out["f_nc"]
        self._T = out["t_nc"]
        self.trial = out
        # the evaluation is the calculator's result for these positions and this state
        calc.atoms = atoms.copy()
        calc.results = {}
        calc._fill_results(out)
        calc.trial = out
        calc._state_version = st.version
        return out

    def _refresh_properties(self):
        pass      # the step already left the calculator's results up to date

    def commit(self, out):
        """Make the trial state the state, then run the response functions; returns #changes."""
        st = self.state
        perm = out["perm"]
        st.sig_p2 = out["sig_p2"]
        st.tau_p2c = out["tau_p2c"]
        st.dlast_pc = out["d_pc"]
        st.thlast_nc[perm] = out["theta_nc"]
        st.P_n[perm] += out["dP_n"]
        i_p, j_p, first_n, side_p, side_s, _ = st.pair_rows(self.atoms)
        s = out["s_ncc"]
        changed = 0
        P = st.npairs
        fl = st.flags
        self.broken_now = np.zeros(P, np.int8)
        if fl["plastic"]:
            mid = st.mat_id_n[perm]
            soft = np.ones(len(perm))
            if fl["plastic_degrading"]:
                plastic_degrading.softening(first_n, side_p, st.D_p, soft)
            epsp = st.epsp_n[perm]
            Mn = np.empty(len(perm))
            wp = np.empty(len(perm))
            Gm, Km = st.G_m[mid], st.K_m[mid]
            T = st.T_n[perm] if st.T_n.size else st.T_n        # empty: no thermal term
            changed += plastic.radial_return(s, first_n, side_p, side_s, mid, st.plastic_m,
                                             st.G_m[mid], st.tab_e, st.tab_s, soft, epsp,
                                             st.sig_p2, st.tau_p2c, Mn, st.implicit_m, st.rateC_m,
                                             st.rate0_m, self.dt, out["omega_n"], wp, st.q0_p2, st.S_p,
                                             np.ascontiguousarray(st.P_n[perm]), 1.0 - 2.0 * Gm / (3.0 * Km),
                                             T, st.therm_m4)
            st.epsp_n[perm] = epsp
            if T.size:
                st.T_n[perm] = T
            self.plastic_work += float(wp.sum())
            if fl["plastic_degrading"]:
                changed += plastic_degrading.degrade_plastic(i_p, j_p, st.linked_p, epsp, st.epsd_p,
                                                             st.epsf_p, st.D_p, st.sig_p2,
                                                             st.tau_p2c, self.broken_now)
        if fl["degrading"]:
            changed += degrading.degrade(i_p, j_p, st.linked_p, s, st.sigd_p, st.sigc_p, st.beta_p,
                                         st.Dc_p, st.D_p, st.sig_p2, st.tau_p2c, self.broken_now)
        elif fl["fracture"]:
            changed += brittle.fracture(i_p, j_p, st.linked_p, s, st.sigc_p, st.beta_p, st.sig_p2,
                                        st.tau_p2c, self.broken_now)
        if st.lnJ_n is not None:
            changed += self._volume_sync(out, i_p, j_p, first_n, side_p, side_s, perm)
        if fl["healing"]:
            welded = np.zeros(P, np.int8)
            nw = healing.weld(st.linked_p, st.sig_p2, out["r_p"], st.r0_p, st.sigw_p, st.nweld_p,
                              st.count_p, welded)
            if nw:
                st.D_p[welded == 1] = 0.0
                changed += nw
        st.version += 1
        return changed

    def _damping_forces(self, v, w):
        atoms = self.atoms
        st = self.state
        i_p, j_p, first_n, side_p, side_s, _ = st.pair_rows(atoms)
        fd = np.empty_like(v)
        td = np.empty_like(v)
        K.pair_damping(v, w, i_p, j_p, self.trial["d_pc"], self.trial["r_p"], self.trial["arm_p2"],
                       self._c_p, fd, td, first_n, side_p, side_s)
        if st.dim == 2:
            fd[:, 2] = 0.0
            td[:, :2] = 0.0
        return fd, td

    def _contacts(self):
        st = self.state
        atoms = self.atoms
        rad = atoms.arrays["radius"]
        skin = 0.25
        if self._nl is None:
            self._nl = NeighborList(2.0 * rad.max() * (1.0 + skin), 0.0, half=True)
        if self._S_mean is None:
            S_mean = np.bincount(np.concatenate([st.pair_rows(atoms)[0], st.pair_rows(atoms)[1]]),
                                 weights=np.concatenate([st.S_p, st.S_p]), minlength=len(atoms))
            cnt = np.bincount(np.concatenate([st.pair_rows(atoms)[0], st.pair_rows(atoms)[1]]),
                              minlength=len(atoms))
            self._S_mean = S_mean / np.maximum(cnt, 1)
        nl = self._nl
        nl.build(atoms.positions, atoms.cell.array, atoms.pbc)
        i, j, _, r = nl.pairs(atoms.positions)
        close = r < (rad[i] + rad[j]) * (1.0 + skin)
        if self.contact is not None:         # bodies meet through segments only
            body = atoms.arrays["body"]
            close &= body[i] == body[j]
        i, j = i[close], j[close]
        ids = atoms.arrays["id"]
        a, b = np.minimum(ids[i], ids[j]), np.maximum(ids[i], ids[j])
        M = int(ids.max()) + 1
        keys = a * M + b
        have = st.pid_p2[:, 0] * M + st.pid_p2[:, 1]
        new = ~np.isin(keys, have)
        if new.any():
            keys_new, first = np.unique(keys[new], return_index=True)
            ii, jj = i[new][first], j[new][first]
            S_new = 0.5 * (self._S_mean[ii] + self._S_mean[jj])
            st.add_pairs(atoms.positions, ids, rad, ii, jj, S_new)
            if self.damping > 0:
                self._setup_masses()

    # ------------------------------------------------------------------ the step
    def step(self, forces=None):
        atoms = self.atoms
        st = self.state
        dt = self.dt
        h = 0.5 * dt
        m = atoms.get_masses()
        J = self.J
        p = np.ascontiguousarray(atoms.get_momenta(), dtype=np.float64)
        w = np.array(atoms.arrays["omega"], dtype=np.float64, order="C")
        F0, T0 = self._F, self._T
        Fe, Te = F0, T0
        if self.damping > 0:                   # the damping of the last evaluation (half-step velocities)
            fd0, td0 = self._Fd, self._Td
            Fe, Te = F0 + fd0, T0 + td0
        if self._friction_on:                  # the friction of the last evaluation
            ff0, tf0 = self._Ff, self._Tf
            Fe, Te = Fe + ff0, Te + tf0
        drives = self._drives()
        Fe = self._constrained(Fe)             # the step's start: a drive records only its first sample
        for d in drives:
            d.begin_step()
        K.half_kick(p, w, _c64(Fe), _c64(Te), J, h)
        self._constrain_motion(p, w)
        if st.dim == 2:
            p[:, 2] = 0.0
            w[:, :2] = 0.0
        dx = np.empty_like(p)
        dth = np.empty_like(w)
        K.drift(p, m, w, dt, _own(atoms, "positions"), _own(atoms, "theta"), dx, dth)
        for d in drives:
            d.end_drift()
        st.step += 1
        st.time += dt
        if st.flags["contacts"] and self.contact_every > 0 and st.step % self.contact_every == 0:
            self._contacts()
        out = self._evaluate(commit=True)
        F1, T1 = self._F, self._T
        f_tr = out_f_trial(out, F1)
        self.stored_work -= 0.5 * (K.sum_of_products(_c64(F0), _c64(f_tr), dx)
                                   + K.sum_of_products(_c64(T0), _c64(T1), dth))
        if f_tr is not F1:                     # the kick uses the corrected forces (O(dt) term)
            self.split_work += 0.5 * float(np.sum((f_tr - F1) * dx))
        if self.remeshing and self._remesh_due(out):
            out = self.remesh()
            F1, T1 = self._F, self._T
        self._check(out)
        Fe, Te = F1, T1
        if self.damping > 0:
            fd, td = self._damping_forces(p / m[:, None], w)
            Fe, Te = F1 + fd, T1 + td
            self.dissipated -= 0.5 * (np.sum((fd0 + fd) * dx) + np.sum((td0 + td) * dth))
            self._Fd, self._Td = fd, td
        if self._friction_on:
            ff, tf = self.contact.friction(atoms, st, p / m[:, None], w, dt, advance=True)
            Fe, Te = Fe + ff, Te + tf
            self.contact.friction_work -= 0.5 * (np.sum((ff0 + ff) * dx) + np.sum((tf0 + tf) * dth))
            self._Ff, self._Tf = ff, tf
        Fe = self._constrained(Fe)             # the drives record their forces at the step's end
        K.half_kick(p, w, _c64(Fe), _c64(Te), J, h)
        self._constrain_motion(p, w)
        if st.dim == 2:
            p[:, 2] = 0.0
            w[:, :2] = 0.0
        atoms.set_momenta(p, apply_constraint=False)
        atoms.arrays["omega"][:] = w
        return F1

    # ------------------------------------------------------------------ large strain
    @property
    def remeshing(self):
        return self.remesh_strain is not None or self.remesh_every > 0

    def _remesh_due(self, out):
        st = self.state
        if self.remesh_every and st.step % self.remesh_every == 0:
            return True
        if self.remesh_strain is not None:
            m, _ = K.max_linked_strain(out["r_p"], st.r0_p, st.linked_p)
            return bool(m > self.remesh_strain)
        return False

    def remesh(self):
        """Re-tessellate now (:meth:`MCAState.retessellate`); returns the new evaluation.

        The forces change at fixed positions (no work); the change of the
        automata's elastic energy counts in :attr:`switch_energy` (energy
        removed by switching, eV), so the ledger (:meth:`ledger`) closes.
        """
        st = self.state
        e0 = self.elastic_energy()
        perm = st.pair_rows(self.atoms)[5]
        if st.lnJ_n is not None:            # the volume the pairs' linear strains missed since the last sync
            i_p, j_p, first_n, side_p, side_s, _ = st.pair_rows(self.atoms)
            if self._volume_sync(self.trial, i_p, j_p, first_n, side_p, side_s, perm, tol=0.0):
                self._evaluate(commit=False)
                e0 = self.elastic_energy()
        info = st.retessellate(self.atoms, self.trial["s_ncc"], self.h_link)
        st.lnJ_n = np.empty(len(self.atoms))
        st.lnJ_n[perm] = self._log_volume()
        st.Pref_n = st.P_n.copy()
        self._nl = None
        self._S_mean = None
        self._setup_masses()
        out = self._evaluate(commit=False)
        de = e0 - self.elastic_energy()
        self.switch_energy += de
        self.remesh_count += 1
        info.update(step=int(st.step), energy_change=-de)
        self.remesh_log.append(info)
        return out

    def elastic_energy(self):
        """Elastic energy stored in the linked pairs (eV; :func:`kernels.pair_energy`)."""
        return self._pair_energy(None)

    def _volume_sync(self, out, i_p, j_p, first_n, side_p, side_s, perm, tol=None):
        """Large strain: give every automaton the volume change its pairs' linear strains missed.

        ``delta_i = (ln J_i - ln J_i,ref) - (P_i - P_i,ref)/K_i``, the exact volume change
        (:func:`kernels.log_volume`) since the last sync less the one the mean stress
        has seen; where ``max |delta| > volume_tol`` every linked pair side of i gets
        ``K_i delta_i`` (a pure pressure change: ``2G/3 delta`` in the strain, ``K delta`` in
        P) and the references are reset.  A commit-time correction like the radial
        return: its energy change at fixed positions is counted in :attr:`volume_energy`.
        Returns 1 if applied, else 0.
        """
        st = self.state
        lnJ = np.empty(len(perm))
        K.log_volume(out["d_pc"], st.q0_p2, st.S_p, st.linked_p, first_n, side_p, side_s, lnJ)
        Kn = st.K_m[st.mat_id_n[perm]]
        delta = (lnJ - st.lnJ_n[perm]) - (st.P_n[perm] - st.Pref_n[perm]) / Kn
        delta[~np.isfinite(delta)] = 0.0       # flat neighbourhoods (kernels.log_volume): no sync
        if not len(delta) or np.max(np.abs(delta)) <= (self.volume_tol if tol is None else tol):
            return 0
        e0 = self._pair_energy(out["s_ncc"])
        dP = Kn * delta
        lk = st.linked_p == 1
        st.sig_p2[lk, 0] += dP[i_p[lk]]
        st.sig_p2[lk, 1] += dP[j_p[lk]]
        st.P_n[perm] += dP
        st.lnJ_n[perm] = lnJ
        st.Pref_n = st.P_n.copy()
        self.volume_energy += e0 - self._pair_energy(out["s_ncc"])
        self.volume_syncs += 1
        return 1

    def _pair_energy(self, s_ncc):
        st = self.state
        _, _, first_n, side_p, side_s, perm = st.pair_rows(self.atoms)
        mid = st.mat_id_n[perm]
        e = np.empty(len(perm))
        K.pair_energy(st.sig_p2, st.tau_p2c, st.q0_p2, st.S_p, st.linked_p, np.ascontiguousarray(st.P_n[perm]),
                      first_n, side_p, side_s, self.trial_omega(perm), st.G_m[mid], st.K_m[mid], e)
        return float(e.sum())

    def trial_omega(self, perm):
        return np.ascontiguousarray(self.state.omega_n[perm])

    def _log_volume(self):
        """``ln sqrt(det B)`` of every automaton (rows of the Atoms) on the present pair table."""
        st = self.state
        atoms = self.atoms
        i_p, j_p, first_n, side_p, side_s, perm = st.pair_rows(atoms)
        d = atoms.positions[j_p] - atoms.positions[i_p]
        from ..neighbors import minimum_image
        minimum_image(d, st.box_c, st.periodic_c)
        lnJ = np.empty(len(atoms))
        K.log_volume(np.ascontiguousarray(d), st.q0_p2, st.S_p, st.linked_p, first_n, side_p, side_s, lnJ)
        return lnJ

    def ledger(self, external_work=None):
        """The energy ledger (eV): where the work done on the body went.

        ``kinetic + rotational + elastic + plastic + damping + switching + splitting + wall``
        against the work of the drives (pistons' ``work``) and the initial
        energy; ``residual`` = initial + work in - the sum (the integration
        error and the difference between the work of the pair forces and the
        pairs' elastic energy; see docs/mca.md).  ``elastic`` is the energy
        stored in the linked pairs (:meth:`elastic_energy`);
        ``wall`` a wall's stored and sticking-dissipated energy.
        """
        kt, kr = self.kinetic_energy()
        el = self.elastic_energy()
        wall = 0.0
        work = 0.0
        for c in self.atoms.constraints:
            if hasattr(c, "work"):
                work += float(c.work)
            if getattr(c, "kind", "") == "Wall":
                wall += float(c.energy) + float(c.dissipated)
        if external_work is not None:
            work = float(external_work)
        out = {"kinetic": kt, "rotational": kr, "elastic": el, "plastic": self.plastic_work,
               "damping": self.dissipated, "switching": self.switch_energy, "splitting": self.split_work,
               "volume": self.volume_energy, "wall": wall, "work_in": work, "initial": self._E_initial}
        out["residual"] = (out["initial"] + work
                           - (kt + kr + el + self.plastic_work + self.dissipated + self.switch_energy
                              + self.split_work + self.volume_energy + wall))
        return out

    def _check(self, out):
        st = self.state
        m, p = K.max_linked_strain(out["r_p"], st.r0_p, st.linked_p)
        if m > 0.5:
            raise InstabilityError(
                "a linked pair stretched or compressed by more than half its rest distance: "
                f"unstable; reduce the time step (now {self.dt / units.ns:.4g} ns, default "
                f"{default_timestep(self.atoms, st.materials) / units.ns:.4g} ns) or the loading rate",
                step=st.step, particles=st.pid_p2[p], quantity="pair strain",
                value=float(m), limit=0.5)

    # ------------------------------------------------------------------ energies
    def kinetic_energy(self):
        v = self.atoms.get_velocities()
        w = self.atoms.arrays["omega"]
        m = self.atoms.get_masses()
        return 0.5 * float(np.sum(m[:, None] * v * v)), 0.5 * float(np.sum(self.J[:, None] * w * w))

    def total_energy(self):
        """kinetic + rotational + stored work (eV)."""
        kt, kr = self.kinetic_energy()
        return kt + kr + self.stored_work

    # ------------------------------------------------------------------ checkpoint
    def get_state(self):
        """All per-pair and per-automaton history plus step, time and energy counters."""
        d = self.state.get_state()
        d["stored_work"] = float(self.stored_work)
        d["dissipated"] = float(self.dissipated)
        d["plastic_work"] = float(self.plastic_work)
        d["switch_energy"] = float(self.switch_energy)
        d["split_work"] = float(self.split_work)
        d["volume_energy"] = float(self.volume_energy)
        d["volume_syncs"] = int(self.volume_syncs)
        d["remesh_count"] = int(self.remesh_count)
        d["E_initial"] = float(self._E_initial)
        d["remesh"] = np.array([-1.0 if self.remesh_strain is None else self.remesh_strain,
                                float(self.remesh_every), self.h_link])
        d["nsteps"] = int(self.nsteps)
        if self._S_mean is not None:
            d["contact_S_mean"] = self._S_mean.copy()
        d["forces"] = self._F.copy()       # the forces of the next half kick, exactly
        d["torques"] = self._T.copy()
        if self._Fd is not None:
            d["damping_forces"] = self._Fd.copy()
            d["damping_torques"] = self._Td.copy()
        if self.contact is not None:
            d["contact"] = self.contact.get_state()
            if self._Ff is not None:
                d["friction_forces"] = self._Ff.copy()
                d["friction_torques"] = self._Tf.copy()
        return d

    def set_state(self, d):
        """Restore :meth:`get_state`; the Atoms (positions, momenta, theta, omega) come separately.

        (Or pass ``state=d`` to the constructor: then no tessellation of the
        deformed sample is made at all.)
        """
        self.state.set_state(d)
        self._nl = None
        self._S_mean = None
        self._setup_masses()
        self._evaluate(commit=False)
        if self.damping > 0:
            self._Fd, self._Td = self._damping_forces(self.atoms.get_velocities(), self.atoms.arrays["omega"])
        if self._friction_on:
            self._Ff, self._Tf = self.contact.friction(self.atoms, self.state, self.atoms.get_velocities(),
                                                       self.atoms.arrays["omega"], self.dt, advance=False)
        self._restore_counters(d)

    def _restore_counters(self, d):
        self.stored_work = float(d.get("stored_work", 0.0))
        self.dissipated = float(d.get("dissipated", 0.0))
        self.plastic_work = float(d.get("plastic_work", 0.0))
        self.switch_energy = float(d.get("switch_energy", 0.0))
        self.split_work = float(d.get("split_work", 0.0))
        self.volume_energy = float(d.get("volume_energy", 0.0))
        self.volume_syncs = int(d.get("volume_syncs", 0))
        self.remesh_count = int(d.get("remesh_count", 0))
        self._E_initial = float(d.get("E_initial", self._E_initial))
        if "remesh" in d:
            rs, re, hl = (float(x) for x in np.asarray(d["remesh"]))
            self.remesh_strain = None if rs < 0 else rs
            self.remesh_every = int(re)
            self.h_link = hl
        self.nsteps = int(d.get("nsteps", self.state.step))
        if "contact_S_mean" in d:
            self._S_mean = np.array(d["contact_S_mean"], dtype=float)
        if "forces" in d:
            self._F = np.array(d["forces"], dtype=float)
            self._T = np.array(d["torques"], dtype=float)
        if "damping_forces" in d and self.damping > 0:
            self._Fd = np.array(d["damping_forces"], dtype=float)
            self._Td = np.array(d["damping_torques"], dtype=float)
        if self.contact is not None and "contact" in d:
            self.contact.set_state(d["contact"])
            if "friction_forces" in d and self._friction_on:
                self._Ff = np.array(d["friction_forces"], dtype=float)
                self._Tf = np.array(d["friction_torques"], dtype=float)


def _c64(a):
    """``a`` as a C-contiguous float64 array (itself when it is one already)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def _own(atoms, name):
    """``atoms.arrays[name]`` for the step to update in place: made a C-contiguous float64 array of
    its own first if it is not one (as ``set_array`` would keep it)."""
    a = atoms.arrays[name]
    if not (a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable):
        a = atoms.arrays[name] = np.array(a, dtype=np.float64, order="C")
    return a


def out_f_trial(out, F1):
    """Forces of the trial evaluation (before response corrections) for the work integral."""
    return out.get("f_trial", F1)
