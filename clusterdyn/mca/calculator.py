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

    Properties: ``energy`` / ``free_energy`` (eV; the elastic energy of the
    automata from their stress tensors), ``energies`` (N,), ``forces`` (N, 3)
    eV/Angstrom, ``torques`` (N, 3) eV, ``stresses`` (N, 6) Voigt per automaton
    (tension positive, eV/Angstrom^3), ``stress`` (6,) volume-averaged over the
    cell (3D cells only).
    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "torques", "stress",
                              "stresses"]
    default_parameters = {}
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
        return self.state

    # --------------------------------------------------------------- evaluation
    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        if "stress" in properties and self.atoms.cell.rank != 3:
            raise PropertyNotImplementedError("stress needs a 3D cell (use 'stresses' per automaton)")
        st = self.setup(self.atoms)
        out = self.evaluate(self.atoms, st)
        self.trial = out
        self._state_version = st.version
        self._fill_results(out)

    def _fill_results(self, out):
        e = out["e_n"]
        self.results["energies"] = e.copy()
        self.results["energy"] = float(e.sum())
        self.results["free_energy"] = float(e.sum())
        self.results["forces"] = out["f_nc"].copy()
        self.results["torques"] = out["t_nc"].copy()
        s = out["s_ncc"]
        self.results["stresses"] = full_3x3_to_voigt_6_stress(s)
        if self.atoms.cell.rank == 3:
            om = out["omega_n"]
            tot = (s * om[:, None, None]).sum(axis=0) / self.atoms.get_volume()
            self.results["stress"] = full_3x3_to_voigt_6_stress(tot)

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
