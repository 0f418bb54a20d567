"""The MCA state: pair table keyed by stable ids, per-pair and per-automaton history.

Owned by :class:`~clusterdyn.mca.dynamics.MCADynamics` (the calculator reads
it, never writes it).  A pair is a row of the pair table; its partners are
stable particle ids (``atoms.arrays['id']``), so sorting or slicing the Atoms
does not lose the history.  Rows of the Atoms are found from ids at every
evaluation.

Per pair (``_p``; ``_p2`` per side, ``_pc`` vector):
``pid_p2`` ids (i < j), ``linked_p`` (1 linked, 0 unlinked), ``S_p`` contact
area, ``q0_p2`` rest distances centre -> contact, ``r0_p`` contact rest
distance, ``sig_p2`` / ``tau_p2c`` specific normal / tangential force (the
committed values), ``dlast_pc`` separation at the last commit, ``D_p``
damage, ``count_p`` compressed steps (healing), and the per-pair material
parameters (strengths, friction, welding threshold) fixed at set-up.

Per automaton (``_n``, by row at set-up, stored by id): ``thlast_nc``
rotation at the last commit, ``epsp_n`` plastic strain, ``omega_n`` volume (Voronoi cell
clipped at the sample surface), ``T_n`` temperature (K) where a material has Johnson-Cook's
thermal term (an empty array otherwise: checkpointed only when present).
"""

import numpy as np

from ..errors import InputError
from ..materials import get_material
from ..neighbors import minimum_image
from ..build.tessellation import tessellate
from .kernels import incidence
from ..materials.mca import check_mca_material
from .response.plastic import hardening_table, rate_constants, thermal_constants

#: per-pair arrays that are history (checkpointed); the rest are set-up constants (also checkpointed)
PAIR_ARRAYS = ("pid_p2", "linked_p", "S_p", "q0_p2", "r0_p", "sig_p2", "tau_p2c", "dlast_pc", "D_p",
               "count_p", "sigc_p", "beta_p", "mu_p", "sigw_p", "nweld_p", "sigd_p", "Dc_p",
               "epsd_p", "epsf_p")
ATOM_ARRAYS = ("id_n", "thlast_nc", "epsp_n", "omega_n", "P_n")
#: room temperature (K) of a material without the thermal term (a placeholder: never used)
ROOM_K = 294.0
#: the choices of :meth:`MCAState.set_inherit`
INHERIT = ("automata", "pairs")


def mca_materials_of(atoms, materials=None):
    """List of Material records indexed by ``atoms.arrays['material']``."""
    if materials is None:
        materials = atoms.info.get("mca_materials")
    if materials is None:
        raise InputError("materials", None, "a list of materials (or atoms built by mca_packing)")
    if not isinstance(materials, (list, tuple)):
        materials = [materials]
    mats = [check_mca_material(get_material(m)) for m in materials]
    mid = atoms.arrays.get("material")
    if mid is not None and len(mid) and (mid.min() < 0 or mid.max() >= len(mats)):
        raise InputError("material", int(mid.max()), f"material ids in [0, {len(mats) - 1}]")
    return mats


def detect_dim(atoms, dim=None):
    """3, or 2 for plane strain; a 2D call on a 3D sample raises InputError."""
    info_dim = atoms.info.get("mca_dim", 3)
    if dim is None:
        dim = info_dim
    if dim not in (2, 3):
        raise InputError("dim", dim, "2 (plane strain) or 3")
    if dim == 2:
        z = atoms.positions[:, 2]
        r = atoms.arrays["radius"]
        if len(z) and np.ptp(z) > 1e-6 * r.max():
            raise InputError("dim", 2, "a planar sample (all z equal) for plane strain; this sample "
                             f"spans {np.ptp(z):.4g} A in z (a 3D sample: use dim=3)")
    return dim


