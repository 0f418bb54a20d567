"""A grain-boundary pair law for Cluster Dynamics packings (beyond the CD paper; docs/theory.md 1.11).

The CD paper's packing is the default and is untouched by this module.  With
the law, the pairs listed as *boundary bonds* (the pairs across grain
boundaries within the cutoff at set-up; optionally every set-up pair) get

- the CD repulsion of the cold curve for ``r < r0_ab`` (the calculator's
  ``attraction="initial"`` rule: these pairs are not in ``bonds0``, so the
  CD pair loop gives them the repulsive branch only), plus
- a **cohesive part** (this module), acting for ``r > r0_ab``: a bilinear
  traction-separation law of the normal opening ``delta = r - r_b`` (``r_b`` =
  r0_ab, or the set-up distance of a pair set up beyond it: no bond starts loaded) with the
  CD bond's own stiffness ``k_n = -f'(r0_ab)`` up to the peak force
  ``F_t = sigma_t A_b``, then linear softening to zero at ``delta_f = 2 W_b /
  F_t`` (``W_b = G_c r0^2/4``); a damaged bond unloads toward the origin; and
- a **shear part**: a tangential spring (stiffness ``k_t = kt_ratio k_n``) on
  the relative tangential displacement of the pair since set-up (rotated with
  the pair, history), capped by ``(1 - d) F_s + mu N_c`` (cohesion
  ``F_s = tau_c A_b`` that the damage removes, and Coulomb friction on the
  pair's compressive CD force ``N_c``); beyond the cap the pair slips.

Damage: ``kappa`` = the largest value so far of ``max(delta, 0) + lambda``
(``lambda`` the accumulated slip length); ``1 - d = F_env(kappa)/(k_n kappa)``
on the softening branch.  A pair with ``kappa >= delta_f`` has failed: no
cohesion ever again (friction stays, while the pair is in contact).  The
history (kappa, lambda, the tangential displacement) is the dynamics' state:
:class:`BoundaryTerm` is attached to a :class:`~clusterdyn.md.DampedVerlet`
as a piece (:meth:`~clusterdyn.md.DampedVerlet.attach_piece`, :mod:`clusterdyn.md.pieces`), which
calls it once per force pass and stores its state in checkpoints.

Areas: ``A_b = r0^2/(2 sqrt 2)`` turns a bond force into a stress (a dense fcc
lattice whose bonds all carry F under hydrostatic tension carries
``sigma = 2 sqrt(2) F / r0^2``, the virial of docs/theory.md 1.4); a (100)
plane is crossed by 4 bonds per r0^2, so ``W_b = G_c r0^2 / 4`` makes a
(100) crack cost G_c per unit area.  sigma_t, tau_c and G_c are therefore
bond-level parameters; what a packing carries is measured
(``clusterdyn study flow-stress``) and calibrated (``clusterdyn study calibrate``).

The bonds are named by the particles' stable ids (``atoms.arrays['id']``), so
sorts and removals of :class:`~clusterdyn.md.DampedVerlet` keep them (a bond
that loses a particle is dropped).  Conservative at fixed history: the forces
are minus the gradient of :attr:`BoundaryTerm.stored_energy` (tests/md/test_boundary.py,
finite differences); momentum is exact (pairwise equal and opposite forces).
"""

import math

import numpy as np
from numba import njit

from .. import units
from ..errors import InputError
from .pieces import Piece

SQRT2 = math.sqrt(2.0)
#: grid of the compressive CD force f(r) (for the friction), r / r0_ab from TABLE_LO to 1
TABLE_LO = 0.2
TABLE_N = 2001
#: J/m^2 in ASE units (eV / Angstrom^2)
J_M2 = units.J / units.m ** 2
#: modes of the kernel
TRIAL, UPDATE, FROZEN = 0, 1, 2


