"""The planar rigid wall: a smooth harmonic repulsion, frictionless or sticking, with its numba kernels.

In LAMMPS it is ``fix wall/region ... harmonic``."""

import numpy as np
from numba import njit

from .. import units
from ..errors import InputError, InstabilityError
from .drives import Drive, _is_f64, _masses, _rows, _shuffle, _unit
from .lammps_form import LammpsForm, group_lines

__all__ = ["Wall", "wall_harmonic", "wall_energy", "kick_rows", "stick_rows"]


@njit(cache=True)
def _wall_candidates(x_nc, rows, n_c, p0, reach, touched):
    """Rows with ``d = x . n - p0 < reach`` into ``touched``; returns (count, smallest d)."""
    n0 = n_c[0]
    n1 = n_c[1]
    n2 = n_c[2]
    dmin = np.inf
    nt = 0
    if rows.shape[0] == 0:
        for i in range(x_nc.shape[0]):
            d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
            dmin = min(dmin, d)
            if d < reach:
                touched[nt] = i
                nt += 1
    else:
        for q in range(rows.shape[0]):
            i = rows[q]
            d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
            dmin = min(dmin, d)
            if d < reach:
                touched[nt] = i
                nt += 1
    return nt, dmin


@njit(cache=True)
def wall_harmonic(x_nc, f_nc, rows, types_n, point_c, n_c, K_t, dc_t, stick, touched, extra_nc):
    """Add the harmonic wall force to ``f`` and list the touched particles.

    For particle i (all rows, or ``rows`` when it has entries) at distance
    ``d = x_i . n - point . n`` from the plane, if ``d < dc``: force
    ``2 K (dc - d) n`` and energy ``K (dc - d)^2`` (K, dc of its type).  With
    ``stick`` the tangential part of ``f_i`` is removed as well.  The change
    made to ``f_i`` goes to ``extra_nc[q]`` with ``touched[q] = i``.  One
    streaming pass finds the particles within the largest d_c (and the
    smallest d); the forces are then computed on those alone.
    Returns (touched count, energy, sum of the changes (3), smallest d, its particle).
    """
    n0 = n_c[0]
    n1 = n_c[1]
    n2 = n_c[2]
    p0 = point_c[0] * n0 + point_c[1] * n1 + point_c[2] * n2
    nc, dmin = _wall_candidates(x_nc, rows, n_c, p0, dc_t.max(), touched)
    nt = 0
    e = 0.0
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for q in range(nc):
        i = touched[q]
        d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
        t = types_n[i]
        dc = dc_t[t]
        if d < dc:
            K = K_t[t]
            g = dc - d
            e += K * g * g
            fw = 2.0 * K * g
            ex = fw * n0
            ey = fw * n1
            ez = fw * n2
            if stick:
                fn = f_nc[i, 0] * n0 + f_nc[i, 1] * n1 + f_nc[i, 2] * n2
                ex -= f_nc[i, 0] - fn * n0
                ey -= f_nc[i, 1] - fn * n1
                ez -= f_nc[i, 2] - fn * n2
            f_nc[i, 0] += ex
            f_nc[i, 1] += ey
            f_nc[i, 2] += ez
            touched[nt] = i
            extra_nc[nt, 0] = ex
            extra_nc[nt, 1] = ey
            extra_nc[nt, 2] = ez
            fx += ex
            fy += ey
            fz += ez
            nt += 1
    imin = -1
    if dmin < 0.0:                       # name the particle (a failing step only)
        for q in range(x_nc.shape[0] if rows.shape[0] == 0 else rows.shape[0]):
            i = q if rows.shape[0] == 0 else rows[q]
            if x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0 == dmin:
                imin = i
                break
    return nt, e, fx, fy, fz, dmin, imin


@njit(cache=True)
def wall_energy(x_nc, rows, types_n, point_c, n_c, K_t, dc_t, touched):
    """Energy of the harmonic wall, sum of ``K (dc - d)^2`` over particles with ``d < dc``."""
    n0 = n_c[0]
    n1 = n_c[1]
    n2 = n_c[2]
    p0 = point_c[0] * n0 + point_c[1] * n1 + point_c[2] * n2
    nc, dmin = _wall_candidates(x_nc, rows, n_c, p0, dc_t.max(), touched)
    e = 0.0
    for q in range(nc):
        i = touched[q]
        d = x_nc[i, 0] * n0 + x_nc[i, 1] * n1 + x_nc[i, 2] * n2 - p0
        t = types_n[i]
        if d < dc_t[t]:
            g = dc_t[t] - d
            e += K_t[t] * g * g
    return e


