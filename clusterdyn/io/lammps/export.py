"""Write a Cluster Dynamics scene as a LAMMPS deck: data file, pair tables, input script (the deck's
contents: :mod:`clusterdyn.io.lammps`).  What cannot be written faithfully is refused in one line
before any file (:func:`check_deck`)."""

import json
from collections import namedtuple
from pathlib import Path

import numpy as np

from ... import units
from ...errors import InputError

__all__ = ["export_lammps", "deck_lines", "run_boundaries", "check_deck", "drive_lines", "pair_lines", "write_data",
           "write_tables",
           "initial_bond_pairs", "type_masses", "aligned_points", "table_grid", "table_entry_name",
           "lammps_table_forces", "table_interpolation_error"]

#: points of the exported tables (LAMMPS' N; uniform in r^2)
DEFAULT_TABLE_POINTS = 100000
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


def drive_lines(atoms, dt):
    """LAMMPS commands for the drives of ``atoms.constraints``: each writes its own.

    Returns ``({'groups': [...], 'fixes': [...]}, meta, held)``: the group and
    fix (and variable, region) commands, a JSON-able description per drive
    for cd.json, and the names of the groups that ``fix move`` integrates
    (not ``fix nve``).  Every constraint gives its commands through its
    ``lammps_form(atoms, dt, k)`` (:class:`~clusterdyn.md.lammps_form.LammpsForm`;
    :meth:`clusterdyn.md.layer_drives.Piston.lammps_form`,
    :meth:`clusterdyn.md.wall.Wall.lammps_form`), which refuses in one line
    what has no faithful form (a traction, a sticking wall, a callable or
    smooth-ramp U(t), a piston with free lateral motion); a constraint
    without one (e.g. ASE's) is refused by name.
    """
    groups, fixes, meta, held = [], [], {}, []
    for k, c in enumerate(atoms.constraints):
        lammps_form = getattr(c, "lammps_form", None)
        if lammps_form is None:
            raise InputError("atoms.constraints", type(c).__name__, "Piston or Wall drives (exportable as fixes)")
        form = lammps_form(atoms, dt, k)
        groups += form.groups
        fixes += form.fixes
        meta.update(form.meta)
        held += form.held
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


def _removal_setup(region, interval, layers, after=None):
    """The region-of-interest removal's regions, groups and dump (:func:`_run_lines` runs it)."""
    def edge(v):
        return "INF" if v == np.inf else ("-INF" if v == -np.inf else repr(float(v)))
    lo, hi = region.lo, region.hi
    box = " ".join(f"{edge(lo[k])} {edge(hi[k])}" for k in range(3))
    return [f"region          roi block {box} units box",
            "region          roi_out block " + box + " side out units box",
            ("group           removable subtract all " + " ".join(layers)) if layers else
            "group           removable union all",
            "group           gone dynamic removable region roi_out every 1",
            f"dump            removal all custom {interval} removal.dump id type x y z vx vy vz",
            "dump_modify     removal sort id format float %.17g" + _append(after)]


