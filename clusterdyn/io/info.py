"""Summaries of H5MD files, for ``clusterdyn info FILE.h5md``."""

import os

import numpy as np

from clusterdyn import units
from clusterdyn.io.h5md_reader import H5MDReader

__all__ = ["h5md_info", "format_info"]


def h5md_info(path):
    """Facts about an H5MD file, as a JSON-able dict.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    dict
        ``path``, ``size_bytes``, ``creator`` ({name, version} or None),
        ``particle_group``, ``n_frames``, ``n_particles``, ``first_step``,
        ``last_step``, ``time_start_ps``, ``time_end_ps`` (None without
        frames), ``pbc`` (3 bools), ``series`` (per-particle series stored:
        position, velocity, force, ...), ``per_particle`` (the extra ones),
        ``observables`` (names), ``units`` ({series: unit string}),
        ``parameters`` and ``description`` (stored scene parameters and
        dynamics description, or None), ``metadata`` (the run's metadata,
        :attr:`clusterdyn.io.H5MDReader.metadata`, with each constraint's
        ``ids`` replaced by their count ``n_particles``), ``pair_state``
        (whether the MCA linked pairs are stored per frame).

    Raises
    ------
    clusterdyn.errors.InputError
        Missing, unreadable or non-H5MD file.
    """
    with H5MDReader(path) as r:
        steps = r.steps
        times_ps = r.times * units.TIME_TO_PS
        n = r.n_frames
        has = r.has
        return {
            "path": str(path),
            "size_bytes": os.path.getsize(path),
            "creator": r.creator,
            "particle_group": r.group_name,
            "n_frames": n,
            "n_particles": r.n_particles,
            "first_step": int(steps[0]) if n else None,
            "last_step": int(steps[-1]) if n else None,
            "time_start_ps": float(times_ps[0]) if n else None,
            "time_end_ps": float(times_ps[-1]) if n else None,
            "pbc": [bool(p) for p in r.pbc],
            "series": [k for k in ("position", "velocity", "force", "species", "mass")
                       if has[k]] + ([("box/edges" if r.pbc.any() else "box/cell")] if has["edges"] else []),
            "per_particle": r.per_particle,
            "observables": r.observables,
            "units": r.units(),
            "parameters": r.parameters,
            "description": r.description,
            "metadata": _jsonable_metadata(r.metadata),
            "pair_state": bool(has["pairs"]),
        }


def _jsonable_metadata(meta):
    out = {k: v for k, v in meta.items() if k not in ("scene", "dynamics", "constraints")}
    cons = meta.get("constraints")
    if cons is not None:
        cons = [{**{k: v for k, v in c.items() if k != "ids"},
                 **({"n_particles": int(len(c["ids"]))} if c.get("ids") is not None else {})}
                for c in cons]
    out["constraints"] = cons
    return out


def _fmt(x, unit, scale):
    return "?" if not isinstance(x, (int, float)) else f"{x / scale:.6g} {unit}"


def _material_line(m):
    text = f"{m.get('id', '?')} {m.get('name', '?')}: rho0 {_fmt(m.get('rho0'), 'g/cm3', units.g_cm3)}"
    if "c0" in m:
        text += f", c0 {_fmt(m['c0'], 'km/s', units.km_s)}"
    if "r0" in m:
        text += f", r0 {_fmt(m['r0'], 'um', units.um)}"
    curve = m.get("curve")
    if curve:
        kind = curve.get("kind")
        if kind == "murnaghan":
            text += f", Murnaghan cold curve (n {curve['n']:.6g})"
        elif kind == "tabulated":
            text += (f", tabulated cold curve ({len(curve['delta'])} rows, {curve.get('tail', 'murnaghan')} "
                     f"tail n {curve.get('n_tail', float('nan')):.3g})")
        else:
            text += f", cold curve {kind}"
    if m.get("E") is not None:
        text += f", E {_fmt(m['E'], 'GPa', units.GPa)}"
    if m.get("nu") is not None:
        text += f", nu {m['nu']:.6g}"
    if m.get("response"):
        text += f", {m['response']}"
    return text


#: a drive's running records: its description is written when the file opens, so they read 0 there
_RECORDS = ("impulse_N_s", "work_J")


