"""LAMMPS text a drive, wall or region writes for itself (the deck: :mod:`clusterdyn.io.lammps`).

Each member of the drive family has ``lammps_form(atoms, dt, k)``: the
:class:`LammpsForm` of its commands (``k``: its place among the Atoms'
constraints, which names its groups and fixes), or a one-line
:class:`~clusterdyn.errors.InputError` naming the setting that has no
faithful LAMMPS form.  This module holds the form and the text helpers the
members share: id ranges, group commands, and the equal-style formulas of a
piecewise-linear history.  Units are LAMMPS' metal units (Angstrom, ps).
"""

from dataclasses import dataclass, field

import numpy as np

__all__ = ["LammpsForm", "id_ranges", "group_lines", "table_formulas", "variable_lines", "TERMS_PER_VARIABLE"]


@dataclass
class LammpsForm:
    """The commands of one drive in a LAMMPS deck.

    ``groups``: group commands (written before the integrator); ``fixes``:
    variable, region and fix commands (written after it); ``meta``: ``{name:
    JSON-able description}`` for cd.json; ``held``: groups the drive moves
    itself (``fix move``), which ``fix nve`` leaves out.
    """

    groups: list = field(default_factory=list)
    fixes: list = field(default_factory=list)
    meta: dict = field(default_factory=dict)
    held: list = field(default_factory=list)


def id_ranges(ids):
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


def group_lines(name, ids, per_line=200):
    parts = id_ranges(ids)
    lines = []
    for k in range(0, len(parts), per_line):
        lines.append(f"group {name} id " + " ".join(parts[k:k + per_line]))
    return lines


#: terms per equal-style variable of a U(t) table (long tables are split over several variables)
TERMS_PER_VARIABLE = 24


def table_formulas(times_ps, vals, t0_ps, s):
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


def variable_lines(name, terms):
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