class MCAState:
    """Pair table and history of an MCA sample (see module docstring).

    Parameters
    ----------
    atoms : ase.Atoms with arrays ``radius``, ``id``, ``material``
    materials : list of Material (default ``atoms.info['mca_materials']``)
    interfaces : dict {(m1, m2): (sigma_t, sigma_c)}, optional
        Strength of pairs joining materials m1 and m2; default: the weaker
        of the two (smaller sigma_t and sigma_c).
    dim : 3 or 2
    """

    def __init__(self, atoms, materials=None, interfaces=None, dim=None):
        for name in ("radius", "id", "material"):
            if name not in atoms.arrays:
                raise InputError("atoms", f"no array '{name}'",
                                 "atoms with arrays radius, id, material (use mca_packing)")
        self.dim = detect_dim(atoms, dim)
        self.materials = mca_materials_of(atoms, materials)
        self.interfaces = dict(interfaces or {})
        self.version = 0
        self.step = 0
        self.time = 0.0
        ids = np.asarray(atoms.arrays["id"], np.int64)
        if len(np.unique(ids)) != len(ids):
            raise InputError("id", "duplicates", "unique particle ids")
        pos = atoms.get_positions()
        if atoms.info.get("mca_closure") == "body" and not np.any(atoms.pbc):
            from ..build.tessellation import tessellate_body     # carved shapes (build.mca)
            geom = tessellate_body(pos, atoms.arrays["radius"], self.dim)
        else:
            geom = tessellate(pos, atoms.arrays["radius"], atoms.cell.array, atoms.pbc, self.dim)
        self.box_c, self.periodic_c = _box(atoms)
        i, j = geom["i_p"], geom["j_p"]
        npair = len(i)
        a, b = ids[i], ids[j]
        swap = a > b
        pid = np.stack([np.where(swap, b, a), np.where(swap, a, b)], axis=1)
        q0 = geom["q_p2"].copy()
        q0[swap] = q0[swap][:, ::-1]
        order = np.lexsort((pid[:, 1], pid[:, 0]))
        self.pid_p2 = np.ascontiguousarray(pid[order])
        self.S_p = geom["S_p"][order].copy()
        self.q0_p2 = np.ascontiguousarray(q0[order])
        self.linked_p = np.ones(npair, np.int8)
        self.sig_p2 = np.zeros((npair, 2))
        self.tau_p2c = np.zeros((npair, 2, 3))
        self.D_p = np.zeros(npair)
        self.count_p = np.zeros(npair, np.int64)
        self.id_n = ids.copy()
        # automaton volume: its Voronoi cell clipped at the sample surface (for an interior
        # automaton equal to (1/3) sum_j q_ij S_ij); surface automata keep the faces they have
        # but their true volume, so their Love-Weber stress is not inflated by missing faces
        self.omega_n = geom["vcell_n"].copy()
        self.omega_faces_n = geom["omega_n"].copy()
        self.thlast_nc = np.array(atoms.arrays.get("theta", np.zeros((len(atoms), 3))), float)
        self.epsp_n = np.zeros(len(atoms))
        self.P_n = np.zeros(len(atoms))       # mean stress from the volume change (energy ledger)
        self.T_n = np.zeros(0)                # temperatures: set by _material_setup if a material heats
        rows = self.rows(ids)
        ii, jj = rows[self.pid_p2[:, 0]], rows[self.pid_p2[:, 1]]
        d = pos[jj] - pos[ii]
        minimum_image(d, self.box_c, self.periodic_c)
        self.dlast_pc = np.ascontiguousarray(d)
        self.r0_p = np.linalg.norm(d, axis=1)
        self._material_setup(atoms, ii, jj)
        self._initial_temperatures()
        cracks = atoms.info.get("mca_cracks", [])
        for c in cracks:
            self.unlink_across(pos, ii, jj, **c)
        self._inc_key = None
        self.lnJ_n = None

    lnJ_n = None      #: large strain: ln sqrt(det B) of every automaton at the last switch (None: none yet)
    #: what a linked pair that survives a switch starts from: "automata" (its automata's tensors,
    #: as every new pair) or "pairs" (its own stress state; :meth:`retessellate`)
    inherit = "automata"

    def set_inherit(self, inherit):
        """Choose what surviving linked pairs inherit at a switch ("automata" or "pairs")."""
        if inherit not in INHERIT:
            raise InputError("inherit", inherit, " or ".join(INHERIT))
        self.inherit = inherit
    Pref_n = None     #: large strain: P_n at the last switch

    # ------------------------------------------------------------------ set-up
    @classmethod
    def from_dict(cls, atoms, d, materials=None, interfaces=None, dim=None):
        """A state restored from :meth:`get_state` (no tessellation: the pair table is in ``d``)."""
        self = cls.__new__(cls)
        self.dim = detect_dim(atoms, dim)
        self.materials = mca_materials_of(atoms, materials)
        self.interfaces = dict(interfaces or {})
        self.version = 0
        self.box_c, self.periodic_c = _box(atoms)
        self._inc_key = None
        self.set_state(d)
        ids = np.asarray(atoms.arrays["id"], np.int64)
        mid = np.asarray(atoms.arrays["material"], np.int64)
        self.mat_id_n = mid[self.rows(ids)[self.id_n]]
        self._material_constants()
        self._initial_temperatures()
        self._flags()
        return self

    def _material_constants(self):
        mats = self.materials
        self.G_m = np.array([m.G for m in mats])
        self.K_m = np.array([m.K for m in mats])
        self.rho_m = np.array([m.rho0 for m in mats])
        self.responses = [m.response or "elastic" for m in mats]
        resp = self.responses
        self.plastic_m = np.array([r in ("elastic-plastic", "plastic-degrading") for r in resp], np.int8)
        tabs = [hardening_table(m) if p else (np.array([0.0, 1.0]), np.array([np.inf, np.inf]))
                for m, p in zip(mats, self.plastic_m)]
        rc = [rate_constants(m) if p else (0, 0.0, 1.0) for m, p in zip(mats, self.plastic_m)]
        self.implicit_m = np.array([r[0] for r in rc], np.int8)
        self.rateC_m = np.array([r[1] for r in rc])
        self.rate0_m = np.array([r[2] for r in rc])
        # Johnson-Cook's thermal term: (m, T_room, T_melt, beta/(rho c_p)), the last 0 where off
        th = [thermal_constants(m) if p else None for m, p in zip(mats, self.plastic_m)]
        self.thermal = any(t is not None for t in th)
        self.therm_m4 = np.array([t if t is not None else (1.0, ROOM_K, 2.0 * ROOM_K, 0.0) for t in th],
                                 dtype=float).reshape(len(mats), 4)
        k = max(len(t[0]) for t in tabs)
        self.tab_e = np.zeros((len(mats), k))
        self.tab_s = np.zeros((len(mats), k))
        for q, (e, s) in enumerate(tabs):
            # pad by repeating the last point far out
            self.tab_e[q] = np.concatenate([e, e[-1] + 1.0 + np.arange(k - len(e))])
            self.tab_s[q] = np.concatenate([s, np.full(k - len(e), s[-1])])

    def _initial_temperatures(self):
        """Every automaton at its material's T_room where a material heats (a state restored
        from a checkpoint keeps its own); an empty array where none does."""
        if not self.thermal:
            self.T_n = np.zeros(0)
        elif getattr(self, "T_n", None) is None or len(self.T_n) != len(self.id_n):
            self.T_n = self.therm_m4[self.mat_id_n, 1].copy()

    def _flags(self):
        """Kernel selection: a term the sample does not use is never run."""
        resp = self.responses
        self.flags = {
            "fracture": bool(np.any(self.sigc_p > 0)) and not any(r == "degrading" for r in resp),
            "degrading": any(r == "degrading" for r in resp),
            "plastic": bool(self.plastic_m.any()),
            "plastic_degrading": any(r == "plastic-degrading" for r in resp),
            "healing": bool(np.any(self.sigw_p > 0)),
        }
        self.flags["contacts"] = (self.flags["fracture"] or self.flags["degrading"]
                                  or self.flags["plastic_degrading"] or bool(np.any(self.linked_p == 0)))

    def _material_setup(self, atoms, ii, jj):
        mats = self.materials
        mid = np.asarray(atoms.arrays["material"], np.int64)
        self.mat_id_n = mid.copy()
        self._material_constants()
        resp = self.responses
        npair = len(ii)
        mi, mj = mid[ii], mid[jj]

        def pairval(f, default=0.0):
            vals = np.array([default if f(m) is None else f(m) for m in mats], float)
            return vals

        st = pairval(lambda m: m.sigma_t, np.inf)
        sc = pairval(lambda m: m.sigma_c, np.inf)
        brittle = np.array([r in ("elastic-brittle", "degrading") for r in resp])
        st[~brittle] = np.inf
        sc[~brittle] = np.inf
        sig_t = np.minimum(st[mi], st[mj])
        sig_c = np.minimum(sc[mi], sc[mj])
        for (m1, m2), (t, c) in self.interfaces.items():
            if not (t > 0 and c >= t):
                raise InputError("interfaces", {(m1, m2): (t, c)},
                                 "0 < sigma_t <= sigma_c for every interface")
            sel = ((mi == m1) & (mj == m2)) | ((mi == m2) & (mj == m1))
            sig_t[sel] = t
            sig_c[sel] = c
        finite = np.isfinite(sig_t) & np.isfinite(sig_c)
        self.sigc_p = np.where(finite, sig_c, 0.0)
        self.beta_p = np.where(finite, sig_c / np.where(finite, sig_t, 1.0), 1.0)
        mu = pairval(lambda m: m.extra.get("mu", 0.3))
        self.mu_p = 0.5 * (mu[mi] + mu[mj])
        sw = pairval(lambda m: m.extra.get("sigma_weld"), 0.0)
        self.sigw_p = np.maximum(sw[mi], sw[mj]) * ((sw[mi] > 0) & (sw[mj] > 0))
        nw = pairval(lambda m: m.extra.get("n_weld", 20))
        self.nweld_p = np.maximum(nw[mi], nw[mj]).astype(np.int64)
        sd = np.array([m.extra.get("sigma_d", 0.7 * m.sigma_c) if r == "degrading" else np.inf
                       for m, r in zip(mats, resp)])
        self.sigd_p = np.minimum(sd[mi], sd[mj])
        self.sigd_p[~np.isfinite(self.sigd_p)] = 0.0
        dc = pairval(lambda m: m.extra.get("D_c", 0.8))
        self.Dc_p = np.where((np.array(resp)[mi] == "degrading") | (np.array(resp)[mj] == "degrading"),
                             np.maximum(dc[mi], dc[mj]), 0.0)
        ed = pairval(lambda m: m.extra.get("eps_d", 0.05))
        ef = np.array([m.extra.get("eps_f", 0.2) if r == "plastic-degrading" else 0.0
                       for m, r in zip(mats, resp)])
        self.epsd_p = np.minimum(ed[mi], ed[mj])
        self.epsf_p = np.maximum(ef[mi], ef[mj]) * ((ef[mi] > 0) | (ef[mj] > 0))
        self._flags()

    def unlink_across(self, pos, ii, jj, point, normal, extent=None, **_):
        """Unlink the pairs whose segment crosses the plane (point, normal) within ``extent``.

        ``extent`` is None (whole plane) or a (3,) array of half-lengths of the
        crack region around ``point`` (Angstrom, per axis; 0 along the normal).
        Returns the number of pairs unlinked.
        """
        point = np.asarray(point, float)
        normal = np.asarray(normal, float)
        normal = normal / np.linalg.norm(normal)
        xi = pos[ii]
        xj = xi + self.dlast_pc
        si = (xi - point) @ normal
        sj = (xj - point) @ normal
        cross = (si * sj < 0)
        t = si / np.where(cross, si - sj, 1.0)
        xc = xi + t[:, None] * (xj - xi)
        if extent is not None:
            ext = np.asarray(extent, float)
            inside = np.all(np.abs(xc - point) <= ext + 1e-12 + np.abs(normal) * 1e30, axis=1)
            cross &= inside
        self.linked_p[cross] = 0
        self.flags["contacts"] = True
        self.version += 1
        return int(cross.sum())

    # ------------------------------------------------------------------ access
    @property
    def npairs(self):
        return len(self.S_p)

    def rows(self, ids):
        m = np.full(int(ids.max()) + 1 if len(ids) else 1, -1, np.int64)
        m[ids] = np.arange(len(ids))
        return m

    def pair_rows(self, atoms):
        """(i_p, j_p, first_n, side_p, side_s, perm_n): rows of the current Atoms (cached by ids)."""
        ids = np.asarray(atoms.arrays["id"], np.int64)
        key = (self.npairs, self.version_pairs)
        if self._inc_key != key or not np.array_equal(ids, self._inc_ids):
            self._inc_ids = ids.copy()
            if len(ids) != len(self.id_n) or not np.array_equal(np.sort(ids), np.sort(self.id_n)):
                raise InputError("atoms", "different particle ids",
                                 "the automata the MCA state was built for (same ids)")
            rows = self.rows(ids)
            i_p = rows[self.pid_p2[:, 0]]
            j_p = rows[self.pid_p2[:, 1]]
            first_n, side_p, side_s = incidence(len(ids), i_p, j_p)
            perm = self.rows(self.id_n)[ids]      # state row of each atoms row
            self._inc = (i_p, j_p, first_n, side_p, side_s, perm)
            self._inc_key = key
            self._consts = None
        return self._inc

    def automaton_constants(self, atoms):
        """(perm, identity, G, K, 2G, 1 - 2G/3K, K + 4G/3, Omega) per Atoms row, kept until the pair
        table, the rows or the volumes change (``identity``: the Atoms rows are the state's rows)."""
        inc = self.pair_rows(atoms)
        if self._consts is None:
            perm = inc[5]
            ident = bool(np.array_equal(perm, np.arange(len(perm))))
            mid = self.mat_id_n[perm]
            G_n = self.G_m[mid]
            K_n = self.K_m[mid]
            self._consts = (perm, ident, G_n, K_n, 2.0 * G_n, 1.0 - 2.0 * G_n / (3.0 * K_n),
                            K_n + 4.0 * G_n / 3.0, np.ascontiguousarray(self.omega_n[perm]))
        return self._consts

    _consts = None

    version_pairs = 0
    _inc_ids = None

    def linked_pairs(self):
        """(P, 2) int64 stable ids (i < j) of the pairs linked now (the bond graph).

        What :class:`clusterdyn.io.H5MDWriter` stores on every frame, so that
        fragments (connected components) can be computed from a file.
        """
        return self.pid_p2[self.linked_p == 1].copy()

    def per_atom(self, name, atoms):
        """A per-automaton state array reordered to the rows of ``atoms``."""
        return getattr(self, name)[self.pair_rows(atoms)[5]]

    # ------------------------------------------------------------------ contacts
    def add_pairs(self, pos, ids, radius, i_new, j_new, S_new):
        """Append unlinked contact pairs (rows i_new, j_new of the current Atoms)."""
        if len(i_new) == 0:
            return 0
        a, b = ids[i_new], ids[j_new]
        swap = a > b
        ri = radius[i_new]
        rj = radius[j_new]
        pid = np.stack([np.where(swap, b, a), np.where(swap, a, b)], axis=1)
        q0 = np.stack([np.where(swap, rj, ri), np.where(swap, ri, rj)], axis=1)
        rows_i = np.where(swap, j_new, i_new)
        rows_j = np.where(swap, i_new, j_new)
        d = pos[rows_j] - pos[rows_i]
        minimum_image(d, self.box_c, self.periodic_c)
        order = np.lexsort((pid[:, 1], pid[:, 0]))
        m = len(order)
        mats = self.mat_id_n[self.rows(self.id_n)[pid[order, 0]]], self.mat_id_n[self.rows(self.id_n)[pid[order, 1]]]
        mu = np.array([mm.extra.get("mu", 0.3) for mm in self.materials])
        sw = np.array([mm.extra.get("sigma_weld") or 0.0 for mm in self.materials])
        nw = np.array([mm.extra.get("n_weld", 20) for mm in self.materials])
        new = {
            "pid_p2": pid[order], "linked_p": np.zeros(m, np.int8), "S_p": np.asarray(S_new)[order],
            "q0_p2": q0[order], "r0_p": q0[order].sum(axis=1), "sig_p2": np.zeros((m, 2)),
            "tau_p2c": np.zeros((m, 2, 3)), "dlast_pc": d[order], "D_p": np.zeros(m),
            "count_p": np.zeros(m, np.int64), "sigc_p": np.zeros(m), "beta_p": np.ones(m),
            "mu_p": 0.5 * (mu[mats[0]] + mu[mats[1]]),
            "sigw_p": np.where((sw[mats[0]] > 0) & (sw[mats[1]] > 0), np.maximum(sw[mats[0]], sw[mats[1]]), 0.0),
            "nweld_p": np.maximum(nw[mats[0]], nw[mats[1]]).astype(np.int64),
            "sigd_p": np.zeros(m), "Dc_p": np.zeros(m), "epsd_p": np.zeros(m), "epsf_p": np.zeros(m),
        }
        # welded contacts take the weaker strength of the two materials
        st = np.array([mm.sigma_t if mm.sigma_t else np.inf for mm in self.materials])
        sc = np.array([mm.sigma_c if mm.sigma_c else np.inf for mm in self.materials])
        t = np.minimum(st[mats[0]], st[mats[1]])
        c = np.minimum(sc[mats[0]], sc[mats[1]])
        fin = np.isfinite(t) & np.isfinite(c)
        new["sigc_p"] = np.where(fin, c, 0.0)
        new["beta_p"] = np.where(fin, c / np.where(fin, t, 1.0), 1.0)
        for k in PAIR_ARRAYS:
            setattr(self, k, np.ascontiguousarray(np.concatenate([getattr(self, k), new[k]])))
        self.version_pairs += 1
        self.version += 1
        return m

    def remove_pairs(self, keep):
        """Keep only the pairs where ``keep`` (P,) bool is True (e.g. drop pairs across bodies)."""
        keep = np.asarray(keep, bool)
        for k in PAIR_ARRAYS:
            setattr(self, k, np.ascontiguousarray(getattr(self, k)[keep]))
        self._flags()
        self.version_pairs += 1
        self.version += 1
        return int((~keep).sum())

    # ------------------------------------------------------------------ large strain
    def retessellate(self, atoms, s_ncc, h_link=0.5):
        """Switch partners and follow the deformation (docs/theory.md 2.7; docs/mca.md).

        The Voronoi tessellation of the current centres (:func:`tessellate_body`,
        the body closed by ghosts) gives the new pairs, contact areas S,
        distances q0 = r/2, and the automaton volumes (their current cells).

        * A pair of the new tessellation is **linked** if it was linked before,
          or if it is new and its overlap ``h = r - (r_i + r_j)`` is below
          ``h_link (r_i + r_j)``; a pair unlinked before (fracture) stays
          unlinked.  New faces beyond the overlap rule (long faces at the
          free surface) are not pairs.
        * A linked pair that no longer shares a face leaves the table (it
          *unlinks by switching*: another automaton has come between).
          Unlinked pairs of the old table still touching (``r < r0``) are kept
          as contacts with their state.
        * Every linked pair's state starts from its automata's stress tensors:
          ``sigma_ij = n.sigma_i.n``, ``tau_ij = sigma_i.n - sigma_ij n`` (and
          the same with ``sigma_j`` on j's side), so a homogeneous stress field
          is carried exactly (``sum_j q S n n = Omega I`` on the new cells);
          damage and healing counters persist on surviving pairs, new pairs
          start undamaged; plastic strain is per automaton and carries over.
          With ``inherit = "pairs"`` (:meth:`set_inherit`) a linked pair that
          survives keeps its own stress state and only new pairs start from
          the tensors: a surface automaton's tensor lacks the load on its outer
          face (a platen's or wall's), so the tensors halve its pairs' normal
          stress along the load (measured: a 30-50% dip of the platens' force
          at each switch of the compression check).
        * Rest distances are reset to the current ones (``r0 = r``); the
          objective increments restart from the current separation and
          rotation.

        Mass and momentum are untouched (positions and velocities are not
        changed).  ``s_ncc`` are the automata's tensors (rows of ``atoms``).
        Returns a dict of counts (pairs before, after, new, switched away).
        """
        from ..build.tessellation import tessellate_body
        if np.any(self.periodic_c):
            raise InputError("remesh", "a periodic sample", "a body without periodic axes "
                             "(the large-strain re-tessellation closes the body by ghosts)")
        ids = np.asarray(atoms.arrays["id"], np.int64)
        rad = np.asarray(atoms.arrays["radius"], float)
        pos = atoms.get_positions()
        i_old, j_old = self.pair_rows(atoms)[:2]
        geom = tessellate_body(pos, rad, self.dim)
        ii, jj = geom["i_p"], geom["j_p"]
        a, b = ids[ii], ids[jj]
        swap = a > b
        pid = np.stack([np.where(swap, b, a), np.where(swap, a, b)], axis=1)
        M = int(ids.max()) + 1
        key_old = self.pid_p2[:, 0] * M + self.pid_p2[:, 1]
        key_new = pid[:, 0] * M + pid[:, 1]
        pos_old = {int(k): q for q, k in enumerate(key_old)}
        old_row = np.array([pos_old.get(int(k), -1) for k in key_new], np.int64)
        have = old_row >= 0
        r = geom["r_p"]
        rsum = rad[ii] + rad[jj]
        was_linked = np.zeros(len(ii), bool)
        was_linked[have] = self.linked_p[old_row[have]] == 1
        link_new = (~have) & (r - rsum < h_link * rsum)
        keep_v = was_linked | link_new | (have & ~was_linked)
        # old unlinked contacts that are not faces any more but still touch
        old_unl = np.nonzero(self.linked_p == 0)[0]
        in_new = np.isin(key_old[old_unl], key_new[keep_v])
        d_old = pos[j_old[old_unl]] - pos[i_old[old_unl]]
        touch = np.linalg.norm(d_old, axis=1) < self.r0_p[old_unl]
        extra = old_unl[~in_new & touch]
        n_before = self.npairs
        switched = int(np.sum((self.linked_p == 1) & ~np.isin(key_old, key_new[keep_v])))
        # the new table: Voronoi pairs kept, then the extra contacts (rows of the old table)
        sel = np.nonzero(keep_v)[0]
        rows_i = np.concatenate([np.where(swap[sel], jj[sel], ii[sel]), i_old[extra]])
        rows_j = np.concatenate([np.where(swap[sel], ii[sel], jj[sel]), j_old[extra]])
        src = np.concatenate([old_row[sel], extra])            # old row or -1
        old = {k: getattr(self, k) for k in PAIR_ARRAYS}
        # per-pair material parameters for every pair, then the survivors' own values
        self._material_setup(atoms, rows_i, rows_j)
        self.mat_id_n = np.asarray(atoms.arrays["material"], np.int64)[self.rows(ids)[self.id_n]]
        per_pair = ("sigc_p", "beta_p", "mu_p", "sigw_p", "nweld_p", "sigd_p", "Dc_p", "epsd_p", "epsf_p")
        fresh = {k: getattr(self, k) for k in per_pair}
        P = len(src)
        surv = src >= 0
        d = pos[rows_j] - pos[rows_i]
        rr = np.linalg.norm(d, axis=1)
        nrm = d / rr[:, None]
        self.pid_p2 = np.ascontiguousarray(np.stack([ids[rows_i], ids[rows_j]], axis=1))
        nv = len(sel)
        self.S_p = np.concatenate([geom["S_p"][sel], old["S_p"][extra]])
        self.q0_p2 = np.ascontiguousarray(np.concatenate([np.stack([0.5 * rr[:nv], 0.5 * rr[:nv]], axis=1),
                                                          old["q0_p2"][extra]]))
        linked = np.zeros(P, np.int8)
        linked[:nv] = (was_linked | link_new)[sel]
        self.linked_p = linked
        self.r0_p = np.where(linked == 1, rr, np.concatenate([rr[:nv], old["r0_p"][extra]]))
        self.dlast_pc = np.ascontiguousarray(d)
        self.sig_p2, self.tau_p2c = _inherited_stresses(s_ncc, rows_i, rows_j, nrm, linked, surv, src, old,
                                                        self.inherit == "pairs")
        self.D_p = np.where(surv, old["D_p"][np.maximum(src, 0)], 0.0)
        self.count_p = np.where(surv, old["count_p"][np.maximum(src, 0)], 0).astype(np.int64)
        for k in per_pair:
            v = fresh[k].copy()
            v[surv] = old[k][src[surv]]
            setattr(self, k, np.ascontiguousarray(v))
        # the table sorted by ids, as at set-up
        order = np.lexsort((self.pid_p2[:, 1], self.pid_p2[:, 0]))
        for k in PAIR_ARRAYS:
            setattr(self, k, np.ascontiguousarray(getattr(self, k)[order]))
        perm = self.rows(self.id_n)[ids]       # state row of each atoms row
        self.omega_n[perm] = geom["vcell_n"]
        # interior automata (no face with a ghost): their mean cell volume is the body's density
        inner = np.abs(geom["vcell_n"] - geom["omega_n"]) <= 1e-9 * geom["vcell_n"]
        self.interior_volume = (float(geom["vcell_n"][inner].mean()) if inner.any() else float("nan"),
                                int(inner.sum()))
        self.thlast_nc[perm] = atoms.arrays.get("theta", np.zeros((len(atoms), 3)))
        self.P_n[perm] = np.trace(s_ncc, axis1=1, axis2=2) / 3.0
        self._flags()
        self.version_pairs += 1
        self.version += 1
        self._inc_key = None
        return {"pairs_before": n_before, "pairs_after": self.npairs,
                "new_links": int(link_new[sel].sum()), "switched": switched}

    # ------------------------------------------------------------------ checkpoint
    def get_state(self):
        d = {k: getattr(self, k).copy() for k in PAIR_ARRAYS + ATOM_ARRAYS}
        d["step"] = int(self.step)
        d["time"] = float(self.time)
        d["version"] = int(self.version)
        if self.lnJ_n is not None:
            d["lnJ_n"] = self.lnJ_n.copy()
            d["Pref_n"] = self.Pref_n.copy()
        if self.T_n.size:
            d["T_n"] = self.T_n.copy()
        if self.inherit != "automata":
            d["inherit"] = self.inherit
        return d

    def set_state(self, d):
        for k in PAIR_ARRAYS + ATOM_ARRAYS:
            if k == "P_n" and k not in d:          # checkpoints written before the ledger
                self.P_n = np.zeros(len(d["id_n"]))
                continue
            setattr(self, k, np.ascontiguousarray(np.array(d[k])))
        self.step = int(d["step"])
        self.time = float(d["time"])
        self.version = int(d.get("version", self.version)) + 1
        self.lnJ_n = None if d.get("lnJ_n") is None else np.array(d["lnJ_n"], dtype=float)
        self.Pref_n = None if d.get("Pref_n") is None else np.array(d["Pref_n"], dtype=float)
        self.T_n = None if d.get("T_n") is None else np.ascontiguousarray(np.array(d["T_n"], dtype=float))
        self.inherit = str(d.get("inherit", "automata"))
        if hasattr(self, "therm_m4"):             # an existing state (else from_dict sets them)
            self._initial_temperatures()
        self.version_pairs += 1
        self._inc_key = None


