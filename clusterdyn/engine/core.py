"""The Cluster Dynamics engine: the state of a CD run's pair loop and the operations on it.

:class:`CDEngine` owns the pair tables, the neighbour list (particles in cell order) and the
buffers kept in that row order (the chunks' force rows, the sorted velocities), and offers:

- :meth:`~CDEngine.forces`: one pair pass (forces, energy, virials as asked);
- :meth:`~CDEngine.advance`: velocity Verlet's first half kick and drift fused with the gathers
  of the next pass (:mod:`clusterdyn.engine.integrate`); the next :meth:`~CDEngine.forces`
  called with ``advanced=True`` uses them;
- :meth:`~CDEngine.sort_order` / :meth:`~CDEngine.reindex`: the particles are put into the
  list's row order (the caller permutes its arrays; the list follows, no rebuild);
- :meth:`~CDEngine.compact`: particles were removed (the list is compacted, no rebuild);
- :meth:`~CDEngine.pairs_touching`: what the pairs of some particles contribute (removal).

It works on arrays (positions, momenta, material ids in the caller's order), knows no ASE
object: :class:`clusterdyn.calculators.ClusterDynamics` is its ASE face, and
:class:`clusterdyn.md.DampedVerlet` drives its steps.  :attr:`~CDEngine.passes` counts the pair
passes by kind, so that a test can show what a run costs.
"""

import math
from collections import Counter

import numpy as np

from ..buffers import grown
from ..errors import InputError, InstabilityError
from ..neighbors import NeighborList
from ..parallel import STREAM_BLOCK, use_threads
from ..potentials import build_tables
from . import chunks as C
from . import pair as K
from .integrate import gather_velocities, kick_drift_gather

_NO_PP1 = np.zeros((0, 1))
_NO_PP6 = np.zeros((0, 6))
_NO_V = np.zeros((0, 3))
_NO_ETA = np.zeros((0, 0))
_NO_TYPES = np.zeros(0, np.int64)
_NO_BONDS = np.zeros((0, 0), np.int64)
_NO_IDS = np.zeros(0, np.int64)


class PassStats(dict):
    """``last_stats`` of a pass: ``min_r_over_r0``, ``npairs``, ``nbuilds`` and ``"closest"`` (the
    caller's rows of the closest pair).  ``"closest"`` comes from the loop when it tracks it, else
    it is found when first read by a rerun of the loop's tracking variant (its buffers are scratch
    by then); it can be read until the engine's next pass or step."""

    def __init__(self, engine, **kw):
        super().__init__(**kw)
        self._engine = engine
        self._token = engine.generation
        self._rerun = None

    def __missing__(self, key):
        if key != "closest" or self._rerun is None:
            raise KeyError(key)
        if self._engine.generation != self._token:
            raise KeyError("closest: read it before the next compute")
        # the tracking variant on the pass's arguments, without damping (vs, eta)
        multi, args, ch, buf, fin, stat, perm = self._rerun
        e = self._engine
        track = K.select(multi, damped=False, per_particle=False, virial=True, energy=True, step=False)
        K.run(track, args, (e.gtab, e.coef, e.meta, _NO_ETA), ch, buf[:3] + (_NO_V,) + buf[4:], fin)
        k = int(np.argmin(stat[:, 1]))
        v = (int(perm[int(stat[k, 2])]), int(perm[int(stat[k, 3])])) if stat[k, 2] >= 0 else (-1, -1)
        self[key] = v
        self._rerun = None
        return v