def _metadata_lines(meta):
    """Lines of ``clusterdyn info`` about the run's metadata."""
    missing = [k for k in ("calculator", "materials", "damping", "constraints") if meta.get(k) is None]
    lines = []
    c = meta.get("calculator")
    if c:
        if c.get("class") == "ClusterDynamics":
            lines.append(f"calculator:   ClusterDynamics, rc {c['rc']:.6g} r0, skin "
                         f"{c['skin_effective']:.6g} r0{'' if c.get('skin') is not None else ' (default)'}"
                         f", n_table {c['n_table']}, attraction {c['attraction']}")
        elif c.get("class") == "MCA":
            lines.append(f"calculator:   MCA, dim {c.get('dim')}"
                         + (f", {len(c['interfaces'])} interface strengths" if c.get("interfaces") else ""))
        else:
            lines.append(f"calculator:   {c.get('class')}")
    mats = meta.get("materials")
    if mats:
        lines.append("materials:    " + _material_line(mats[0]))
        lines += ["              " + _material_line(m) for m in mats[1:]]
    d = meta.get("damping")
    if d is not None:
        if "J" in d:
            lines.append("damping:      " + ("off (J None)" if d["J"] is None
                                             else f"J = {d['J']:.6g} (Gamma = c0/(J r0))"))
        elif "damping" in d:
            lines.append(f"damping:      {d['damping']:.6g} of critical (relative pair velocity)")
    cons = meta.get("constraints")
    if cons is not None:
        if not cons:
            lines.append("drives:       none")
        for k, con in enumerate(cons):
            if "repr" in con and "attributes" in con:     # no describe(): class and attributes
                text = con["class"] + "(" + ", ".join(f"{a}={b}" for a, b in
                                                      con["attributes"].items()) + ")"
            else:
                text = ", ".join(f"{a}={b}" + (" (at the file's start; the run's are in its observables)"
                                                if a in _RECORDS else "")
                                 for a, b in con.items() if a not in ("ids", "particles", "n_particles"))
            n = len(con["ids"]) if con.get("ids") is not None else con.get("n_particles")
            lines.append(("drives:       " if k == 0 else "              ") + text
                         + (f" [acts on {n} particles]" if n is not None else ""))
    if missing:
        lines.append("metadata:     missing " + ", ".join(missing)
                     + " (written without the run's metadata: analyses need calc= or virials=)")
    return lines


def _fmt_time(t_ps):
    if t_ps is None:
        return "-"
    a = abs(t_ps)
    if a >= 1e6:
        return f"{t_ps / 1e6:.6g} us"
    if a >= 1e3:
        return f"{t_ps / 1e3:.6g} ns"
    return f"{t_ps:.6g} ps"


def format_info(path):
    """A human-readable summary of an H5MD file (what ``clusterdyn info`` prints).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    str
        Several lines: file and creator, frames and step range, time span,
        particles and periodicity, stored series with units, observables
        (with their last value), the stored dynamics description, and the
        run's metadata: calculator (rc, skin, n_table, attraction), material
        table (rho0, c0, r0, cold curve), damping J, drives and walls.
    """
    d = h5md_info(path)
    lines = [f"file:         {d['path']} ({d['size_bytes'] / 1e6:.3g} MB)"]
    if d["creator"]:
        lines.append(f"creator:      {d['creator'].get('name', '?')} "
                     f"{d['creator'].get('version', '')}".rstrip())
    lines.append(f"particles:    {d['n_particles']} in particles/{d['particle_group']}, "
                 f"pbc {''.join('T' if p else 'F' for p in d['pbc'])}")
    if d["n_frames"]:
        lines.append(f"frames:       {d['n_frames']} (steps {d['first_step']} .. "
                     f"{d['last_step']})")
        span = d["time_end_ps"] - d["time_start_ps"]
        lines.append(f"time:         {_fmt_time(d['time_start_ps'])} .. "
                     f"{_fmt_time(d['time_end_ps'])} (span {_fmt_time(span)})")
    else:
        lines.append("frames:       0")
    u = d["units"]
    series = [f"{k} [{u[k]}]" if k in u else k for k in d["series"]]
    lines.append("series:       " + (", ".join(series) or "-"))
    extra = [f"{k} [{u[k]}]" if k in u else k for k in d["per_particle"]]
    lines.append("per-particle: " + (", ".join(extra) or "-"))
    if d["observables"]:
        lines.append("observables:  (last frame)")
        with H5MDReader(path) as r:
            for name in d["observables"]:
                unit = u.get(f"observables/{name}", "")
                try:
                    _, _, values = r.get_observable(name)
                    last = np.asarray(values[-1]) if len(values) else None
                    text = "-" if last is None else np.array2string(
                        last, precision=6, separator=", ") if last.ndim else f"{last:.6g}"
                except Exception:  # a foreign observable layout: list the name only
                    text = "?"
                if unit == "kJ mol-1" and last is not None:     # H5MD's molecular unit; a sample's energy in J too
                    joules = np.asarray(last, dtype=float) * (units.kJ / units.mol) / units.J
                    unit += " (" + (np.array2string(joules, precision=6, separator=", ") if joules.ndim
                                    else f"{joules:.6g}") + " J)"
                lines.append(f"  {name:<22s} {text} {unit}".rstrip())
    else:
        lines.append("observables:  -")
    if d["description"]:
        desc = d["description"]
        kind = desc.get("md-type") or desc.get("type") or "?"
        lines.append(f"dynamics:     {kind}" + (
            f", timestep {desc['timestep'] * units.TIME_TO_PS * 1e3:.6g} fs"
            if isinstance(desc.get("timestep"), (int, float)) else ""))
    if d["parameters"]:
        keys = ", ".join(sorted(d["parameters"])) if isinstance(d["parameters"], dict) else ""
        lines.append(f"parameters:   {keys}")
    lines += _metadata_lines(d["metadata"])
    if d["pair_state"]:
        lines.append("pair state:   linked pairs per frame (connectivity/linked_pairs)")
    return "\n".join(lines)
