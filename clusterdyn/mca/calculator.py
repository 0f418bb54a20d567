"""The MCA calculator (ASE): forces, torques and automaton stresses from positions and pair state.

docs/theory.md 2.2-2.5.  The calculator evaluates the *trial* (elastic predictor)
state at the current positions from the committed state held by an
:class:`~clusterdyn.mca.state.MCAState`: the increments of elongation and of
objective tangential displacement since the last commit, split between the
two automata of each pair, give the trial specific forces

    sigma_ij = sigma_ij^last + (1-D) [2G_i d eps_ij + (1 - 2G_i/3K_i) dP_i],
    tau_ij   = R tau_ij^last + (1-D) 2 G_i G_j du_t / (q_ij G_j + q_ji G_i),

from which forces, torques (MCA 6) and the Love-Weber stress of every
automaton follow.  A pure function of positions, rotations and state: it
never changes the state (the dynamics commits it between steps, and runs the
response functions then).  Called at the committed positions it returns the
committed forces.
"""

import sys
import warnings
import weakref

import numpy as np
from ase.calculators.calculator import Calculator, PropertyNotImplementedError, all_changes
from ase.stress import full_3x3_to_voigt_6_stress

from ..parallel import use_threads
from . import kernels as K
from .state import MCAState, _box


class MCA(Calculator):
    """Movable Cellular Automata (ASE calculator).

    Parameters
    ----------
    materials : list of Material or names, optional
        Indexed by ``atoms.arrays['material']``; default ``atoms.info['mca_materials']``.
    interfaces : dict {(m1, m2): (sigma_t, sigma_c)}, optional
        Strength of pairs joining two materials (eV/Angstrom^3).
    dim : 3 or 2 (plane strain), optional; default ``atoms.info['mca_dim']`` or 3.
    state : MCAState, optional
        Use this state (otherwise built from the atoms at the first call, or by
        :class:`MCADynamics`).

    Notes
    -----
    Properties (ASE's conventions):

    - ``energy`` / ``free_energy`` (eV): the energy that, with the Atoms'
      (translational) kinetic energy, is conserved without damping, so that
      ``atoms.get_total_energy()`` and MDLogger's Etot are the conserved
      total: the rotational kinetic energy of the automata (ASE's Atoms know
      only translation) plus, under an :class:`~clusterdyn.mca.MCADynamics`,
      the stored work of the pair forces (``dyn.stored_work``, docs/mca.md
      "Energy"), or, without one, the elastic energy of the automata from
      their stress tensors;
    - ``energies`` (N,): per automaton, elastic + rotational (their sum is
      ``energy`` without a dynamics; under one ``energy`` differs from it by
      the integration residual of the ledger, ``dyn.ledger()``);
    - ``forces`` (N, 3) eV/Angstrom, ``torques`` (N, 3) eV;
    - ``stress`` (6,) Voigt, eV/Angstrom^3, tension positive: the automata's
      stresses averaged over the cell volume (3D cells only);
    - ``stresses`` (N, 6): per automaton ``sigma_i Omega_i / V``, extensive as
      in ASE (they sum to ``stress``; 3D cells only), like
      :class:`~clusterdyn.calculators.ClusterDynamics`;
    - ``automaton_stresses`` (N, 6): the automata's own (intensive) stress
      tensors ``sigma_i`` (any cell).

    ``parameters`` / ``todict()`` name the materials, the interfaces and ``dim``.
    Only :class:`~clusterdyn.mca.MCADynamics` integrates MCA (rotations, pair
    history); another ASE integrator warns once.
    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "torques", "stress",
                              "stresses", "automaton_stresses"]
    default_parameters = {"materials": None, "interfaces": None, "dim": None}
    #: per-particle arrays the result depends on (besides positions)
    state_arrays = ("theta", "id", "material", "radius")

    def __init__(self, materials=None, interfaces=None, dim=None, state=None, **kwargs):
        super().__init__(**kwargs)
        self.materials = materials
        self.interfaces = interfaces
        self.dim = dim
        self.state = state
        self.trial = None
        self._state_version = None
        self._dynamics = None          # weakref to the MCADynamics driving this calculator
        self._warned_driver = False
        self._set_parameters()

    def _set_parameters(self):
        """``parameters`` as plain values: material names, interfaces as [m1, m2, sigma_t, sigma_c]."""
        mats = self.materials
        if mats is None and self.state is not None:
            mats = self.state.materials
        names = None if mats is None else [str(getattr(m, "name", m)) for m in mats]
        inter = None if self.interfaces is None else [
            [str(getattr(a, "name", a)), str(getattr(b, "name", b)), float(v[0]), float(v[1])]
            for (a, b), v in self.interfaces.items()]
        dim = self.dim if self.dim is not None or self.state is None else self.state.dim
        self.parameters.update(materials=names, interfaces=inter,
                               dim=None if dim is None else int(dim))

    def attach_dynamics(self, dyn):
        """Called by :class:`~clusterdyn.mca.MCADynamics`: ``energy`` then includes its stored work."""
        self._dynamics = weakref.ref(dyn)

    def _driver(self):
        return None if self._dynamics is None else self._dynamics()

    def _warn_foreign_integrator(self):
        """Warn once when an ASE MolecularDynamics other than MCADynamics drives this calculator."""
        if self._warned_driver or self._driver() is not None:
            return
        from ase.md.md import MolecularDynamics
        f = sys._getframe(2)
        for _ in range(30):
            if f is None:
                break
            obj = f.f_locals.get("self")
            if isinstance(obj, MolecularDynamics):
                self._warned_driver = True
                warnings.warn(f"{type(obj).__name__} drives an MCA calculator: it ignores the automata's "
                              "rotations (torques) and never commits the pair history, so links neither "
                              "break nor deform plastically; integrate MCA with clusterdyn.mca.MCADynamics",
                              stacklevel=2)
                break
            f = f.f_back

    # --------------------------------------------------------------- ASE cache
    def check_state(self, atoms, tol=1e-15):
        changes = super().check_state(atoms, tol=tol)
        if self.atoms is not None:
            for k in self.state_arrays:
                a, b = self.atoms.arrays.get(k), atoms.arrays.get(k)
                if (a is None) != (b is None) or (a is not None and not np.array_equal(a, b)):
                    changes.append(k)
        if self.state is not None and self._state_version != self.state.version:
            changes.append("mca_state")
        return changes

    def setup(self, atoms):
        """Build the MCA state (tessellation, pair table) for ``atoms`` if not done yet."""
        if self.state is None:
            self.state = MCAState(atoms, self.materials, self.interfaces, self.dim)
        if self.parameters.get("materials") is None:
            self._set_parameters()
        return self.state

    # --------------------------------------------------------------- evaluation
    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        if "stress" in properties and self.atoms.cell.rank != 3:
            raise PropertyNotImplementedError("stress needs a 3D cell (use 'stresses' per automaton)")
        self._warn_foreign_integrator()
        st = self.setup(self.atoms)
        out = self.evaluate(self.atoms, st)
        self.trial = out
        self._state_version = st.version
        self._fill_results(out)

    def rotational_energies(self, atoms):
        """Rotational kinetic energy of each automaton, ``J w^2 / 2`` (eV; spheres
        ``J = m d^2/10``, plane strain discs ``m d^2/8``, as :class:`MCADynamics`)."""
        w = atoms.arrays.get("omega")
        if w is None or "radius" not in atoms.arrays:
            return np.zeros(len(atoms))
        d = 2.0 * np.asarray(atoms.arrays["radius"], float)
        dim = self.state.dim if self.state is not None else (self.dim or 3)
        J = atoms.get_masses() * d * d / (8.0 if dim == 2 else 10.0)
        return 0.5 * J * np.sum(np.asarray(w, float) ** 2, axis=1)

    def _fill_results(self, out):
        e = out["e_n"] + self.rotational_energies(self.atoms)
        self.results["energies"] = e
        self.results["energy"] = float(e.sum())
        self.results["free_energy"] = float(e.sum())
        self.results["forces"] = out["f_nc"].copy()
        self.results["torques"] = out["t_nc"].copy()
        s = out["s_ncc"]
        self.results["automaton_stresses"] = full_3x3_to_voigt_6_stress(s)
        if self.atoms.cell.rank == 3:
            om = out["omega_n"]
            per = s * (om / self.atoms.get_volume())[:, None, None]
            self.results["stresses"] = full_3x3_to_voigt_6_stress(per)
            self.results["stress"] = full_3x3_to_voigt_6_stress(per.sum(axis=0))

    def get_property(self, name, atoms=None, allow_calculation=True):
        if name == "stresses" and (atoms if atoms is not None else self.atoms) is not None \
                and (atoms if atoms is not None else self.atoms).cell.rank != 3:
            raise PropertyNotImplementedError("MCA 'stresses' are per cell volume (ASE): they need a 3D "
                                              "cell; 'automaton_stresses' are the automata's own tensors")
        value = super().get_property(name, atoms, allow_calculation)
        dyn = self._driver()
        if name in ("energy", "free_energy") and value is not None and dyn is not None:
            a = atoms if atoms is not None else self.atoms
            value = float(dyn.stored_work + self.rotational_energies(a).sum())
        return value

    def get_automaton_stresses(self, atoms=None):
        return self.get_property("automaton_stresses", atoms)

    def evaluate(self, atoms, st):
        """Trial evaluation: a dict of arrays (forces, torques, tensors, trial pair forces)."""
        i_p, j_p, first_n, side_p, side_s, perm = st.pair_rows(atoms)
        n = len(atoms)
        use_threads(n)        # the kernels' thread count (their results do not depend on it)
        P = st.npairs
        pos = np.ascontiguousarray(atoms.positions, dtype=np.float64)
        if st.dim == 2:
            theta = np.zeros((n, 3))
            if "theta" in atoms.arrays:
                theta[:, 2] = atoms.arrays["theta"][:, 2]
        else:
            theta = np.ascontiguousarray(atoms.arrays.get("theta", np.zeros((n, 3))), dtype=np.float64)
        perm, ident, G_n, K_n, A_n, lk_n, M_n, omega_n = st.automaton_constants(atoms)
        thlast = st.thlast_nc if ident else np.ascontiguousarray(st.thlast_nc[perm])
        box_c, periodic_c = _box(atoms)
        d_pc = np.empty((P, 3))
        r_p = np.empty(P)
        dr_p = np.empty(P)
        arm_p2 = np.empty((P, 2))
        dtau_pc = np.empty((P, 3))
        taurot = np.empty((P, 2, 3))
        deps = np.empty((P, 2))
        dB = np.empty(n)
        dP = np.empty(n)
        sigt = np.empty((P, 2))
        taut = np.empty((P, 2, 3))
        f = np.empty((n, 3))
        t = np.empty((n, 3))
        s = np.empty((n, 3, 3))
        e = np.empty(n)
        # one call: rotations, geometry, strain split by stiffness (force balance of the 2G eps
        # parts; the mean-stress terms enter the pair force as the stiffness-weighted mean of the
        # two sides, docs/mca.md), volume change, trial pair forces, sums (kernels.trial_forces)
        K.trial_forces(pos, theta, thlast, i_p, j_p, first_n, side_p, side_s, st.dlast_pc, st.q0_p2,
                       st.S_p, st.linked_p, st.sig_p2, st.tau_p2c, st.D_p, st.r0_p, st.mu_p, G_n, K_n,
                       A_n, lk_n, M_n, omega_n, box_c, periodic_c, bool(st.flags["contacts"]),
                       np.empty((n, 9)), d_pc, r_p, dr_p, arm_p2, dtau_pc, taurot, deps, dB, dP, sigt,
                       taut, np.empty((P, 3)), np.empty((P, 3)), np.empty((P, 3)), f, t, s, e)
        if st.dim == 2:
            f[:, 2] = 0.0
            t[:, :2] = 0.0
        if not np.isfinite(np.sum(f)):
            bad = ~np.isfinite(f).all(axis=1)
            from ..errors import InstabilityError
            rows = np.nonzero(bad)[0]
            raise InstabilityError("non-finite MCA force", step=st.step,
                                   particles=atoms.arrays["id"][rows[:5]], quantity="force")
        return {"f_nc": f, "t_nc": t, "s_ncc": s, "e_n": e, "sig_p2": sigt, "tau_p2c": taut,
                "d_pc": d_pc, "r_p": r_p, "arm_p2": arm_p2, "theta_nc": theta, "omega_n": omega_n,
                "i_p": i_p, "j_p": j_p, "perm": perm, "dP_n": dP}

    def wall_defaults(self, atoms):
        """Default stiffness K and reach d_c of a :class:`~clusterdyn.md.Wall`, per material.

        The wall stands in for the mirror image of a touching automaton: a
        half automaton (length d/2) in uniaxial strain on a flat face of
        area d^2 (a (100) face of the fcc packing has one automaton per d^2),
        ``k = M d^2 / (d/2) = 2 M d`` with ``M = K + 4G/3``; the harmonic wall
        ``E = K_w (d_c - x)^2`` has stiffness ``2 K_w``, so ``K_w = M d`` and
        ``d_c = d/2`` (the face touches the wall where the centre is d/2 away).
        d is the mean automaton size of each material.
        """
        from .state import mca_materials_of
        mats = mca_materials_of(atoms, self.materials)
        rad = np.asarray(atoms.arrays["radius"], float)
        mid = np.asarray(atoms.arrays["material"], np.int64)
        K = np.empty(len(mats))
        dc = np.empty(len(mats))
        for m, mat in enumerate(mats):
            sel = mid == m
            d = 2.0 * float(rad[sel].mean() if sel.any() else rad.mean())
            K[m] = (mat.K + 4.0 * mat.G / 3.0) * d
            dc[m] = 0.5 * d
        return K, dc

    def get_torques(self, atoms=None):
        return self.get_property("torques", atoms)