class BoundaryLaw:
    """Parameters of the boundary pair law (stresses in ASE units; see the module docstring).

    Parameters
    ----------
    sigma_t : float
        Tensile strength of a bond, as a stress (``F_t = sigma_t r0^2/(2 sqrt 2)``), > 0.
    G_c : float
        Fracture energy per area (``W_b = G_c r0^2/4`` per bond), > 0, eV/Angstrom^2
        (``units.J / units.m**2`` is 1 J/m^2).  Or, instead:
    ductility : float
        ``delta_f / delta_0`` (> 1): the softening ends at this multiple of the peak's opening, at
        every r0 (a packing calibrated so responds the same at any resolution; its G_c then
        scales with r0).
    tau_c : float, default 0
        Cohesive shear strength, as a stress (``F_s = tau_c r0^2/(2 sqrt 2)``), >= 0.
    mu : float, default 0
        Coulomb friction coefficient, >= 0.
    kt_ratio : float, default 1
        Tangential stiffness as a fraction of the normal one, in (0, 1] (used
        only when tau_c or mu is > 0).
    select : "boundary" or "all"
        Which set-up pairs get the law: pairs across grain boundaries, or every pair
        within the cutoff (the lattice's own attraction then comes from this law only).
    """

    FIELDS = ("sigma_t", "G_c", "tau_c", "mu", "kt_ratio", "select", "ductility")

    def __init__(self, sigma_t, G_c=None, tau_c=0.0, mu=0.0, kt_ratio=1.0, select="boundary", ductility=None):
        self.sigma_t = _positive("sigma_t", sigma_t)
        if (G_c is None) == (ductility is None):
            raise InputError("G_c", G_c, "a fracture energy G_c or a ductility delta_f/delta_0 (one of the two)")
        self.G_c = None if G_c is None else _positive("G_c", G_c)
        self.ductility = None if ductility is None else _positive("ductility", ductility)
        if self.ductility is not None and self.ductility <= 1:
            raise InputError("ductility", ductility, "delta_f/delta_0 > 1")
        self.tau_c = _positive("tau_c", tau_c, zero=True)
        self.mu = _positive("mu", mu, zero=True)
        self.kt_ratio = _positive("kt_ratio", kt_ratio)
        if self.kt_ratio > 1:
            raise InputError("kt_ratio", kt_ratio, "a fraction in (0, 1] of the normal stiffness")
        if select not in ("boundary", "all"):
            raise InputError("select", select, "'boundary' (pairs across grain boundaries) or 'all'")
        self.select = select

    @property
    def shear(self):
        return self.tau_c > 0 or self.mu > 0

    def todict(self, display=False):
        """The parameters; ``display=True``: stresses in GPa, G_c in J/m^2."""
        d = {k: getattr(self, k) for k in self.FIELDS}
        if display:
            d.update(sigma_t=self.sigma_t / units.GPa, tau_c=self.tau_c / units.GPa,
                     G_c=None if self.G_c is None else self.G_c / J_M2)
        return {k: x for k, x in d.items() if x is not None}

    @classmethod
    def fromdict(cls, d, display=False):
        d = dict(d)
        if display:
            d.update(sigma_t=float(d["sigma_t"]) * units.GPa, tau_c=float(d.get("tau_c", 0.0)) * units.GPa)
            if d.get("G_c") is not None:
                d["G_c"] = float(d["G_c"]) * J_M2
        return cls(**{k: d[k] for k in cls.FIELDS if k in d})

    def bond_constants(self, r0, kn):
        """(F_t, F_s, delta_0, delta_f) of bonds of rest length r0 and stiffness kn (arrays)."""
        r0 = np.asarray(r0, float)
        area = r0 ** 2 / (2.0 * SQRT2)
        ft = self.sigma_t * area
        fs = self.tau_c * area
        d0 = ft / kn
        if self.ductility is not None:
            df = self.ductility * d0
        else:
            df = 2.0 * self.G_c * r0 ** 2 / 4.0 / ft
        return ft, fs, d0, df

    def __repr__(self):
        d = self.todict(display=True)
        soft = f"G_c={d['G_c']:g} J/m2" if self.G_c is not None else f"ductility={self.ductility:g}"
        return (f"BoundaryLaw(sigma_t={d['sigma_t']:g} GPa, {soft}, tau_c={d['tau_c']:g} GPa, "
                f"mu={self.mu:g}, kt_ratio={self.kt_ratio:g}, select={self.select!r})")


