"""The Cluster Dynamics calculator (ASE): EOS-derived pair potentials on a numba Verlet list."""

import math

import numba
import numpy as np
from ase.calculators.calculator import Calculator, PropertyNotImplementedError, all_changes
from ase.stress import full_3x3_to_voigt_6_stress  # noqa: F401  (convention reference)

from ..errors import InputError, InstabilityError
from ..materials import get_material
from ..neighbors import NeighborList
from ..potentials import DEFAULT_RC, N_BINS, ClusterPotential, MixedPairPotential, build_tables, check_rc
from ..engine.integrate import gather_velocities, kick_drift_gather
from ..buffers import grown
from ..parallel import STREAM_BLOCK, use_threads
from ..engine import pair as K

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


class _Stats(dict):
    """``last_stats`` of a :meth:`ClusterDynamics.compute`.  ``"closest"`` (the caller's rows of
    the closest pair) comes from the loop when it tracks it, else it is found when first read
    by a rerun of the loop's tracking variant (its buffers are scratch by then); it can be
    read until the next compute or step."""

    def __init__(self, calc, **kw):
        super().__init__(**kw)
        self._calc = calc
        self._token = calc._ncompute
        self._args = None

    def __missing__(self, key):
        if key != "closest" or self._args is None:
            raise KeyError(key)
        if self._calc._ncompute != self._token:
            raise KeyError("closest: read it before the next compute")
        kernel, args, stat, perm = self._args
        kernel(*args)
        k = int(np.argmin(stat[:, 1]))
        v = (int(perm[int(stat[k, 2])]), int(perm[int(stat[k, 3])])) if stat[k, 2] >= 0 else (-1, -1)
        self[key] = v
        self._args = None
        return v


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
        self.nl = None
        self.potentials = None
        self.last_stats = None
        self._buffers = None
        self._ncompute = 0
        self._advanced = None
        self._vs_token = None
        self._eta_tt = None
        self._bstat = None
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
        self.potentials = [ClusterPotential(m, r, rc) for m, r in zip(mats, r0)]
        coef, self.meta, self.tables = build_tables(self.potentials, int(prm["n_table"]))
        self.coef, self.gtab = K.kernel_tables(coef, self.meta)
        r0min = min(r0)
        skin = default_skin(rc) if prm["skin"] is None else float(prm["skin"])
        if not skin >= 0:
            raise InputError("skin", self.parameters.skin, "a multiple of r0 >= 0")
        cutoff = max(t.cutoff for row in self.tables for t in row)
        self.nl = NeighborList(cutoff, skin * r0min, half=True, sort=True, centered=True)
        self.masses_t = np.array([p.mass for p in self.potentials])
        m = self.meta
        #: squared cut-off and smallest tabulated distance in units of r0_ab^2 (largest over pair types)
        self._cut2n = float((m[:, :, 2] * m[:, :, 4]).max())
        self._rmin2n = float((m[:, :, 3] * m[:, :, 4]).max())
        self._setup_key = key
        self._buffers = None
        self._ncompute = 0
        self._advanced = None
        self._vs_token = None
        self._eta_tt = None
        self._bstat = None
        self._types_key = None

    def _check_types(self, atoms):
        mid = atoms.arrays.get("material")
        n = len(atoms)
        if mid is None:
            if len(self.potentials) == 1:
                return np.zeros(n, np.int64)
            raise InputError("atoms.arrays['material']", None, "a material id per particle")
        mid = np.ascontiguousarray(mid, dtype=np.int64)
        if n and (mid.min() < 0 or mid.max() >= len(self.potentials)):
            raise InputError("atoms.arrays['material']", f"ids {mid.min()}..{mid.max()}",
                             f"ids in 0..{len(self.potentials) - 1}")
        return mid

    def _layout(self, n, per_particle, damped):
        """Chunks and buffers of the current list (recomputed after each rebuild)."""
        nl = self.nl
        lay = self._buffers
        if lay is None or lay["n"] != n:
            # a new particle count (particles removed): the pair-slot buffers and the velocities'
            # store are kept (they grow, never shrink), so a removal allocates nothing of N's size
            old = lay or {"f_m3": np.empty((0, 3)), "e_m1": self._NO_PP1, "w_m6": self._NO_PP6, "vs_store": None}
            lay = {"n": n, "key": None, "vs": None, "f_m3": old["f_m3"], "e_m1": old["e_m1"], "w_m6": old["w_m6"],
                   "vs_store": old["vs_store"]}
            self._buffers = lay
        if lay["key"] != nl.version:
            nk = K.chunk_count(n, nl.layer_rows)
            lay["xs"] = nl.xs_nc          # the list's buffer of sorted positions (rewritten by each build)
            (lay["bounds"], lay["span"], lay["boff"], lay["cptr"], lay["clist"], lay["shared_n"],
             lay["shared_r"], lay["owner_r"]) = K.chunk_layout(nl.first_n, nl.jp_p, nl.j_mask, nk)
            lay["stat_k"] = np.empty((nk, 6))
            lay["vir_k6"] = np.empty((nk, 6))
            m = int(lay["boff"][-1])
            if lay["f_m3"].shape[0] < m:
                lay["f_m3"] = None          # let the old buffer go first: never both held
                lay["f_m3"] = np.empty((m + m // 8, 3))
                lay["e_m1"], lay["w_m6"] = self._NO_PP1, self._NO_PP6
            lay["key"] = nl.version
        m = lay["f_m3"].shape[0]
        if per_particle and lay["e_m1"].shape[0] != m:
            lay["e_m1"] = np.empty((m, 1))
            lay["w_m6"] = np.empty((m, 6))
        if damped and lay["vs"] is None:
            lay["vs_store"] = grown(lay["vs_store"], n)
            lay["vs"] = lay["vs_store"][:n]
        return lay

    _NO_PP1 = np.zeros((0, 1))
    _NO_PP6 = np.zeros((0, 6))
    _NO_V = np.zeros((0, 3))
    _NO_TYPES = np.zeros(0, np.int64)

    # -- the pair loop ---------------------------------------------------------
    def compute(self, atoms, per_particle=False, damping=None, step=None, out=None, virial=True,
                energy=True, kick=None, forces=True):
        """Run the pair loop on ``atoms`` (no copy).  Returns a dict of results.

        ``damping = (momenta_nc, invmass_n, eta_tt)`` selects the fused damped
        kernel (used by :class:`clusterdyn.md.DampedVerlet`); its forces include
        the damping term.  ``out``: an (N, 3) array to receive the forces
        (default: a new one).  ``virial=False`` skips the cell virial and
        ``energy=False`` the pair energy (the dynamics' steps; the result's
        ``"energy"`` is then None).  With damping the energy takes a second,
        conservative pass.  ``kick = (momenta_nc, h)`` adds ``h * forces`` to
        the momenta in the passes that write the forces (the dynamics' second
        half kick).  ``forces=False`` (without damping, kick or out): the
        energy and virials only, no (N, 3) array made or written (``"forces"``
        is None).  Raises InstabilityError if a pair is closer than the
        tabulated range (the step has failed then: the rows the pair loop wrote
        itself may have had their kick).

        The kernel is chosen per call from what is asked: one material or
        several (or ``attraction="initial"``), with or without damping, cell
        virial, per-particle energies and virials; each is a separately
        compiled loop without the terms it does not use.
        """
        if not forces and (damping is not None or kick is not None or out is not None):
            raise InputError("forces", forces, "True when damping, kick or out is given")
        self.setup(atoms)
        n = len(atoms)
        pos = atoms.arrays["positions"]
        nl = self.nl
        adv, self._advanced = self._advanced, None
        if adv is not None and (adv[0] != id(pos) or adv[1] != nl.version or adv[5] != self._setup_key):
            adv = None
        rebuilt = nl.update(pos, atoms.cell.array, atoms.pbc, displacement=None if adv is None else adv[2:4])
        fresh = adv is not None and not rebuilt  # the gathers of _advance are current
        initial, bonds, ids = self._bond_args(atoms)
        multi = len(self.potentials) > 1 or initial
        types = self._types(atoms, nl.version)
        lay = self._layout(n, per_particle, damping is not None)
        perm = nl.perm_n
        xs = lay["xs"]
        if not fresh and not rebuilt:       # a build (always sorted here) leaves them in xs
            nl.sorted_positions(pos, out=xs)
        types_s = types[perm] if multi else self._NO_TYPES
        vs, eta = self._NO_V, self._NO_ETA
        if damping is not None:
            p_nc, invm_n, eta = damping
            vs = lay["vs"]
            if not (fresh and adv[4]):
                gather_velocities(p_nc, invm_n, perm, vs)
            mode = "damped"
        elif per_particle:
            mode = "per_particle"
        elif virial or energy:
            mode = "virial"
        else:
            mode = "forces"
        stat, vir = lay["stat_k"], lay["vir_k6"]
        f_nc = self._NO_V if not forces else np.empty((n, 3)) if out is None else out
        # the step kernels (forces only, damped or not) write the rows no other chunk touches
        # themselves, with the half kick; reduce_shared sums the rest
        fin = mode in ("forces", "damped")
        p_kick, h = (self._NO_V, 0.0) if kick is None else (kick[0], float(kick[1]))
        args = (xs, types_s, nl.first_n, nl.jp_p, nl.img_shift, nl.image_sc, self.gtab, self.coef, self.meta,
                lay["bounds"], lay["span"], lay["boff"], lay["f_m3"], stat, vir, vs, eta, lay["e_m1"], lay["w_m6"],
                perm, bonds, ids, initial, lay["shared_n"], f_nc, p_kick, h)
        K.KERNELS[multi, mode](*args)
        k, low, nclose = K.chunk_stats(stat, perm)
        self._ncompute += 1
        # the step kernels take the smallest distance over every listed pair: beyond the cut-off
        # it means that no pair is within it
        x2 = stat[k, 1]
        stats = _Stats(self, min_r_over_r0=math.sqrt(x2) if x2 < self._cut2n else math.inf,
                       npairs=nl.npairs, nbuilds=nl.nbuilds)
        if stat[k, 2] >= 0:
            stats["closest"] = (int(stat[k, 2]), int(stat[k, 3]))
        else:
            # the tracking variant on the same arguments, without damping (vs, eta)
            stats._args = (K.KERNELS[multi, "virial"], args[:15] + (self._NO_V, self._NO_ETA) + args[17:],
                           stat, perm)
        self.last_stats = stats
        self._check_close(stat, types, step, x2, low, nclose)
        red = (lay["bounds"], lay["span"], lay["boff"], lay["cptr"], lay["clist"], perm)
        if fin:
            use_threads(lay["shared_r"].shape[0])
            K.reduce_shared(lay["f_m3"], *red, lay["shared_r"], lay["owner_r"], f_nc, p_kick, h)
            use_threads(n)
        elif forces:
            K.reduce_rows(lay["f_m3"], *red, f_nc, p_kick, h)
        res = {"forces": f_nc if forces else None, "energy": None if fin else float(stat[:, 0].sum())}
        if damping is not None:
            res["dissipation"] = float(stat[:, 5].sum())     # eV per ASE time, >= 0
        if mode in ("virial", "per_particle"):
            res["virial"] = vir.sum(axis=0)
        if per_particle:
            e = np.empty((n, 1))
            K.reduce_rows(lay["e_m1"], *red, e, self._NO_V, 0.0)
            res["energies"] = e[:, 0]
            w = np.empty((n, 6))
            K.reduce_rows(lay["w_m6"], *red, w, self._NO_V, 0.0)
            res["virials"] = w
        if mode == "damped" and energy:
            res["energy"] = self.compute(atoms, step=step, virial=False, forces=False)["energy"]
        if mode == "damped":
            # this pass's velocities stay in lay["vs"] until the next pass (pairs_touching)
            self._vs_token, self._eta_tt = (self._ncompute, nl.version), eta
        return res

    _NO_ETA = np.zeros((0, 0))

    def _advance(self, atoms, momenta, forces, invm, h, dt, damped):
        """The dynamics' first half kick and drift fused with the next pair loop's gathers.

        ``momenta += h forces; positions += dt momenta/m``
        (:func:`clusterdyn.engine.integrate.kick_drift_gather`), with the
        sorted positions (and velocities if ``damped``) and the rebuild test's
        displacements taken in the same pass; the next :meth:`compute` on these
        positions uses them.  Returns (max v^2, its particle), or None when the
        list is not ready for it (the caller then runs the separate passes).
        """
        nl = self.nl
        pos = atoms.arrays["positions"]
        n = len(atoms)
        # (a list compacted by a removal is ready: the layout follows the new count below)
        if (nl is None or nl.perm_n is None or nl.ref_nc is None or nl.ref_nc.shape != pos.shape
                or self._buffers is None or self._setup_key is None or pos.dtype != np.float64
                or not pos.flags.c_contiguous or not momenta.flags.c_contiguous
                or not forces.flags.c_contiguous or momenta.dtype != np.float64
                or forces.dtype != np.float64):
            return None
        lay = self._layout(n, False, damped)
        nb = (n + STREAM_BLOCK - 1) // STREAM_BLOCK
        if self._bstat is None or self._bstat.shape[0] != nb:
            self._bstat = np.empty((nb, 9))
        use_threads(n)
        self._ncompute += 1  # the sorted positions change: last_stats' lazy "closest" expires
        v2max, k, m2, h2 = kick_drift_gather(momenta, forces, pos, invm, h, dt, nl.row_n, nl.offs_nc,
                                             nl.ref_nc, lay["xs"], lay["vs"] if damped else self._NO_V,
                                             self._bstat)
        self._advanced = (id(pos), nl.version, m2, h2, damped, self._setup_key)
        return v2max, k

    def renumbered(self, order):
        """The Atoms were reordered in place, new particle k being old particle ``order[k]``
        (:meth:`clusterdyn.md.DampedVerlet.sort_atoms`; the list was renumbered with them): drop
        what was cached by array identity and rename the closest pair of :attr:`last_stats`."""
        self.reset()
        self._types_key = self._types_cache = None
        self._advanced = None
        st = self.last_stats
        if st is not None and dict.__contains__(st, "closest") and st["closest"][0] >= 0:
            st["closest"] = tuple(int(np.flatnonzero(order == i)[0]) for i in st["closest"])

    def removed(self, keep_n):
        """The Atoms' particles where ``keep_n`` (bool, the old rows) is False were taken out, the
        others keeping their order (:meth:`clusterdyn.md.DampedVerlet.remove_outside`): the list
        is compacted with them (:meth:`clusterdyn.neighbors.NeighborList.remove`: no rebuild), or,
        when it can not be, rebuilt at the next compute; what was cached by array identity or
        row is dropped.  Returns True when the list was kept."""
        nl = self.nl
        kept = nl is not None and nl.remove(keep_n)
        self.reset()
        self._types_key = self._types_cache = None
        self._advanced = None
        self._ncompute += 1
        self.last_stats = None
        return kept

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
        f = self._NO_V if forces is None else forces
        if forces is not None and (f.shape != (len(atoms), 3) or f.dtype != np.float64 or not f.flags.c_contiguous):
            raise InputError("forces", f"{f.dtype} array of shape {f.shape}", f"C-contiguous float64 ({len(atoms)}, 3)")
        self.setup(atoms)
        nl = self.nl
        lay = self._buffers
        vs = self._NO_V
        if damped:
            if self._vs_token != (self._ncompute, nl.version) or lay is None or lay["vs"] is None:
                return None
            vs = lay["vs"]
        pos = atoms.arrays["positions"]
        if nl.update(pos, atoms.cell.array, atoms.pbc) and damped:
            return None
        xs = nl.sorted_positions(pos, out=nl.xs_nc)
        initial, bonds, ids = self._bond_args(atoms)
        types = self._check_types(atoms) if len(self.potentials) > 1 else self._NO_TYPES
        e, d = K.pairs_touching(xs, types, nl.first_n, nl.jp_p, nl.img_shift, nl.image_sc, self.gtab, self.coef,
                                self.meta, mask, nl.perm_n, bonds, ids, initial, vs,
                                self._eta_tt if damped else self._NO_ETA, f)
        return float(e), float(d)

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

    _NO_BONDS = np.zeros((0, 0), np.int64)
    _NO_IDS = np.zeros(0, np.int64)

    def _bond_args(self, atoms):
        if self.parameters["attraction"] != "initial":
            return False, self._NO_BONDS, self._NO_IDS
        bonds = atoms.arrays.get("bonds0")
        ids = atoms.arrays.get("id")
        if bonds is None or ids is None:
            raise InputError("atoms.arrays['bonds0']", None,
                             "set-up bonds for attraction='initial': call "
                             "clusterdyn.calculators.mark_initial_bonds(atoms) on the set-up configuration")
        return True, np.ascontiguousarray(bonds, np.int64), np.ascontiguousarray(ids, np.int64)

    def _check_close(self, stat, types, step, x2, low, nclose):
        """``x2``: the smallest r^2/r0^2 of the pass (NaN if any is); ``low``, ``nclose``: the
        smallest and the sum of the chunks' counts of pairs below the table
        (:func:`~clusterdyn.engine.pair.chunk_stats`)."""
        if low < 0:
            # a single-material step kernel does not count the pairs below the table: recount
            # (the tracking variant) only when the smallest distance is below it
            if x2 > self._rmin2n:
                return
            self.last_stats["closest"]            # reruns the loop's tracking variant into stat
            nclose = stat[:, 4].sum()
            x2 = stat[:, 1].min()
        if nclose > 0:
            i, j = self.last_stats["closest"]  # may rerun the loop into the same buffers
            a, b = types[i], types[j]
            r0ab = 1.0 / math.sqrt(self.meta[a, b, 4])
            r = math.sqrt(x2) * r0ab
            raise InstabilityError(
                f"{int(nclose)} pair(s) closer than the potential's tabulated range "
                f"(r_min = {math.sqrt(self.meta[a, b, 3]) / r0ab:.2f} r0); the time step is too large for this "
                "compression or velocity, or the sample overlaps",
                step=step, particles=(i, j), quantity="distance r/r0", value=r / r0ab,
                limit=math.sqrt(self.meta[a, b, 3]) / r0ab)

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        Calculator.calculate(self, atoms, properties, system_changes)
        atoms = self.atoms
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
