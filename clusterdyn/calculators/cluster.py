"""The Cluster Dynamics calculator (ASE): EOS-derived pair potentials on a numba Verlet list."""

import numpy as np
from ase.calculators.calculator import Calculator, PropertyNotImplementedError, all_changes

from ..engine import CDEngine
from ..errors import InputError
from ..materials import get_material
from ..neighbors import NeighborList, check_cell
from ..potentials import DEFAULT_RC, N_BINS, ClusterPotential, check_rc

#: arrays besides ASE's own whose change invalidates cached results
STATE_ARRAYS = ("material", "bonds0", "id")
#: values of the ``attraction`` parameter
ATTRACTION = ("all", "initial")


def mark_initial_bonds(atoms, rc=DEFAULT_RC, within=None):
    """Record the pairs within ``rc * r0_ab`` now as the set-up bonds (``attraction="initial"``).

    Writes ``atoms.arrays['bonds0']``: for every particle the stable ids
    (``arrays['id']``) of its bonded partners, padded with -1.  Being a
    per-particle array it follows slicing, sorting, H5MD and checkpoints.
    ``within``: name of a per-particle label array (e.g. ``"grain"``); only
    pairs with equal labels >= 0 are bonded, so pairs across grain boundaries
    only repel.
    """
    calc = ClusterDynamics(rc=rc)
    calc.setup(atoms)
    n = len(atoms)
    if "id" not in atoms.arrays:
        atoms.new_array("id", np.arange(n, dtype=np.int64))
    nl = NeighborList(calc.nl.cutoff, 0.0, half=False)
    nl.build(atoms.positions, atoms.cell.array, atoms.pbc)
    i, j, d, r = nl.pairs(atoms.positions)
    types = calc._check_types(atoms)
    cut = np.sqrt(calc.meta[types[i], types[j], 2])
    keep = r < cut
    if within is not None:
        if within not in atoms.arrays:
            raise InputError("within", within, f"a per-particle array of the Atoms ({sorted(atoms.arrays)})")
        lab = np.asarray(atoms.arrays[within])
        keep &= (lab[i] == lab[j]) & (lab[i] >= 0)
    i, j = i[keep], j[keep]
    counts = np.bincount(i, minlength=n)
    width = max(1, int(counts.max()) if n else 1)
    bonds = np.full((n, width), -1, dtype=np.int64)
    order = np.argsort(i, kind="stable")
    i, j = i[order], j[order]
    start = np.concatenate([[0], np.cumsum(counts)])
    col = np.arange(len(i)) - start[i]
    bonds[i, col] = atoms.arrays["id"][j]
    if "bonds0" in atoms.arrays:
        del atoms.arrays["bonds0"]
    atoms.new_array("bonds0", bonds)
    return bonds


def default_skin(rc):
    """Verlet skin as a multiple of r0: fcc second neighbours sit at sqrt(2) r0, so
    a skin up to ``1.40 - rc`` adds no pairs at rest; between 0.05 and 0.25."""
    return float(min(0.25, max(0.05, 1.40 - rc)))