def _positive(name, v, zero=False):
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(name, v, "a number") from None
    if not math.isfinite(x) or x < 0 or (x == 0 and not zero):
        raise InputError(name, v, "a finite number >= 0" if zero else "a finite number > 0")
    return x


# --------------------------------------------------------------------------- the kernel
@njit(cache=True)
def _row_map(ids, out):
    out[:] = -1
    for k in range(ids.shape[0]):
        out[ids[k]] = k


@njit(cache=True)
def boundary_kernel(x, p, invm, cell, icell, pbc, row, bi, bj, btype, r0, rest, kn, kt, ft, fs, mu, d0, df,
                    ftab, tinv, kappa, lam, s, mode, dt, shear, fb, rb, db, vir):
    """The force on particle i of every bond into ``fb`` ((M, 3); j gets minus it) and the bond's
    rows into ``rb`` ((M, 2), -1 for a bond that lost a particle: :func:`scatter` adds them),
    its vector x_j - x_i (minimum image) into ``db`` ((M, 3): :func:`bond_virials`);
    returns (stored energy, energy dissipated by this pass (UPDATE: the stored energy that the
    damage growth and the slip remove at the current positions), failed bonds).

    ``mode``: TRIAL (the damage of the current opening stored, not booked as dissipated: a
    state's first pass; the tangential history kept), UPDATE (the step's
    pass: damage, slip and tangential displacement stored; the tangential displacement grows by
    the relative tangential velocity ``p/m`` times ``dt``), FROZEN (the stored history only: the
    forces are then minus the gradient of the energy).  ``vir`` (6,) += the bonds' virial (eV,
    Voigt xx yy zz yz xz xy, tension positive)."""
    energy = 0.0
    slipd = 0.0
    nfail = 0
    for b in range(bi.shape[0]):
        i = row[bi[b]]
        j = row[bj[b]]
        if i < 0 or j < 0:
            rb[b, 0] = -1
            rb[b, 1] = -1
            continue
        rb[b, 0] = i
        rb[b, 1] = j
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        dz = x[j, 2] - x[i, 2]
        # minimum image on the periodic axes
        f0 = dx * icell[0, 0] + dy * icell[1, 0] + dz * icell[2, 0]
        f1 = dx * icell[0, 1] + dy * icell[1, 1] + dz * icell[2, 1]
        f2 = dx * icell[0, 2] + dy * icell[1, 2] + dz * icell[2, 2]
        if pbc[0]:
            f0 -= np.floor(f0 + 0.5)
        if pbc[1]:
            f1 -= np.floor(f1 + 0.5)
        if pbc[2]:
            f2 -= np.floor(f2 + 0.5)
        if pbc[0] or pbc[1] or pbc[2]:
            dx = f0 * cell[0, 0] + f1 * cell[1, 0] + f2 * cell[2, 0]
            dy = f0 * cell[0, 1] + f1 * cell[1, 1] + f2 * cell[2, 1]
            dz = f0 * cell[0, 2] + f1 * cell[1, 2] + f2 * cell[2, 2]
        db[b, 0] = dx
        db[b, 1] = dy
        db[b, 2] = dz
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        nx = dx / r
        ny = dy / r
        nz = dz / r
        delta = r - rest[b]
        k = kn[b]
        # damage from kappa = max over time of (opening + slip)
        kap = kappa[b]
        kap_old = kap
        if mode != FROZEN:
            trial = max(delta, 0.0) + lam[b]
            if trial > kap:
                kap = trial
        if mode != FROZEN:
            kappa[b] = kap          # (damage is a function of the largest opening: storing it is idempotent)
        if kap >= df[b]:
            keep = 0.0
            nfail += 1
        elif kap > d0[b]:
            keep = ft[b] * (df[b] - kap) / (df[b] - d0[b]) / (k * kap)
        else:
            keep = 1.0
        if mode == UPDATE and kap > kap_old and delta > 0.0:
            # damage grew at this opening: the stored energy it removes is dissipated
            if kap_old >= df[b]:
                keep_old = 0.0
            elif kap_old > d0[b]:
                keep_old = ft[b] * (df[b] - kap_old) / (df[b] - d0[b]) / (k * kap_old)
            else:
                keep_old = 1.0
            slipd += 0.5 * k * (keep_old - keep) * delta * delta
        fn = 0.0                      # attractive normal force (on i along +n)
        if delta > 0.0 and keep > 0.0:
            fn = k * keep * delta
            energy += 0.5 * k * keep * delta * delta
        Fx = fn * nx
        Fy = fn * ny
        Fz = fn * nz
        if shear:
            sx = s[b, 0]
            sy = s[b, 1]
            sz = s[b, 2]
            if mode == UPDATE:
                # rotate the tangential displacement into the current tangent plane (length kept)
                s2 = sx * sx + sy * sy + sz * sz
                sn = sx * nx + sy * ny + sz * nz
                sx -= sn * nx
                sy -= sn * ny
                sz -= sn * nz
                t2 = sx * sx + sy * sy + sz * sz
                if t2 > 0.0:
                    sc = math.sqrt(s2 / t2)
                    sx *= sc
                    sy *= sc
                    sz *= sc
                vx = p[j, 0] * invm[j] - p[i, 0] * invm[i]
                vy = p[j, 1] * invm[j] - p[i, 1] * invm[i]
                vz = p[j, 2] * invm[j] - p[i, 2] * invm[i]
                vn = vx * nx + vy * ny + vz * nz
                sx += (vx - vn * nx) * dt
                sy += (vy - vn * ny) * dt
                sz += (vz - vn * nz) * dt
            # the cap: cohesion (removed by the damage) + Coulomb friction on the CD contact force
            nc = 0.0
            if r < r0[b]:
                ti = btype[b]
                xg = (r / r0[b] - TABLE_LO) * tinv
                kg = int(xg)
                if kg < 0:
                    kg = 0
                    xg = 0.0
                w = xg - kg
                nc = ftab[ti, kg] + w * (ftab[ti, kg + 1] - ftab[ti, kg])
            cap = keep * fs[b] + mu * nc
            kts = kt[b]
            smag = math.sqrt(sx * sx + sy * sy + sz * sz)
            if kts * smag > cap:
                scale = cap / (kts * smag) if smag > 0.0 else 0.0
                if mode == UPDATE:
                    lam[b] += smag * (1.0 - scale)
                    slipd += 0.5 * kts * smag * smag * (1.0 - scale * scale)
                sx *= scale
                sy *= scale
                sz *= scale
            if mode == UPDATE:
                s[b, 0] = sx
                s[b, 1] = sy
                s[b, 2] = sz
            Fx += kts * sx
            Fy += kts * sy
            Fz += kts * sz
            energy += 0.5 * kts * (sx * sx + sy * sy + sz * sz)
        fb[b, 0] = Fx
        fb[b, 1] = Fy
        fb[b, 2] = Fz
        vir[0] += dx * Fx
        vir[1] += dy * Fy
        vir[2] += dz * Fz
        vir[3] += dy * Fz
        vir[4] += dx * Fz
        vir[5] += dx * Fy
    return energy, slipd, nfail