def _box(atoms):
    from ..neighbors import check_cell
    box, per = check_cell(atoms.cell.array, atoms.pbc)
    return np.ascontiguousarray(box, dtype=np.float64), np.ascontiguousarray(per, dtype=np.bool_)


def _inherited_stresses(s_ncc, rows_i, rows_j, nrm, linked, surv, src, old, keep_linked=False):
    """The re-tessellated pairs' stress state (:meth:`MCAState.retessellate`): a linked pair's from
    its automata's tensors on each side (``sigma = n.s.n``, ``tau = s.n - sigma n``); a contact that
    survived keeps its own, a new contact starts at zero.  With ``keep_linked`` a linked pair that
    survived keeps its own too (only new pairs start from the tensors)."""
    P = len(src)
    sig = np.zeros((P, 2))
    tau = np.zeros((P, 2, 3))
    for side, rows in ((0, rows_i), (1, rows_j)):
        t = np.einsum("pab,pb->pa", s_ncc[rows], nrm)
        sn = np.einsum("pa,pa->p", t, nrm)
        sig[:, side] = sn
        tau[:, side] = t - sn[:, None] * nrm
    unl = linked == 0                      # contacts: the contact law sets them afresh
    sig[unl & surv] = old["sig_p2"][src[unl & surv]]
    tau[unl & surv] = old["tau_p2c"][src[unl & surv]]
    sig[unl & ~surv] = 0.0
    tau[unl & ~surv] = 0.0
    if keep_linked:
        k = (linked == 1) & surv
        sig[k] = old["sig_p2"][src[k]]
        tau[k] = old["tau_p2c"][src[k]]
    return np.ascontiguousarray(sig), np.ascontiguousarray(tau)