class ClusterDynamics(Calculator):
    """Cluster Dynamics forces (CD eq. 1-2) as an ASE calculator.

    Particles carry a material id in ``atoms.arrays['material']``; material
    names and cluster sizes come from the arguments or, if omitted, from
    ``atoms.info['cd_materials']`` and ``atoms.info['cd_r0']`` (set by the
    builders).  A pair interacts while ``r < rc * r0_ab``; the energy is
    shifted by ``E(rc)`` so it stays continuous when pairs cross the cutoff.

    Implemented properties: ``energy``, ``free_energy``, ``energies`` (eV),
    ``forces`` (eV/Angstrom), ``stress`` (Voigt, eV/Angstrom^3, needs a 3-D cell),
    ``stresses`` (per-particle virial divided by the cell volume, ASE's
    convention: they sum to ``stress``; potential part only), ``virials``
    (per-particle virial W^a of CD eq. 3 without the kinetic part, Voigt, eV).
    Per-particle quantities are computed only when asked for.

    Parameters
    ----------
    rc : float, default 1.15
        Cutoff as a multiple of r0, in (1, sqrt 2).
    materials : list of str or Material, optional
        Material of each id (index = id).
    r0 : float or list of float, optional
        Cluster size of each id, Angstrom.
    skin : float, optional
        Verlet skin as a multiple of the smallest r0 (default: :func:`default_skin`).
    n_table : int, default :data:`clusterdyn.potentials.N_BINS` (10407)
        Bins of the cubic-Hermite pair tables, uniform in r^2 over [(R_MIN_FACTOR r0)^2, (rc r0)^2].
    attraction : "all" or "initial"
        ``"initial"``: attraction only between pairs bonded at set-up
        (``atoms.arrays['bonds0']``, see :func:`mark_initial_bonds`); pairs that
        come within the cutoff later only repel (docs/theory.md 1.5 remedy for the
        soft response at u ~ 2 km/s).

    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "stress", "stresses",
                              "virials"]
    default_parameters = {"rc": DEFAULT_RC, "materials": None, "r0": None, "skin": None,
                          "n_table": N_BINS, "attraction": "all"}
    nolabel = True

    def __init__(self, **kwargs):
        Calculator.__init__(self, **kwargs)
        check_rc(self.parameters.rc)
        if self.parameters.attraction not in ATTRACTION:
            raise InputError("attraction", self.parameters.attraction, "'all' or 'initial'")
        self._setup_key = None
        #: the :class:`~clusterdyn.engine.CDEngine` of the current set-up (None before it)
        self.engine = None
        self.potentials = None
        self._types_key = None
        self._types_cache = None
        self._spec_cache = None

    # -- set-up ------------------------------------------------------------------
    def set(self, **kwargs):
        changed = Calculator.set(self, **kwargs)
        if changed:
            self._setup_key = None
        return changed

    def check_state(self, atoms, tol=1e-15):
        changes = Calculator.check_state(self, atoms, tol)
        if self.atoms is not None:
            for name in STATE_ARRAYS:
                if not np.array_equal(self.atoms.arrays.get(name), atoms.arrays.get(name)):
                    changes.append(name)
        return changes

    def _material_spec(self, atoms):
        prm, info = self.parameters, atoms.info     # item access: Parameters' attributes are a Python call
        raw = (prm["materials"], prm["r0"], info.get("cd_materials"), info.get("cd_r0"))
        probe = repr(raw)
        if self._spec_cache is not None and self._spec_cache[0] == probe:
            return self._spec_cache[1]
        spec = self._material_spec_uncached(atoms)
        self._spec_cache = (probe, spec)
        return spec

    def _material_spec_uncached(self, atoms):
        mats = self.parameters.materials
        r0 = self.parameters.r0
        if mats is None:
            mats = atoms.info.get("cd_materials")
        if r0 is None:
            r0 = atoms.info.get("cd_r0")
        if mats is None or r0 is None:
            raise InputError("materials", mats, "material names and r0 given to ClusterDynamics or set "
                             "by a clusterdyn builder in atoms.info['cd_materials'], ['cd_r0']")
        if isinstance(mats, str):
            mats = [mats]
        r0 = list(np.atleast_1d(np.asarray(r0, dtype=float)))
        if len(r0) == 1 and len(mats) > 1:
            r0 = r0 * len(mats)
        if len(r0) != len(mats):
            raise InputError("r0", r0, f"one value or one per material ({len(mats)})")
        return tuple(get_material(m).name if not hasattr(m, "curve") else m for m in mats), tuple(r0)

    def setup(self, atoms):
        """Build potentials, tables and the neighbour list (once per material set)."""
        mats, r0 = self._material_spec(atoms)
        prm = self.parameters
        key = (mats, r0, float(prm["rc"]), prm["skin"], prm["n_table"])
        if key == self._setup_key:
            return
        rc = check_rc(prm["rc"])
        skin = default_skin(rc) if prm["skin"] is None else float(prm["skin"])
        if not skin >= 0:
            raise InputError("skin", self.parameters.skin, "a multiple of r0 >= 0")
        self.potentials = [ClusterPotential(m, r, rc) for m, r in zip(mats, r0)]
        self.engine = CDEngine(self.potentials, prm["n_table"], skin * min(r0))
        self.masses_t = np.array([p.mass for p in self.potentials])
        self._setup_key = key
        self._types_key = None

    # the engine's tables and list, as attributes of the calculator (read by exporters and tests)
    nl = property(lambda self: None if self.engine is None else self.engine.nl)
    meta = property(lambda self: self.engine.meta)
    tables = property(lambda self: self.engine.tables)
    coef = property(lambda self: self.engine.coef)
    gtab = property(lambda self: self.engine.gtab)
    last_stats = property(lambda self: None if self.engine is None else self.engine.last_stats)

    def _check_types(self, atoms):
        mid = atoms.arrays.get("material")
        n = len(atoms)
        if mid is None and "tags" in atoms.arrays and "cd_materials" in atoms.info:
            mid = atoms.arrays["tags"]     # Atoms back from an ASE .traj (DampedVerlet(trajectory=))
        if mid is None:
            if len(self.potentials) == 1:
                return np.zeros(n, np.int64)
            raise InputError("atoms.arrays['material']", None, "a material id per particle")
        mid = np.ascontiguousarray(mid, dtype=np.int64)
        if n and (mid.min() < 0 or mid.max() >= len(self.potentials)):
            raise InputError("atoms.arrays['material']", f"ids {mid.min()}..{mid.max()}",
                             f"ids in 0..{len(self.potentials) - 1}")
        return mid

    # -- the pair loop (the engine's) ----------------------------------------------------
    def compute(self, atoms, per_particle=False, damping=None, step=None, out=None, virial=True,
                energy=True, kick=None, forces=True, advanced=False, conservative=False):
        """Run the pair loop on ``atoms`` (no copy): :meth:`clusterdyn.engine.CDEngine.forces`
        with this calculator's material ids and set-up bonds.  Returns a dict of results.

        ``damping = (momenta_nc, invmass_n, eta_tt)`` selects the fused damped
        kernel (used by :class:`clusterdyn.md.DampedVerlet`); its forces include
        the damping term.  ``out``: an (N, 3) array to receive the forces
        (default: a new one).  ``virial=False`` skips the cell virial and
        ``energy=False`` the pair energy (the result's ``"energy"`` is then None).
        ``kick = (momenta_nc, h)`` adds ``h * forces`` to the momenta (the dynamics'
        second half kick).  ``forces=False`` (without damping, kick or out): the
        energy and virials only, no (N, 3) array made or written (``"forces"``
        is None).  ``advanced``: the positions are those the engine's last
        :meth:`~clusterdyn.engine.CDEngine.advance` made.  ``conservative``: a damped step's
        pass also gives the conservative forces apart (``"conservative"``, the same bits as an
        undamped pass), in the same pair loop.  Raises InstabilityError if a pair is closer than
        the tabulated range.

        The kernel is chosen per call from what is asked: one material or
        several (or ``attraction="initial"``), with or without damping, cell
        virial, energy, per-particle energies and virials; each is a separately
        compiled loop without the terms it does not use.
        """
        self.setup(atoms)
        eng = self.engine
        return eng.forces(atoms.arrays["positions"], atoms.cell.array, atoms.pbc, self._types(atoms, eng.nl.version),
                          self._bonds(atoms), per_particle=per_particle, damping=damping, step=step, out=out,
                          virial=virial, energy=energy, kick=kick, forces=forces, advanced=advanced,
                          conservative=conservative)

    def removed(self, keep_n):
        """The Atoms' particles where ``keep_n`` (bool, the old rows) is False were taken out, the
        others keeping their order: the engine's list is compacted with them
        (:meth:`clusterdyn.engine.CDEngine.compact`: no rebuild), or, when it can not be, rebuilt
        at the next compute; the cached results are dropped.  Returns True when the list was kept."""
        kept = self.engine is not None and self.engine.compact(keep_n)
        self.reset()
        self._types_key = self._types_cache = None
        return kept

    def reindexed(self):
        """The Atoms were put in the engine's row order (:meth:`clusterdyn.engine.CDEngine.reindex`):
        drop what was cached by array identity."""
        self.reset()
        self._types_key = self._types_cache = None

    def pairs_touching(self, atoms, mask_n, forces=None, damped=False):
        """What the listed pairs with at least one particle where ``mask_n`` is True contribute at
        the current positions: returns (energy, dissipation), eV and eV per ASE time unit, or
        None (nothing done) when ``damped`` is asked and the last damped force pass is not
        the last pass (its velocities are gone).  The energy is what the potential energy loses
        when those particles are taken out (the energy passes' pairs and rules).  With
        ``forces`` ((N, 3), caller's order: the last force pass's own, constraints apart), their
        pair forces are subtracted from it, with the pair damping at that pass's velocities when
        ``damped``: the forces that pass gives without those pairs
        (:func:`clusterdyn.engine.pair.pairs_touching`, one pass over the list)."""
        mask = np.ascontiguousarray(mask_n, dtype=np.bool_)
        if mask.shape != (len(atoms),):
            raise InputError("mask_n", f"shape {mask.shape}", f"one bool per particle ({len(atoms)},)")
        f = forces
        if f is not None and (f.shape != (len(atoms), 3) or f.dtype != np.float64 or not f.flags.c_contiguous):
            raise InputError("forces", f"{f.dtype} array of shape {f.shape}", f"C-contiguous float64 ({len(atoms)}, 3)")
        self.setup(atoms)
        types = self._check_types(atoms) if len(self.potentials) > 1 else None
        return self.engine.pairs_touching(atoms.arrays["positions"], atoms.cell.array, atoms.pbc, types,
                                          self._bonds(atoms), mask, forces=forces, damped=damped)

    def _types(self, atoms, key):
        """Material ids (checked); for one material checked once per list build or new array."""
        mid = atoms.arrays.get("material")
        if len(self.potentials) == 1:
            ck = (key, id(mid), len(atoms))
            if self._types_key == ck:
                return self._types_cache
            t = self._check_types(atoms)
            self._types_key, self._types_cache = ck, t
            return t
        return self._check_types(atoms)

    def _bond_args(self, atoms):
        """``(initial, bonds_nk, id_n)``: the set-up bonds as the LAMMPS export reads them (empty
        arrays without ``attraction="initial"``)."""
        b = self._bonds(atoms)
        return (False, np.zeros((0, 0), np.int64), np.zeros(0, np.int64)) if b is None else (True, *b)

    def _bonds(self, atoms):
        """``(bonds_nk, id_n)`` for ``attraction="initial"``, else None."""
        if self.parameters["attraction"] != "initial":
            return None
        bonds = atoms.arrays.get("bonds0")
        ids = atoms.arrays.get("id")
        if bonds is None or ids is None:
            raise InputError("atoms.arrays['bonds0']", None,
                             "set-up bonds for attraction='initial': call "
                             "clusterdyn.calculators.mark_initial_bonds(atoms) on the set-up configuration")
        return np.ascontiguousarray(bonds, np.int64), np.ascontiguousarray(ids, np.int64)

    # -- ASE ---------------------------------------------------------------------------
    def _refuse_triclinic(self, atoms):
        """A periodic cell must be orthorhombic.  Refused: one-line InputError, and Atoms changed by
        a caller since the last calculation (a cell filter's or optimiser's step) get back the cell
        and positions of that calculation, so the exception leaves no strained cell behind."""
        if atoms is None or not np.any(atoms.pbc):
            return
        try:
            check_cell(atoms.cell.array, atoms.pbc)
        except InputError:
            refused = np.round(atoms.cell.array, 6).tolist()
            last = getattr(self, "_last_box", None)   # (cell, positions, numbers) of the last calculation
            back = ""
            if last is not None and len(last[1]) == len(atoms) and np.array_equal(last[2], atoms.numbers):
                atoms.set_cell(last[0], scale_atoms=False)
                atoms.positions = last[1]
                back = "; the Atoms keep the cell and positions of the last calculation"
            raise InputError("atoms.cell", refused, "an orthorhombic cell when any axis is periodic",
                             hint="ClusterDynamics does not support triclinic periodic cells (see the "
                                  "ASE users' guide, 'Triclinic cells')" + back) from None

    def calculate_numerical_stress(self, atoms, d=1e-6, voigt=True):
        """Refused before the cell is touched: finite-difference shears make the periodic cell
        triclinic.  The analytic virial stress is ``atoms.get_stress()``."""
        if atoms is not None and np.any(atoms.pbc):
            raise InputError("calculate_numerical_stress", "a periodic cell",
                             "atoms.get_stress() (analytic virial stress; the finite-difference shears "
                             "need triclinic periodic cells, which ClusterDynamics does not support)")
        return Calculator.calculate_numerical_stress(self, atoms, d=d, voigt=voigt)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        self._refuse_triclinic(atoms)
        Calculator.calculate(self, atoms, properties, system_changes)
        atoms = self.atoms               # ASE's copy
        self._last_box = (atoms.cell.array, atoms.positions, atoms.numbers)
        want_pp = "energies" in properties or "stresses" in properties or "virials" in properties
        out = self.compute(atoms, per_particle=want_pp)
        self.results["energy"] = out["energy"]
        self.results["free_energy"] = out["energy"]
        self.results["forces"] = out["forces"]
        rank3 = atoms.cell.rank == 3
        if rank3:
            self.results["stress"] = out["virial"] / atoms.get_volume()
        elif "stress" in properties:
            raise PropertyNotImplementedError("stress needs a 3-D cell (atoms.cell has rank "
                                              f"{atoms.cell.rank})")
        if want_pp:
            self.results["energies"] = out["energies"]
            self.results["virials"] = out["virials"]
            if rank3:
                self.results["stresses"] = out["virials"] / atoms.get_volume()
            elif "stresses" in properties:
                raise PropertyNotImplementedError("stresses need a 3-D cell; use 'virials' (eV) instead")

    def publish(self, atoms, energy, forces=None):
        """Take the results of a pass run for ``atoms`` outside :meth:`calculate` (a dynamics
        step's, :class:`clusterdyn.md.DampedVerlet`): ``energy`` (eV) and, when given, the
        conservative ``forces`` ((N, 3), copied).  Until ``atoms`` change, ``get_potential_energy``
        and ``get_forces`` (and an H5MD frame) read them without a pass; the other properties
        are computed when asked, as usual."""
        self.reset()
        self.atoms = atoms.copy()
        self.results["energy"] = self.results["free_energy"] = energy
        if forces is not None:
            self.results["forces"] = forces.copy()

    # -- helpers for dynamics -------------------------------------------------
    def damping_matrix(self, J):
        """eta_tt[a, b] = 2 m_a m_b/(m_a+m_b) (Gamma_a + Gamma_b)/2, Gamma = c0/(J r0) (amu/time)."""
        g = np.array([p.c0 / (J * p.r0) for p in self.potentials])
        m = self.masses_t
        mu = 2.0 * m[:, None] * m[None, :] / (m[:, None] + m[None, :])
        return np.ascontiguousarray(mu * 0.5 * (g[:, None] + g[None, :]))

    def law(self, a, b):
        """Pair law (ClusterPotential or MixedPairPotential) of material ids a, b."""
        return self.tables[a][b].law