@njit(cache=True)
def scatter(fb, rb, f_out, p_kick, h):
    """``f_out[i] += fb[b]``, ``f_out[j] -= fb[b]`` per bond (rows ``rb``); with a non-empty
    ``p_kick`` also ``p_kick += h`` times the same."""
    kick = p_kick.shape[0] > 0
    for b in range(fb.shape[0]):
        i = rb[b, 0]
        j = rb[b, 1]
        if i < 0:
            continue
        for c in range(3):
            f_out[i, c] += fb[b, c]
            f_out[j, c] -= fb[b, c]
            if kick:
                p_kick[i, c] += h * fb[b, c]
                p_kick[j, c] -= h * fb[b, c]


@njit(cache=True)
def bond_virials(fb, db, rb, out):
    """``out`` ((N, 6) Voigt, eV, tension positive) += half of each bond's virial ``d (x) F`` on each
    of its two particles (rows ``rb``): the bonds' share of the per-particle virial W^a of
    docs/theory.md 1.4 (its sum over the particles is the term's ``virial``)."""
    for b in range(fb.shape[0]):
        i = rb[b, 0]
        j = rb[b, 1]
        if i < 0:
            continue
        dx, dy, dz = db[b, 0], db[b, 1], db[b, 2]
        fx, fy, fz = fb[b, 0], fb[b, 1], fb[b, 2]
        w0, w1, w2 = 0.5 * dx * fx, 0.5 * dy * fy, 0.5 * dz * fz
        w3, w4, w5 = 0.5 * dy * fz, 0.5 * dx * fz, 0.5 * dx * fy
        for a in (i, j):
            out[a, 0] += w0
            out[a, 1] += w1
            out[a, 2] += w2
            out[a, 3] += w3
            out[a, 4] += w4
            out[a, 5] += w5