@njit(cache=True)
def kick_rows(p_nc, touched, extra_nc, nt, h):
    """p[touched[q]] += h * extra[q] for q < nt."""
    for q in range(nt):
        i = touched[q]
        p_nc[i, 0] += h * extra_nc[q, 0]
        p_nc[i, 1] += h * extra_nc[q, 1]
        p_nc[i, 2] += h * extra_nc[q, 2]


@njit(cache=True)
def stick_rows(p_nc, m_n, touched, nt, n_c, dp_c):
    """Remove the tangential momentum of the touched rows; dp (3) gets the momentum change,
    returns the kinetic energy removed."""
    de = 0.0
    for q in range(nt):
        i = touched[q]
        pn = p_nc[i, 0] * n_c[0] + p_nc[i, 1] * n_c[1] + p_nc[i, 2] * n_c[2]
        tx = p_nc[i, 0] - pn * n_c[0]
        ty = p_nc[i, 1] - pn * n_c[1]
        tz = p_nc[i, 2] - pn * n_c[2]
        de += 0.5 * (tx * tx + ty * ty + tz * tz) / m_n[i]
        p_nc[i, 0] -= tx
        p_nc[i, 1] -= ty
        p_nc[i, 2] -= tz
        dp_c[0] -= tx
        dp_c[1] -= ty
        dp_c[2] -= tz
    return de


def _per_type(v, name, unit):
    if v is None:
        return None
    a = np.atleast_1d(np.array(v, dtype=float))
    if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a)) or not np.all(a > 0):
        raise InputError(name, v, f"a positive number ({unit}) or one per material id, or None for the default")
    return a


