"""Summaries of H5MD files, for ``clusterdyn info FILE.h5md``."""

import os

import numpy as np

from clusterdyn import units
from clusterdyn.io.h5md import H5MDReader

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
        dynamics description, or None).

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
                       if has[k]] + (["box/edges"] if has["edges"] else []),
            "per_particle": r.per_particle,
            "observables": r.observables,
            "units": r.units(),
            "parameters": r.parameters,
            "description": r.description,
        }


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
        (with their last value), and the stored dynamics description.
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
    return "\n".join(lines)