# --------------------------------------------------------------------------- bonds and the term
def set_up_pairs(atoms, calc):
    """(i, j, r) of the pairs within the calculator's cutoff ``rc r0_ab`` now (i < j)."""
    from ..neighbors import NeighborList
    calc.setup(atoms)
    nl = NeighborList(calc.nl.cutoff, 0.0, half=False)
    nl.build(atoms.positions, atoms.cell.array, atoms.pbc)
    i, j, d, r = nl.pairs(atoms.positions)
    types = calc._check_types(atoms)
    keep = (r < np.sqrt(calc.meta[types[i], types[j], 2])) & (i < j)
    return i[keep], j[keep], r[keep]


NO_BONDS = np.zeros((0, 1), np.int64)


def apply_boundary_law(atoms, law, rc=None, within="grain"):
    """Give ``atoms`` the boundary law: returns ``(calc, term)``.

    Marks ``atoms.arrays['bonds0']`` (the CD attraction) on the set-up pairs inside one
    grain (``within`` labels; ``law.select == "all"``: on no pair), makes a
    :class:`~clusterdyn.calculators.ClusterDynamics` with ``attraction="initial"`` (so
    every other pair only repels) and the :class:`BoundaryTerm` over the other set-up
    pairs.  Attach the term to the dynamics: ``dyn.attach_piece(term)``.  ``atoms.calc`` is set.
    """
    from ..calculators import ClusterDynamics
    from ..potentials import DEFAULT_RC
    if not isinstance(law, BoundaryLaw):
        raise InputError("law", law, "a BoundaryLaw")
    rc = DEFAULT_RC if rc is None else rc
    calc = ClusterDynamics(rc=rc, attraction="initial")
    n = len(atoms)
    if "id" not in atoms.arrays:
        atoms.new_array("id", np.arange(n, dtype=np.int64))
    i, j, r = set_up_pairs(atoms, calc)
    if law.select == "all":
        inside = np.zeros(len(i), bool)
    else:
        if within not in atoms.arrays:
            raise InputError("within", within, f"a per-particle label array of the Atoms ({sorted(atoms.arrays)}); "
                             "a single crystal has no boundaries: use select='all'")
        lab = np.asarray(atoms.arrays[within])
        inside = (lab[i] == lab[j]) & (lab[i] >= 0)
    ids = atoms.arrays["id"]
    # bonds0: partners (ids) of the pairs that keep the CD attraction, both directions
    a = np.concatenate([i[inside], j[inside]])
    b = np.concatenate([j[inside], i[inside]])
    counts = np.bincount(a, minlength=n)
    width = max(1, int(counts.max()) if n and len(a) else 1)
    bonds = np.full((n, width), -1, dtype=np.int64)
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    start = np.concatenate([[0], np.cumsum(counts)])
    bonds[a, np.arange(len(a)) - start[a]] = ids[b]
    if "bonds0" in atoms.arrays:
        del atoms.arrays["bonds0"]
    atoms.new_array("bonds0", bonds)
    atoms.calc = calc
    calc.setup(atoms)
    term = BoundaryTerm.from_pairs(calc, atoms, law, i[~inside], j[~inside], r[~inside])
    return calc, term