class CDEngine:
    """Pair tables, neighbour list and row-order buffers of one Cluster Dynamics set-up.

    Parameters
    ----------
    potentials : list of ClusterPotential
        One per material id.
    n_table : int
        Bins of the pair tables (:func:`clusterdyn.potentials.build_tables`).
    skin : float
        Verlet skin, Angstrom.
    """

    def __init__(self, potentials, n_table, skin):
        self.potentials = potentials
        coef, self.meta, self.tables = build_tables(potentials, int(n_table))
        self.coef, self.gtab = K.kernel_tables(coef, self.meta)
        cutoff = max(t.cutoff for row in self.tables for t in row)
        self.nl = NeighborList(cutoff, skin, half=True, sort=True, centered=True)
        m = self.meta
        #: squared cut-off and smallest tabulated distance in units of r0_ab^2 (largest over pair types)
        self._cut2n = float((m[:, :, 2] * m[:, :, 4]).max())
        self._rmin2n = float((m[:, :, 3] * m[:, :, 4]).max())
        #: pair passes run, by kind: "step" (a dynamics step's force pass), "forces" (any other
        #: pass that writes forces), "energy" (energy and virials only), "touching" (removals)
        self.passes = Counter()
        #: changes whenever the sorted buffers are rewritten (a pass, a step, a sort, a removal)
        self.generation = 0
        self.last_stats = None
        self._lay = None
        self._pending = None       # (m2, h2, damped) of the last advance, for the next pass
        self._vs_pass = None       # the generation whose damped pass left its velocities in vs
        self._eta_tt = None
        self._bstat = None
        self._variants = {}        # K.select's answers, by what a pass asks

    @property
    def multi(self):
        return len(self.potentials) > 1

    # -- buffers -------------------------------------------------------------------
    def _layout(self, n, per_particle, damped, conservative=False):
        """Chunks and buffers of the current list (recomputed after each rebuild)."""
        nl = self.nl
        lay = self._lay
        if lay is None or lay["n"] != n:
            # a new particle count (particles removed): the pair-slot buffers and the velocities'
            # store are kept (they grow, never shrink), so a removal allocates nothing of N's size
            old = lay or {"f_m3": np.empty((0, 3)), "e_m1": _NO_PP1, "w_m6": _NO_PP6, "c_m3": _NO_V,
                          "vs_store": None}
            lay = {"n": n, "key": None, "vs": None, "f_m3": old["f_m3"], "e_m1": old["e_m1"], "w_m6": old["w_m6"],
                   "c_m3": old["c_m3"], "vs_store": old["vs_store"]}
            self._lay = lay
        if lay["key"] != nl.version:
            nk = C.chunk_count(n, nl.layer_rows)
            lay["xs"] = nl.xs_nc          # the list's buffer of sorted positions (rewritten by each build)
            lay["chunks"] = C.chunk_layout(nl.first_n, nl.jp_p, nl.j_mask, nk)
            lay["ch"] = tuple(lay["chunks"])          # as the kernels take it
            lay["stat_k"] = np.empty((nk, 6))
            lay["vir_k6"] = np.empty((nk, 6))
            m = int(lay["chunks"].boff[-1])
            if lay["f_m3"].shape[0] < m:
                lay["f_m3"] = None          # let the old buffer go first: never both held
                lay["f_m3"] = np.empty((m + m // 8, 3))
                lay["e_m1"], lay["w_m6"], lay["c_m3"] = _NO_PP1, _NO_PP6, _NO_V
            lay["key"] = nl.version
        m = lay["f_m3"].shape[0]
        if per_particle and lay["e_m1"].shape[0] != m:
            lay["e_m1"] = np.empty((m, 1))
            lay["w_m6"] = np.empty((m, 6))
        if conservative and lay["c_m3"].shape[0] != m:
            lay["c_m3"] = np.empty((m, 3))
        if damped and lay["vs"] is None:
            lay["vs_store"] = grown(lay["vs_store"], n)
            lay["vs"] = lay["vs_store"][:n]
        return lay

    # -- one pair pass -------------------------------------------------------------------
    def forces(self, pos, cell, pbc, types, bonds=None, *, per_particle=False, damping=None, step=None,
               out=None, virial=True, energy=True, kick=None, forces=True, advanced=False, conservative=False):
        """One pair pass over ``pos`` ((N, 3), caller's order).  Returns a dict of results.

        ``types``: checked material ids (N,); ``bonds = (bonds_nk, id_n)`` for
        ``attraction="initial"`` (None: every pair attracts).  ``damping = (momenta_nc,
        invmass_n, eta_tt)`` selects the damped kernel; its forces include the damping term.
        ``out``: an (N, 3) array to receive the forces.  ``virial=False`` skips the cell virial
        and ``energy=False`` the pair energy (``"energy"`` is then None).  With damping the
        energy takes a second, conservative pass, unless the step kernel takes it (``energy``
        with ``kick`` or ``out``: the step variants with the energy).  ``kick = (momenta_nc, h)``
        adds ``h * forces`` to the momenta.  ``forces=False`` (without damping, kick or out):
        the energy and virials only.  ``advanced=True``: the positions are those of the last
        :meth:`advance`, whose gathers this pass uses.  ``conservative=True`` (with damping, kick
        or out, and ``energy``): the damped step also gives the conservative forces apart,
        ``"conservative"`` ((N, 3), caller's order), the same bits as a pass without damping
        gives, in the same pair loop (no second pass).  Raises InstabilityError if a pair is
        closer than the tabulated range (the step has failed then: the rows the pair loop wrote
        itself may have had their kick).
        """
        if not forces and (damping is not None or kick is not None or out is not None):
            raise InputError("forces", forces, "True when damping, kick or out is given")
        if conservative and (damping is None or not energy or (kick is None and out is None)):
            raise InputError("conservative", conservative, "False unless a damped step's pass (damping, kick "
                             "or out, energy) is asked")
        n = pos.shape[0]
        nl = self.nl
        adv, self._pending = self._pending, None
        if not advanced or (adv is not None and adv[3] != nl.version):
            adv = None
        rebuilt = nl.update(pos, cell, pbc, displacement=None if adv is None else adv[:2])
        fresh = adv is not None and not rebuilt  # the gathers of advance() are current
        initial = bonds is not None
        bonds_nk, id_n = bonds if initial else (_NO_BONDS, _NO_IDS)
        multi = self.multi or initial
        lay = self._layout(n, per_particle, damping is not None, conservative)
        perm = nl.perm_n
        xs = lay["xs"]
        if not fresh and not rebuilt:       # a build (always sorted here) leaves them in xs
            nl.sorted_positions(pos, out=xs)
        vs, eta = _NO_V, _NO_ETA
        if damping is not None:
            p_nc, invm_n, eta = damping
            vs = lay["vs"]
            if not (fresh and adv[2]):
                gather_velocities(p_nc, invm_n, perm, vs)
        key = (multi, damping is not None, per_particle, virial, energy, kick is not None or out is not None,
               conservative)
        variant = self._variants.get(key)
        if variant is None:
            variant = self._variants[key] = K.select(key[0], damped=key[1], per_particle=key[2], virial=key[3],
                                                     energy=key[4], step=key[5], conservative=key[6])
        stat, vir = lay["stat_k"], lay["vir_k6"]
        f_nc = _NO_V if not forces else np.empty((n, 3)) if out is None else out
        p_kick, h = (_NO_V, 0.0) if kick is None else (kick[0], float(kick[1]))
        # the kernels' arguments: plain tuples in the field order of K.PairArgs, K.Tables,
        # K.PassBuffers and K.Finish (numba types a plain tuple of arrays in C; a namedtuple costs
        # about 12 us more a call)
        args = (xs, types[perm] if multi else _NO_TYPES, nl.first_n, nl.jp_p, nl.img_shift, nl.image_sc, perm,
                bonds_nk, id_n, initial)
        tab = (self.gtab, self.coef, self.meta, eta)
        buf = (lay["f_m3"], stat, vir, vs, lay["e_m1"], lay["w_m6"], lay["c_m3"] if conservative else _NO_V)
        fin = (f_nc, p_kick, h)
        ch = lay["ch"]
        K.run(variant, args, tab, ch, buf, fin)
        self.generation += 1
        self.passes["step" if kick is not None else "forces" if forces else "energy"] += 1
        k, low, nclose = C.chunk_stats(stat, perm)
        # the step kernels take the smallest distance over every listed pair: beyond the cut-off
        # it means that no pair is within it
        x2 = stat[k, 1]
        stats = PassStats(self, min_r_over_r0=math.sqrt(x2) if x2 < self._cut2n else math.inf,
                          npairs=nl.npairs, nbuilds=nl.nbuilds)
        if stat[k, 2] >= 0:
            stats["closest"] = (int(stat[k, 2]), int(stat[k, 3]))
        else:
            # the tracking variant on the same arguments, without damping (vs, eta)
            stats._rerun = (multi, args, ch, buf, fin, stat, perm)
        self.last_stats = stats
        self._check_close(stat, types, step, x2, low, nclose)
        if variant.FIN:
            use_threads(lay["chunks"].shared_r.shape[0])
            C.reduce_shared(lay["f_m3"], ch, perm, f_nc, p_kick, h)
            use_threads(n)
        elif forces:
            C.reduce_rows(lay["f_m3"], ch, perm, f_nc, p_kick, h)
        res = {"forces": f_nc if forces else None, "energy": float(stat[:, 0].sum()) if variant.ENERGY else None}
        if conservative:
            c = np.empty((n, 3))
            C.reduce_rows(lay["c_m3"], ch, perm, c, _NO_V, 0.0)
            res["conservative"] = c
        if damping is not None:
            res["dissipation"] = float(stat[:, 5].sum())     # eV per ASE time, >= 0
        if variant.VIR:
            res["virial"] = vir.sum(axis=0)
        if per_particle:
            e = np.empty((n, 1))
            C.reduce_rows(lay["e_m1"], ch, perm, e, _NO_V, 0.0)
            res["energies"] = e[:, 0]
            w = np.empty((n, 6))
            C.reduce_rows(lay["w_m6"], ch, perm, w, _NO_V, 0.0)
            res["virials"] = w
        if damping is not None:
            # this pass's velocities stay in lay["vs"] until the next pass (pairs_touching)
            self._vs_pass, self._eta_tt = self.generation, eta
        return res

    def _check_close(self, stat, types, step, x2, low, nclose):
        """``x2``: the smallest r^2/r0^2 of the pass (NaN if any is); ``low``, ``nclose``: the
        smallest and the sum of the chunks' counts of pairs below the table
        (:func:`~clusterdyn.engine.chunks.chunk_stats`)."""
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

    # -- the integrator's fused half -----------------------------------------------------
    def advance(self, pos, momenta, forces, invm, h, dt, damped):
        """Velocity Verlet's first half kick and drift fused with the next pass's gathers.

        ``momenta += h forces; positions += dt momenta/m``
        (:func:`clusterdyn.engine.integrate.kick_drift_gather`), with the sorted positions
        (and velocities if ``damped``) and the rebuild test's displacements taken in the same
        pass; the next :meth:`forces` with ``advanced=True`` uses them.  Returns (max v^2, its
        particle), or None when the list is not ready for it (the caller then runs the
        separate passes).
        """
        nl = self.nl
        n = pos.shape[0]
        # (a list compacted by a removal is ready: the layout follows the new count below)
        if (nl.perm_n is None or nl.ref_nc is None or nl.ref_nc.shape != pos.shape or self._lay is None
                or not all(a.dtype == np.float64 and a.flags.c_contiguous for a in (pos, momenta, forces))):
            return None
        lay = self._layout(n, False, damped)
        nb = (n + STREAM_BLOCK - 1) // STREAM_BLOCK
        if self._bstat is None or self._bstat.shape[0] != nb:
            self._bstat = np.empty((nb, 9))
        use_threads(n)
        self.generation += 1  # the sorted positions change: last_stats' lazy "closest" expires
        v2max, k, m2, h2 = kick_drift_gather(momenta, forces, pos, invm, h, dt, nl.row_n, nl.offs_nc,
                                             nl.ref_nc, lay["xs"], lay["vs"] if damped else _NO_V, self._bstat)
        self._pending = (m2, h2, damped, nl.version)
        return v2max, k

    # -- renumbering -------------------------------------------------------------------
    def sort_order(self, n):
        """``(order, scratch)`` to put n particles into the list's row order (new particle k is
        old particle ``order[k]``; ``scratch``: the list's key scratch, free between builds), or
        None when the list has not been built over them yet or they are in its order already."""
        nl = self.nl
        if nl.perm_n is None or nl.ref_nc is None or nl.ref_nc.shape[0] != n or nl.in_order:
            return None
        return nl.perm_n, nl.scratch(n)

    def reindex(self, order, scratch):
        """The caller put its particles in the order :meth:`sort_order` gave: the list follows
        (no rebuild), the closest pair of :attr:`last_stats` is renamed."""
        self._forget()
        st = self.last_stats
        if st is not None and dict.__contains__(st, "closest") and st["closest"][0] >= 0:
            st["closest"] = tuple(int(np.flatnonzero(order == i)[0]) for i in st["closest"])
        self.nl.renumber(scratch)

    def compact(self, keep_n):
        """The particles where ``keep_n`` (bool, old rows) is False were taken out, the others
        keeping their order: the list is compacted with them
        (:meth:`clusterdyn.neighbors.NeighborList.remove`: no rebuild), or, when it can not be,
        rebuilt at the next pass.  Returns True when the list was kept."""
        kept = self.nl.remove(keep_n)
        self._forget()
        self.generation += 1
        self.last_stats = None
        return kept

    def _forget(self):
        self._pending = None

    # -- removal ---------------------------------------------------------------------
    def pairs_touching(self, pos, cell, pbc, types, bonds, mask, forces=None, damped=False):
        """What the listed pairs with a particle where ``mask`` is True contribute: (energy,
        dissipation), or None when ``damped`` is asked and the last damped pass is not the last
        pass; with ``forces``, their pair forces (and damping) are taken out of it (see
        :meth:`clusterdyn.calculators.ClusterDynamics.pairs_touching`)."""
        nl = self.nl
        lay = self._lay
        vs = _NO_V
        if damped:
            if self._vs_pass != self.generation or lay is None or lay["vs"] is None:
                return None
            vs = lay["vs"]
        if nl.update(pos, cell, pbc) and damped:
            return None
        xs = nl.sorted_positions(pos, out=nl.xs_nc)
        initial = bonds is not None
        bonds_nk, id_n = bonds if initial else (_NO_BONDS, _NO_IDS)
        self.passes["touching"] += 1
        args = (xs, types if self.multi else _NO_TYPES, nl.first_n, nl.jp_p, nl.img_shift, nl.image_sc, nl.perm_n,
                bonds_nk, id_n, initial)
        e, d = K.pairs_touching(args, (self.gtab, self.coef, self.meta, self._eta_tt if damped else _NO_ETA),
                                mask, vs, _NO_V if forces is None else forces)
        return float(e), float(d)