def run_boundaries(nsteps, interval=None):
    """The steps at which the first deck starts a ``run`` (LAMMPS' set-up computes the forces afresh there):
    0, and with a region's removal every multiple of ``interval`` up to the last whole block."""
    if not interval:
        return [0]
    return list(range(0, (nsteps // interval) * interval + 1, interval))


def _run_lines(nsteps, interval=None, bonds=False, start=0):
    """The deck's runs from step ``start`` (0: the first deck; else a continuation from a restart file at
    that step) to ``nsteps``.

    With a region (``interval``): blocks of ``interval`` steps, after each the particles outside the box
    (never a driven layer: group ``removable``) deleted (clusterdyn removes after the step whose number
    is a multiple of the interval).  A continuation resumes mid-loop: a restart file at the end of a block
    holds the state before that block's deletion (LAMMPS writes it within the run), so the deletion comes
    first (the group of the particles outside the region now, as the dynamic group had them); from within
    a block it runs ``upto`` the block's end."""
    upto = " upto" if start else ""
    if not interval:
        return [f"run             {nsteps}{upto}"]
    delete = "delete_atoms    group {} compress no" + (" bond yes" if bonds else "")
    nblocks, rest = divmod(nsteps, interval)
    done, into = divmod(start, interval)
    lines = []
    if start > nblocks * interval:                      # within the last, partial block
        return [f"run             {nsteps} upto"]
    if start and into == 0:                             # a block ended here: its deletion is still to do
        lines += ["group           cdout_now region roi_out",
                  "group           cdgone_now intersect cdout_now removable",
                  delete.format("cdgone_now")]
    elif start:
        lines += [f"run             {(done + 1) * interval} upto", delete.format("gone")]
        done += 1
    if nblocks - done > 0:
        lines += [f"variable        cdblock loop {nblocks - done}",
                  "label           cdremove",
                  f"run             {interval}",
                  delete.format("gone"),
                  "next            cdblock",
                  "jump            SELF cdremove"]
    if rest:
        lines.append(f"run             {rest}")
    return lines


def check_deck(atoms, calc, dyn, allow_region=False):
    """Everything :func:`export_lammps` refuses, checked without writing anything.

    Refused (:class:`~clusterdyn.errors.InputError`, one line): a calculator
    other than ClusterDynamics, dynamics other than clusterdyn's
    :class:`~clusterdyn.md.DampedVerlet` or ASE's velocity Verlet (both are
    velocity Verlet, which ``fix nve`` is), a dynamics with a region of
    interest (its removal has no form here), a drive without a LAMMPS form
    (:func:`drive_lines`), one-sided set-up bonds (:func:`initial_bond_pairs`),
    masses that differ within a material, a non-orthorhombic periodic cell.
    Returns ``(drive commands, drive meta, held groups, bonds or None)``.
    """
    from ase.md.verlet import VelocityVerlet

    from ...calculators.cluster import ClusterDynamics
    from ...md.damped import DampedVerlet
    if not isinstance(calc, ClusterDynamics):
        raise InputError("calc", type(calc).__name__, "a ClusterDynamics calculator")
    if dyn is not None and not isinstance(dyn, (DampedVerlet, VelocityVerlet)):
        raise InputError("dyn", type(dyn).__name__, "DampedVerlet or ASE's VelocityVerlet (LAMMPS' fix nve)")
    region = getattr(dyn, "region", None)
    if region is not None and not allow_region:
        raise InputError("region", repr(region), "no region of interest (removing the particles that leave "
                         "it is written only by clusterdyn run --engine lammps, which replays the removal)")
    calc.setup(atoms)
    dt = float(dyn.dt) if dyn is not None else 0.0
    drive_cmds, groups, held = drive_lines(atoms, dt)
    bonds = initial_bond_pairs(atoms, calc) if calc.parameters.attraction == "initial" else None
    type_masses(atoms, calc._check_types(atoms))
    _check_cell(atoms)
    return drive_cmds, groups, held, bonds


def _append(after):
    """``dump_modify`` words of a continuation from a restart file at step ``after``: append to the dump,
    and nothing before step ``after + 1`` (the frames up to it are the stopped run's, kept)."""
    return "" if after is None else f" append yes delay {int(after) + 1}"


def _dump_lines(frames, every, probes, after=None):
    """The deck's dumps: ``frames.dump`` every ``every`` steps (when ``frames``) and the probes'
    (:func:`export_lammps`); ``after``: a continuation's restart step (:func:`_append`)."""
    from ...md.lammps_form import group_lines
    vir = "compute         vir all stress/atom NULL virial"
    app = _append(after)
    lines = []
    if frames:
        lines += [
            vir,
            f"dump            frames all custom {every} frames.dump id type x y z vx vy vz fx fy fz "
            "c_vir[1] c_vir[2] c_vir[3] c_vir[4] c_vir[5] c_vir[6]",
            "dump_modify     frames sort id format float %.17g" + app,
        ]
    for name, rows, pevery in probes:
        if rows is None:                        # the whole sample, as frames.dump, at its own cadence
            if not frames and vir not in lines:
                lines.append(vir)
            lines += [f"dump            {name} all custom {int(pevery)} {name}.dump id type x y z vx vy vz fx fy fz "
                      "c_vir[1] c_vir[2] c_vir[3] c_vir[4] c_vir[5] c_vir[6]",
                      f"dump_modify     {name} sort id format float %.17g" + app]
            continue
        lines += group_lines(f"probe_{name}", np.asarray(rows, np.int64) + 1)
        lines += [f"dump            {name} probe_{name} custom {int(pevery)} {name}.dump id type x y z vx vy vz",
                  f"dump_modify     {name} sort id format float %.17g" + app]
    return lines


def _table_entries(calc, remainder):
    """(a, b, entry, r_lo, r_hi) of every table :func:`write_tables` writes, in its order."""
    nt = len(calc.potentials)
    out = []
    for kind in (("", "R") if remainder else ("",)):
        for a in range(nt):
            for b in range(a, nt):
                t = calc.tables[a][b]
                out.append((a, b, table_entry_name(a, b, kind), float(t.r_min), float(t.cutoff)))
    return out


def _force_lines(step, forces):
    """A continuation's first forces made those of the stopped run at its restart step.

    LAMMPS' set-up computes the forces afresh with the full-step velocities, where the run computed them
    within the step with the half-step ones (velocity Verlet): the pair damping differs by O(dt).  The
    forces the run dumped at that step are read back per atom id (``forces``: the prefix of the three
    ``atomfile`` files ``PREFIXx``, ``PREFIXy``, ``PREFIXz``; atomfile variables move with their atoms
    between ranks, as a read-in force would not) and ``fix addforce`` adds the difference at the set-up
    only (``step == S``; it is evaluated at the multiples of S only, and adds zero there).  Defined after
    every other fix, so the forces it sees are the pair forces plus the walls'."""
    s = int(step)
    lines = [f"variable        cdf0{ax} atomfile {forces}{ax}" for ax in "xyz"]
    lines += [f"variable        cdf{ax} atom (v_cdf0{ax}-f{ax})*(step=={s})" for ax in "xyz"]
    lines.append(f"fix             cdf_fix all addforce v_cdfx v_cdfy v_cdfz every {s}")
    return lines


#: what :func:`deck_lines` returns besides the lines
DeckInfo = namedtuple("DeckInfo", "bonds types cutoff skin n_points entries every groups J dt dt_ps nsteps interval")


def deck_lines(atoms, calc, dyn, *, nsteps=None, frames=20, n_points=DEFAULT_TABLE_POINTS, seed=12345, skin=None,
               dump_every=None, probes=(), region_removal=False, restart_every=None, resume=None,
               resume_forces=None):
    """The lines of the deck's input script, and a :class:`DeckInfo` (arguments: :func:`export_lammps`).

    ``resume``: a restart step; the lines are then those of the continuation from the folder's
    ``restart.STEP`` (``in.resume.cd``): ``read_restart`` instead of the data file, then everything a
    LAMMPS restart file does not hold, written by the same lines as the first deck (the pair styles and
    coefficients, neighbour settings, groups, fixes (a ``fix move`` takes its state back from the restart
    file by its ID), the time step, computes, dumps appending from step ``resume + 1`` on, the restart
    files), and the runs from that step (:func:`_run_lines`).  ``resume_forces``: the file with the run's
    frame at that step, for :func:`_force_lines` (needed with pair damping, unless the first deck starts
    a ``run`` at that step: :func:`run_boundaries`)."""
    drive_cmds, groups, held, bonds = check_deck(atoms, calc, dyn, allow_region=region_removal)
    dt = float(dyn.dt) if dyn is not None else 0.0
    initial = bonds is not None
    if initial:
        n_points = aligned_points(calc, n_points)
    types = calc._check_types(atoms)
    cutoff = float(max(t.cutoff for row in calc.tables for t in row))
    if skin is None:
        skin = calc.nl.skin
    entries = _table_entries(calc, initial)
    dt_ps = dt * units.TIME_TO_PS
    nsteps = 0 if nsteps is None else int(nsteps)
    J = getattr(dyn, "J", None)
    every = max(1, nsteps // max(1, frames)) if nsteps else 1
    if dump_every is not None:
        every = max(1, int(dump_every))
    region = getattr(dyn, "region", None) if region_removal else None
    interval = None if region is None else int(dyn.remove_interval)
    pbc = atoms.pbc
    bstr = " ".join("p" if p else "s" for p in pbc)
    lines = ["# clusterdyn export: Cluster Dynamics (CD eq. 1-2, 5-6) as LAMMPS input",
             "# units metal: Angstrom, eV, g/mol (= amu), ps; velocities Angstrom/ps"]
    if resume is None:
        lines += ["units           metal",
                  f"atom_style      {'bond' if initial else 'atomic'}",
                  "atom_modify     map array",
                  f"boundary        {bstr}",
                  "newton          on",
                  f"read_data       {DATA_FILE}"]
    else:
        lines += [f"# the continuation of {INPUT_FILE} from its restart file at step {int(resume)}",
                  f"read_restart    restart.{int(resume)}"]
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
    lines += _dump_lines(frames, every, probes, after=resume)
    if restart_every:
        lines.append(f"restart         {int(restart_every)} restart.*")
    if region is not None:
        layers = [g for g, m in groups.items() if isinstance(m, dict) and m.get("kind") in ("Piston", "Traction")]
        lines += _removal_setup(region, interval, layers, after=resume)
    if resume is not None and J is not None and int(resume) not in run_boundaries(nsteps, interval):
        if resume_forces is None:
            raise InputError("resume_forces", None, "the files of the run's forces at the restart step (pair damping)")
        lines += _force_lines(resume, resume_forces)
    lines += _run_lines(nsteps, interval, bonds=initial, start=0 if resume is None else int(resume))
    if frames and nsteps and nsteps % every:
        lines.append("write_dump      all custom frames.dump id type x y z vx vy vz fx fy fz c_vir[1] c_vir[2] "
                     "c_vir[3] c_vir[4] c_vir[5] c_vir[6] modify append yes sort id format float %.17g")
    info = DeckInfo(bonds, types, cutoff, float(skin), n_points, entries, every, groups, J, dt, dt_ps, nsteps,
                    interval)
    return lines, info


def export_lammps(atoms, calc, dyn, folder, *, nsteps=None, frames=20, n_points=DEFAULT_TABLE_POINTS,
                  seed=12345, skin=None, extra=None, dump_every=None, probes=(), region_removal=False,
                  restart_every=None):
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
    dump_every : int, optional
        Steps between dumped frames (default ``nsteps // frames``); when it
        does not divide ``nsteps`` the last step is dumped too (``write_dump``),
        as clusterdyn's frame loop takes its last frame there.
    region_removal : bool
        With a dynamics' region of interest: write the removal (``run`` in blocks of
        ``remove_interval`` steps, after each ``delete_atoms`` of the particles outside the region,
        pistons' and tractions' layers kept; the whole sample dumped to ``removal.dump`` just before
        each deletion, so that a replay can book the removed energy and momentum as clusterdyn does:
        :mod:`clusterdyn.scenes.lammps_engine`).  Without it a region is refused.
    probes : sequence of (name, rows, every)
        Extra dumps ``NAME.dump`` of the rows' positions and velocities every
        ``every`` steps (an observer of a few particles, e.g. a free-surface
        velocity probe, without dumping the whole sample that often); rows
        None: the whole sample with the columns of ``frames.dump`` (e.g. a
        trajectory at another cadence than the analysis frames).
    restart_every : int, optional
        Steps between LAMMPS restart files ``restart.STEP`` (``restart N restart.*``), so that a
        stopped run can be continued from the last one; default none.

    Returns
    -------
    pathlib.Path
        The folder.
    """
    lines, d = deck_lines(atoms, calc, dyn, nsteps=nsteps, frames=frames, n_points=n_points, seed=seed, skin=skin,
                          dump_every=dump_every, probes=probes, region_removal=region_removal,
                          restart_every=restart_every)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    n = len(atoms)
    lo, hi, mass_t = write_data(atoms, d.types, folder / DATA_FILE, margin=d.cutoff, bonds=d.bonds)
    entries = write_tables(calc, folder / TABLE_FILE, d.n_points, remainder=d.bonds is not None)
    (folder / INPUT_FILE).write_text("\n".join(lines) + "\n")
    meta = {"n_particles": n, "n_types": int(len(mass_t)), "nsteps": d.nsteps, "dump_every": d.every,
            "probes": {name: int(pevery) for name, _, pevery in probes},
            "dt_ps": d.dt_ps, "dt_ase": d.dt, "J": d.J, "table_points": d.n_points, "cutoff_A": d.cutoff,
            "skin_A": d.skin, "restart_every": None if not restart_every else int(restart_every),
            "groups": d.groups, "attraction": calc.parameters.attraction,
            "n_bonds": None if d.bonds is None else int(len(d.bonds)),
            "tables": [{"a": a, "b": b, "entry": e, "r_lo_A": lo_, "r_hi_A": hi_}
                       for a, b, e, lo_, hi_ in entries],
            "units": "metal", "extra": extra or {}}
    (folder / META_FILE).write_text(json.dumps(meta, indent=1, default=float))
    return folder