class BoundaryTerm(Piece):
    """The boundary law over a fixed list of bonds, with its history (see the module docstring).

    Made by :func:`apply_boundary_law`; attached to a dynamics with
    ``dyn.attach_piece(term)``.  Attributes: ``law``, ``bonds`` ((M, 2) particle ids),
    ``kappa``, ``lam`` ((M,) history), ``s`` ((M, 3) tangential displacement),
    ``slip_dissipated`` (eV since the start: damage and slip, :attr:`dissipated`), ``stored_energy`` (stored energy of the last pass, eV),
    ``virial`` ((6,) eV of the last pass).
    """

    name = "boundary"
    adds_forces = True

    def __init__(self, law, bonds, btype, r0, kn, ftab, rest=None):
        self.law = law
        self.bonds = np.ascontiguousarray(bonds, np.int64).reshape(-1, 2)
        m = self.bonds.shape[0]
        self.btype = np.ascontiguousarray(btype, np.int64)
        self.r0 = np.ascontiguousarray(r0, float)          # r0_ab
        self.rest = self.r0.copy() if rest is None else np.ascontiguousarray(rest, float)
        self.kn = np.ascontiguousarray(kn, float)
        self.ftab = np.ascontiguousarray(ftab, float)
        self.ft, self.fs, self.d0, self.df = (np.ascontiguousarray(a, float) for a in law.bond_constants(self.r0, self.kn))
        if m and np.any(self.df <= self.d0):
            k = int(np.argmin(self.df / self.d0))
            gmin = 0.5 * self.ft[k] * self.d0[k] / (self.r0[k] ** 2 / 4.0)
            raise InputError("G_c", f"{(law.G_c or 0.0) / J_M2:.4g} J/m2",
                             f"at least {gmin / J_M2:.4g} J/m2 (the elastic energy at the tensile strength: "
                             "softening needs G_c above it)")
        self.kt = self.kn * law.kt_ratio
        self.kappa = np.zeros(m)
        self.lam = np.zeros(m)
        self.s = np.zeros((m, 3))
        self.slip_dissipated = 0.0
        self.stored_energy = 0.0
        self.virial = np.zeros(6)
        self._rowbuf = np.zeros(0, np.int64)
        self._fb = np.zeros((0, 3))
        self._rb = np.zeros((0, 2), np.int64)
        self._db = np.zeros((0, 3))
        self.nfailed = 0
        #: True: the bonds are elastic springs (no damage, no slip, no history advanced): a
        #: quench of the packing with its bonds intact (set back to False before the run)
        self.hold = False
        self.tinv = (TABLE_N - 1) / (1.0 - TABLE_LO)

    @classmethod
    def from_pairs(cls, calc, atoms, law, i, j, r=None):
        """The term over the pairs (rows i, j of ``atoms`` now) with the calculator's pair laws.
        ``r``: their set-up distances; a pair set up beyond r0_ab has its cohesive part's rest
        length there (no bond starts loaded)."""
        types = calc._check_types(atoms)
        nt = len(calc.potentials)
        ta, tb = types[i], types[j]
        btype = np.minimum(ta, tb) * nt + np.maximum(ta, tb)
        r0t = np.zeros(nt * nt)
        knt = np.zeros(nt * nt)
        ftab = np.zeros((nt * nt, TABLE_N))
        for a in range(nt):
            for b in range(nt):
                law_ab = calc.law(a, b)
                r0ab = law_ab.r0
                if a == b:
                    k = float(law_ab.stiffness(r0ab))
                else:
                    hh = 1e-4 * r0ab
                    k = -(float(law_ab.force(r0ab + hh)) - float(law_ab.force(r0ab - hh))) / (2 * hh)
                t = a * nt + b
                r0t[t], knt[t] = r0ab, k
                rr = np.linspace(TABLE_LO, 1.0, TABLE_N) * r0ab
                ftab[t] = np.maximum(np.asarray(law_ab.force(rr), float), 0.0)
        ids = atoms.arrays["id"]
        bonds = np.stack([ids[i], ids[j]], axis=1) if len(i) else np.zeros((0, 2), np.int64)
        rest = r0t[btype] if r is None else np.maximum(r0t[btype], np.asarray(r, float))
        return cls(law, bonds, btype, r0t[btype], knt[btype], ftab, rest=rest)

    # -- the force pass ----------------------------------------------------------------------
    def _rows(self, atoms):
        ids = atoms.arrays.get("id")
        if ids is None:
            raise InputError("atoms.arrays['id']", None, "stable particle ids (the boundary bonds name them)")
        ids = np.ascontiguousarray(ids, np.int64)
        size = max(int(ids.max()) + 1 if len(ids) else 0, int(self.bonds.max()) + 1 if self.bonds.size else 0)
        if self._rowbuf.shape[0] < size:
            self._rowbuf = np.empty(size, np.int64)
        row = self._rowbuf[:size]
        _row_map(ids, row)
        return row

    def evaluate(self, atoms, invm=None, dt=0.0, mode=TRIAL):
        """The bonds' forces at the current positions (kept for :meth:`scatter`); returns the stored
        energy.  ``mode`` UPDATE advances the history: the tangential displacement by the
        momenta's relative velocities times ``dt`` (the dynamics' step pass, called with the
        half-step momenta before any kick), damage and slip stored."""
        x = np.ascontiguousarray(atoms.arrays["positions"], float)
        p = atoms.arrays.get("momenta")
        if p is None:
            p = np.zeros_like(x)
        if invm is None:
            invm = 1.0 / atoms.get_masses()
        cell = np.ascontiguousarray(atoms.cell.array, float)
        pbc = np.asarray(atoms.pbc, np.bool_)
        icell = np.linalg.pinv(cell) if pbc.any() else np.zeros((3, 3))
        vir = np.zeros(6)
        m = self.bonds.shape[0]
        if self._fb.shape[0] != m:
            self._fb = np.zeros((m, 3))
            self._rb = np.full((m, 2), -1, np.int64)
            self._db = np.zeros((m, 3))
        if self.hold:
            mode = FROZEN
        e, slip, nfail = boundary_kernel(x, p, invm, cell, icell, pbc, self._rows(atoms), self.bonds[:, 0],
                                         self.bonds[:, 1], self.btype, self.r0, self.rest, self.kn, self.kt, self.ft, self.fs,
                                         self.law.mu, self.d0, self.df, self.ftab, self.tinv, self.kappa, self.lam,
                                         self.s, mode, float(dt), self.law.shear, self._fb, self._rb, self._db, vir)
        self.slip_dissipated += slip
        self.stored_energy = e
        self.virial = vir
        self.nfailed = int(nfail)
        return e

    def scatter(self, forces, momenta=None, h=0.0):
        """Add the forces of the last :meth:`evaluate` to ``forces`` (in place); with ``momenta``
        also ``momenta += h`` times them (the dynamics' second half kick)."""
        scatter(self._fb, self._rb, forces, momenta if momenta is not None else np.zeros((0, 3)), float(h))

    def add_virials(self, virials):
        """Add the bonds' per-particle virials of the last pass ((N, 6) Voigt, eV, tension positive;
        rows of the Atoms of that pass) to ``virials`` in place, and return it.  The dynamics
        evaluates the bonds at every step's positions, so after a step this is the bonds' share
        of the stress at the current positions (:func:`clusterdyn.analysis.stress.add_piece_virials`)."""
        if self._fb.shape[0]:
            bond_virials(self._fb, self._db, self._rb, virials)
        return virials

    def accumulate(self, atoms, forces, mode=TRIAL):
        """:meth:`evaluate` then :meth:`scatter` into ``forces``; returns the stored energy."""
        e = self.evaluate(atoms, mode=mode)
        self.scatter(forces)
        return e

    # -- the piece's hooks (clusterdyn.md.pieces.Piece) -----------------------------------------
    def before_forces(self, atoms, kick):
        """The bonds at the step's positions, with the half-step momenta (the history advanced in a
        step's pass, ``kick`` given; a trial pass otherwise)."""
        if kick is None:
            self.evaluate(atoms, mode=TRIAL)
        else:
            self.evaluate(atoms, self.dyn._invm_n, self.dyn.dt, mode=UPDATE)

    def add_forces(self, atoms, forces, kick):
        """The bonds' forces added (and, in a step's pass, their second half kick)."""
        self.scatter(forces, None if kick is None else atoms.arrays["momenta"], 0.0 if kick is None else kick)

    def energy(self, atoms):
        """The bonds' stored energy at the last pass, eV."""
        return self.stored_energy

    def forces(self, atoms, mode=FROZEN):
        """(N, 3) forces of the bonds alone (the history not advanced unless ``mode`` says)."""
        f = np.zeros((len(atoms), 3))
        self.accumulate(atoms, f, mode=mode)
        return f

    # -- what the history holds ------------------------------------------------------------------
    @property
    def dissipated(self):
        """Energy dissipated since the start, eV: at every step pass, the stored energy that damage
        growth and slip removed at the step's positions (so the ledger closes to the integrator's
        error)."""
        return self.slip_dissipated

    def failed(self):
        """(M,) bool: bonds that have failed (no cohesion left)."""
        return self.kappa >= self.df

    def summary(self):
        m = len(self.kappa)
        return {"bonds": m, "failed": int(self.failed().sum()), "damaged": int((self.kappa > self.d0).sum()),
                "law": self.law.todict(display=True)}

    # -- checkpoints ---------------------------------------------------------------------------
    def get_state(self):
        return {"kind": "BoundaryTerm", "law": self.law.todict(), "bonds": self.bonds.copy(),
                "btype": self.btype.copy(), "r0": self.r0.copy(), "rest": self.rest.copy(), "kn": self.kn.copy(), "ftab": self.ftab.copy(),
                "kappa": self.kappa.copy(), "lam": self.lam.copy(), "s": self.s.copy(),
                "slip_dissipated": float(self.slip_dissipated)}

    def set_state(self, st):
        if np.asarray(st["bonds"]).shape != self.bonds.shape or not np.array_equal(st["bonds"], self.bonds):
            raise InputError("state['bonds']", "other bonds", "the term's own bonds (a restart keeps the packing)")
        self.kappa = np.array(st["kappa"], float)
        self.lam = np.array(st["lam"], float)
        self.s = np.array(st["s"], float).reshape(-1, 3)
        self.slip_dissipated = float(st["slip_dissipated"])

    @classmethod
    def from_state(cls, st):
        d = dict(st["law"])
        d["select"] = str(d["select"])
        t = cls(BoundaryLaw.fromdict(d), st["bonds"], st["btype"], st["r0"], st["kn"], st["ftab"], rest=st["rest"])
        t.set_state(st)
        return t