class Wall(Drive):
    """A planar rigid wall with any normal, as a smooth repulsive force (harmonic).

    A particle at distance ``d = (x - point) . normal`` from the plane (on the
    side the normal points to) feels, for ``d < d_c``,

    .. math::  E = K (d_c - d)^2, \\qquad \\mathbf f = 2 K (d_c - d)\\, \\mathbf n

    exactly LAMMPS' ``fix wall/region ... harmonic K sigma d_c`` on a plane
    region (so the export is faithful).  Defaults from the calculator's pair
    law (:class:`~clusterdyn.calculators.ClusterDynamics`), per material a:
    ``2 K_a = k_a`` with ``k_a = -f'(r0_a)`` the cluster-cluster bond stiffness
    (the wall is as stiff as one bond) and ``d_c = r0_a / 2`` (a cluster
    touches the wall where a neighbour at r0 would touch it).

    Frictionless by default.  ``sticking=True``: particles within ``d_c``
    have the tangential part of their force removed and their tangential
    momentum set to zero at every constraint call (no slip while touching);
    the momentum removed counts in :attr:`impulse` and the kinetic energy
    removed in :attr:`dissipated`.

    The wall's energy enters ``atoms.get_potential_energy()`` (and
    DampedVerlet's energies) through ``adjust_potential_energy``, so the
    total energy is conserved.  A fixed wall does no work (:attr:`work` stays 0).
    A particle behind the plane (d < 0) stops the run with
    :class:`~clusterdyn.errors.InstabilityError` (the time step does not
    resolve the impact, or the wall is too soft for it).

    Parameters
    ----------
    point : (3,) array, Angstrom
        A point of the plane.
    normal : (3,) array
        Normal pointing to the particles' side; normalised.
    stiffness : float or (n_materials,) array, optional
        K, eV/Angstrom^2 (LAMMPS' epsilon of the harmonic style).
    cutoff : float or (n_materials,) array, optional
        d_c, Angstrom.
    sticking : bool, default False
    indices : array of int or bool mask, optional
        Particles the wall acts on (default: all).
    """

    kind = "Wall"

    def __init__(self, point, normal, stiffness=None, cutoff=None, sticking=False, indices=None):
        super().__init__()
        p = np.array(point, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError("point", point, "a finite 3-vector (Angstrom)")
        self.point = p
        self.normal = _unit(normal, "normal")
        self.stiffness = _per_type(stiffness, "stiffness", "eV/Angstrom^2")
        self.cutoff = _per_type(cutoff, "cutoff", "Angstrom")
        if not isinstance(sticking, (bool, np.bool_)):
            raise InputError("sticking", sticking, "True or False")
        self.sticking = bool(sticking)
        self.index = None if indices is None else _rows(indices)
        self.energy = 0.0
        self.dissipated = 0.0
        self._K_t = None
        self._dc_t = None
        self._zeros = None
        self._buf = None
        self._nt = 0

    _NO_ROWS = np.zeros(0, np.int64)

    def resolve(self, atoms):
        """Fix K and d_c per material id (defaults from ``atoms.calc``); returns (K_t, dc_t)."""
        if self._K_t is not None:
            return self._K_t, self._dc_t
        K, dc = self.stiffness, self.cutoff
        if (K is None or dc is None) and hasattr(atoms.calc, "wall_defaults"):
            K_d, dc_d = atoms.calc.wall_defaults(atoms)      # e.g. MCA: from modulus and size
            K = np.asarray(K_d, float) if K is None else K
            dc = np.asarray(dc_d, float) if dc is None else dc
        if K is None or dc is None:
            calc = atoms.calc
            if hasattr(calc, "setup") and hasattr(calc, "potentials"):
                calc.setup(atoms)
            pots = getattr(calc, "potentials", None)
            if not pots:
                raise InputError("stiffness" if K is None else "cutoff", None,
                                 "a value: the defaults (2K = -f'(r0), d_c = r0/2) need a ClusterDynamics "
                                 "calculator's pair law")
            if K is None:
                K = np.array([0.5 * float(p.stiffness(p.r0)) for p in pots])
            if dc is None:
                dc = np.array([0.5 * float(p.r0) for p in pots])
        nt = max(K.size, dc.size)
        if K.size not in (1, nt) or dc.size not in (1, nt):
            raise InputError("stiffness", K.tolist(), f"one value or one per material ({nt}) like cutoff")
        self._K_t = np.ascontiguousarray(np.broadcast_to(K, (nt,)), dtype=float)
        self._dc_t = np.ascontiguousarray(np.broadcast_to(dc, (nt,)), dtype=float)
        return self._K_t, self._dc_t

    def _types(self, atoms):
        n = len(atoms)
        if self._K_t.size == 1:
            if self._zeros is None or self._zeros.shape[0] != n:
                self._zeros = np.zeros(n, np.int64)
            return self._zeros
        mid = atoms.arrays.get("material")
        if mid is None:
            raise InputError("atoms.arrays['material']", None, "material ids for a wall with per-material K")
        mid = np.ascontiguousarray(mid, dtype=np.int64)
        if n and (mid.min() < 0 or mid.max() >= self._K_t.size):
            raise InputError("atoms.arrays['material']", f"ids {mid.min()}..{mid.max()}",
                             f"ids in 0..{self._K_t.size - 1} (one wall stiffness per material)")
        return mid

    def _rows_arg(self):
        return self._NO_ROWS if self.index is None else self.index

    def adjust_forces(self, atoms, forces):
        K_t, dc_t = self.resolve(atoms)
        types = self._types(atoms)
        x = np.ascontiguousarray(atoms.arrays["positions"], dtype=float)
        n = len(atoms)
        if self._buf is None or self._buf[0].shape[0] != n:
            self._buf = (np.empty(n, np.int64), np.empty((n, 3)))
        touched, extra = self._buf
        f = forces if _is_f64(forces) else np.ascontiguousarray(forces, dtype=float)
        nt, e, fx, fy, fz, dmin, imin = wall_harmonic(x, f, self._rows_arg(), types, self.point, self.normal,
                                                      K_t, dc_t, self.sticking, touched, extra)
        if f is not forces:
            forces[:] = f
        self._nt = nt
        self.energy = e
        if dmin < 0.0:
            raise InstabilityError("a particle crossed behind the wall plane (the wall force did not stop it: "
                                   "lower the time step or stiffen the wall)", step=self._step_number(),
                                   particles=(imin,), quantity="distance from the wall plane",
                                   value=float(dmin), limit=0.0)
        t = self.time
        how = self._how(t)
        if how != "skip":
            self._commit(how, t, -np.array([fx, fy, fz]), 0.0)

    def kick_extra(self, momenta, h):
        if self._nt:
            kick_rows(momenta, self._buf[0], self._buf[1], self._nt, h)

    def adjust_momenta(self, atoms, momenta):
        if not self.sticking or not self._nt:
            return
        m = _masses(atoms)
        p = momenta if _is_f64(momenta) else np.ascontiguousarray(momenta, dtype=float)
        dp = np.zeros(3)
        de = stick_rows(p, np.ascontiguousarray(m, dtype=float), self._buf[0], self._nt, self.normal, dp)
        if p is not momenta:
            momenta[:] = p
        self.impulse = self.impulse + dp
        self.dissipated += de

    def adjust_potential_energy(self, atoms):
        K_t, dc_t = self.resolve(atoms)
        x = np.ascontiguousarray(atoms.arrays["positions"], dtype=float)
        scratch = np.empty(len(atoms), np.int64)
        return float(wall_energy(x, self._rows_arg(), self._types(atoms), self.point, self.normal, K_t, dc_t,
                                 scratch))

    def index_shuffle(self, atoms, ind):
        if self.index is not None:
            self.index = _shuffle(self.index, ind, "wall")
        self._nt = 0

    def get_state(self):
        K = self._K_t if self._K_t is not None else self.stiffness
        dc = self._dc_t if self._dc_t is not None else self.cutoff
        return {"kind": self.kind, "point": self.point.copy(), "normal": self.normal.copy(),
                "stiffness": None if K is None else np.array(K), "cutoff": None if dc is None else np.array(dc),
                "sticking": self.sticking, "index": None if self.index is None else self.index.copy(),
                "dissipated": float(self.dissipated), **self._records_state()}

    @classmethod
    def _from_state(cls, d):
        w = cls(d["point"], d["normal"], d.get("stiffness"), d.get("cutoff"), bool(d.get("sticking", False)),
                d.get("index"))
        w.dissipated = float(d.get("dissipated", 0.0))
        w._restore_records(d)
        return w

    def describe(self):
        K = self._K_t if self._K_t is not None else self.stiffness
        dc = self._dc_t if self._dc_t is not None else self.cutoff
        return {"kind": "Wall", "point_um": (self.point / units.um).tolist(), "normal": self.normal.tolist(),
                "law": "harmonic: E = K (d_c - d)^2 for d < d_c (LAMMPS fix wall/region harmonic)",
                "K_eV_per_A2": None if K is None else np.asarray(K).tolist(),
                "K_N_per_m": None if K is None else (np.asarray(K) / (units.J / units.m ** 2)).tolist(),
                "d_c_um": None if dc is None else (np.asarray(dc) / units.um).tolist(),
                "default_rule": "2K = -f'(r0), d_c = r0/2 of each material's pair law",
                "sticking": self.sticking,
                "n_particles": None if self.index is None else int(self.index.size),
                "impulse_N_s": (self.impulse / (units.N * units.s)).tolist(),
                "dissipated_J": float(self.dissipated / units.J)}

    def lammps_form(self, atoms, dt, k):
        """``region wall<k> plane ... side in units box`` and ``fix wall/region ... harmonic K 1.0 d_c``
        (with ``fix_modify energy yes``), one fix per material when K differs by material.  Refused: a
        sticking wall (LAMMPS' fix has no sticking law), a normal with a component along a periodic
        axis (LAMMPS wraps periodic coordinates)."""
        if self.sticking:
            raise InputError("atoms.constraints", repr(self),
                             "a frictionless wall (LAMMPS' fix wall/region has no sticking law)")
        per = np.abs(self.normal[np.asarray(atoms.pbc, bool)])
        if per.size and per.max() > 0:
            raise InputError("atoms.constraints", repr(self), "a wall whose normal is perpendicular to the "
                             "periodic axes (LAMMPS wraps periodic coordinates)")
        K_t, dc_t = self.resolve(atoms)
        name = f"wall{k}"
        form = LammpsForm()
        groups, fixes = form.groups, form.fixes
        p, n = self.point.tolist(), self.normal.tolist()
        fixes.append(f"region          {name} plane {p[0]!r} {p[1]!r} {p[2]!r} {n[0]!r} {n[1]!r} {n[2]!r} "
                     "side in units box")
        base = "all"
        if self.index is not None:
            groups += group_lines(f"{name}_sel", np.asarray(self.index) + 1)
            base = f"{name}_sel"
        targets = [(base, 0, "")]
        if K_t.size > 1:
            targets = []
            for t in range(K_t.size):
                g = f"{name}_type{t + 1}"
                if base == "all":
                    groups.append(f"group           {g} type {t + 1}")
                else:
                    groups.append(f"group           {g}_all type {t + 1}")
                    groups.append(f"group           {g} intersect {g}_all {base}")
                targets.append((g, t, f"_{t + 1}"))
        for g, t, sfx in targets:
            fixes.append(f"fix             {name}{sfx} {g} wall/region {name} harmonic "
                         f"{float(K_t[t])!r} 1.0 {float(dc_t[t])!r}")
            fixes.append(f"fix_modify      {name}{sfx} energy yes")
        form.meta[name] = {"kind": "Wall", "point_A": p, "normal": n,
                           "K_eV_per_A2": K_t.tolist(), "cutoff_A": dc_t.tolist()}
        return form

    def __repr__(self):
        return (f"Wall(point={self.point.tolist()}, normal={self.normal.tolist()}, "
                f"{'sticking' if self.sticking else 'frictionless'})")
