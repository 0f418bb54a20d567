"""Piston speeds for a target shock pressure, from the model's own CD Hugoniot.

A scene asked for "a shock of 15 GPa" must know which piston speed gives
15 GPa *in the model*: the CD Hugoniot of a material differs from its
experimental one (lead's lies 9-21% off Steinberg's, docs/hugoniot.md), so
the speed is read from measured CD runs, not from the experimental line.

The measured points are piston shocks (:func:`clusterdyn.scenes.shock.build_shock`)
on a block of 60 x 6 x 6 repeat cells, 10 m/s noise, one per (material,
direction, rc, damping J, u): the front speed D (straight-line fit), the
longitudinal stress P = -sigma_xx behind the front (the pressure a scene
targets), ``rho0 D u`` beside it, the particle velocity behind the front,
whether the run is steady, and the ordered fraction behind the front
(:mod:`clusterdyn.analysis.order`: the share of clusters that keep their 12
fcc neighbours; below about 0.5 the shocked lattice has lost its order).
The points ship in ``clusterdyn/data/cd_hugoniot.csv``; its rows are made by

    python -m clusterdyn.scenes.pressure Pb --J none,50 --u 0.3,0.4,...

and a combination without rows is measured on the fly (about 2 s per point
on 2 cores) on :data:`DEFAULT_U_GRID`.

:func:`piston_speed` inverts P(u), a monotone cubic through the points, for
the target pressure (points where P falls as u rises, unsteady weak shocks
such as lead's at 0.5 km/s, are left out); the scenes then measure the
pressure their own sample reaches and report it beside the target.
"""

import argparse
import csv
import math
from importlib import resources

import numpy as np

from .. import units
from ..errors import InputError
from ..materials import get_material

__all__ = ["measure_cd_hugoniot", "write_cd_hugoniot", "cd_hugoniot", "piston_speed", "pressure_at", "CD_HUGONIOT_CSV",
           "DEFAULT_U_GRID", "HUGONIOT_CELLS"]

#: the shipped table of measured CD Hugoniot points
CD_HUGONIOT_CSV = "cd_hugoniot.csv"
#: piston speeds (km/s) measured when a combination has no rows
DEFAULT_U_GRID = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0)
#: repeat cells of the measuring block (along the shock, across, across)
HUGONIOT_CELLS = (60, 6, 6)
COLUMNS = ("material", "direction", "rc", "J", "u_km_s", "D_km_s", "P_GPa", "P_momentum_GPa",
           "u_behind_km_s", "steady", "ordered_fraction", "cells")

_MEASURED = {}


def _jkey(J):
    return "none" if J is None else f"{float(J):g}"


def measure_cd_hugoniot(material, us, *, J=None, direction="100", rc=1.15, size=HUGONIOT_CELLS,
                        r0=5 * units.um, noise=10 * units.m_s, seed=1, progress=False):
    """Run one piston shock per speed and return the measured points.

    Parameters
    ----------
    material : str
        A CD material of the library.
    us : sequence of float
        Piston speeds, ASE units.
    J : float or None
        Pair damping (None: off).
    direction, rc, size, r0, noise, seed :
        As for :func:`clusterdyn.scenes.shock.build_shock` (CD shock speeds do
        not depend on r0).

    Returns
    -------
    list of dict
        One row per speed with the :data:`COLUMNS` (display units: km/s, GPa).
    """
    from ..analysis.order import OrderReference
    from .shock import build_shock, run_shock
    rows = []
    for u in us:
        # fit_from=0: the fit window is the last 80% of the sample's front travel, as when the shipped
        # rows were measured (the auto window of the shock scene is sized for its auto lengths)
        s = build_shock(material, u, direction, size, r0, rc, J, noise, seed, fit_from=0)
        ref = OrderReference(s.atoms.copy(), r0=r0)
        tracker, st, _ = run_shock(s, frames=30, progress=progress, desc=f"CD Hugoniot {material} u={u / units.km_s:g}")
        a = s.atoms
        x = a.positions[:, s.axis]
        front = tracker.frames[-1]["front"]
        pist = a.positions[s.piston_mask, s.axis].max()
        behind = (x > pist + 5 * s.slab) & (x < front - 3 * s.slab)
        rows.append({"material": get_material(material).name, "direction": str(direction), "rc": float(rc),
                     "J": _jkey(J), "u_km_s": u / units.km_s, "D_km_s": st.D_fit / units.km_s,
                     "P_GPa": st.P / units.GPa, "P_momentum_GPa": st.P_momentum / units.GPa,
                     "u_behind_km_s": st.u / units.km_s, "steady": bool(st.steady),
                     "ordered_fraction": ref.fraction(a, behind), "cells": "x".join(map(str, size))})
    return rows


def write_cd_hugoniot(rows, path):
    """Write measured points as CSV (the :data:`COLUMNS`); returns the path."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([f"{r[c]:.6g}" if isinstance(r[c], float) else r[c] for c in COLUMNS])
    return path


def _shipped():
    path = resources.files("clusterdyn") / "data" / CD_HUGONIOT_CSV
    if not path.is_file():
        return []
    with path.open() as fh:
        return [r for r in csv.DictReader(fh) if r and not r["material"].startswith("#")]


def cd_hugoniot(material, *, J=None, direction="100", rc=1.15, measure=True, progress=False):
    """The measured CD Hugoniot points of a combination (shipped, else measured now).

    Returns
    -------
    dict
        ``u``, ``D``, ``P`` (ASE units, (n,) arrays ascending in u),
        ``ordered`` (n,), ``steady`` (n,) bool, ``source`` ("table" or "measured now").
    """
    name = get_material(material).name
    key = (name, str(direction), float(rc), _jkey(J))
    rows = [r for r in _shipped() if (r["material"], r["direction"], float(r["rc"]), r["J"]) == key]
    source = "table clusterdyn/data/cd_hugoniot.csv"
    if not rows:
        if key not in _MEASURED:
            if not measure:
                raise InputError("material", name, f"a combination with measured CD Hugoniot points "
                                 f"(none for {name} [{direction}] rc={rc:g} J={_jkey(J)})")
            got = measure_cd_hugoniot(name, [u * units.km_s for u in DEFAULT_U_GRID], J=J, direction=direction,
                                      rc=rc, progress=progress)
            _MEASURED[key] = [{k: str(v) for k, v in r.items()} for r in got]
        rows = _MEASURED[key]
        source = "measured now on " + "x".join(map(str, HUGONIOT_CELLS)) + " cells"
    rows = sorted(rows, key=lambda r: float(r["u_km_s"]))
    f = lambda c: np.array([float(r[c]) for r in rows])      # noqa: E731
    return {"u": f("u_km_s") * units.km_s, "D": f("D_km_s") * units.km_s, "P": f("P_GPa") * units.GPa,
            "ordered": f("ordered_fraction"), "steady": np.array([r["steady"] in ("True", "true", "1")
                                                                  for r in rows]),
            "source": source, "material": name, "J": _jkey(J), "direction": str(direction), "rc": float(rc)}


def _rising(h):
    """The points of a CD Hugoniot on which P rises with u (a point below its predecessor is left out)."""
    u, Ps = h["u"], h["P"]
    keep = [0]
    for k in range(1, len(u)):
        if Ps[k] > Ps[keep[-1]]:
            keep.append(k)
    return u[keep], Ps[keep]


def pressure_at(u, hugoniot):
    """P(u) of measured CD Hugoniot points (the monotone cubic :func:`piston_speed` inverts), ASE units."""
    from scipy.interpolate import PchipInterpolator
    us, Ps = _rising(hugoniot)
    return float(PchipInterpolator(us, Ps, extrapolate=True)(u))


def piston_speed(material, pressure, *, J=None, direction="100", rc=1.15, hugoniot=None):
    """Piston speed whose shock has longitudinal stress ``pressure`` in the CD model.

    Parameters
    ----------
    material : str
    pressure : float
        Target -sigma_xx behind the front, ASE units (``15 * units.GPa``).
    J, direction, rc :
        The model (damping, crystal direction along the shock, cutoff).
    hugoniot : dict, optional
        Points from :func:`cd_hugoniot` (default: looked up).

    Returns
    -------
    dict
        ``u`` (ASE units), ``D`` (the front speed there, ASE units, from the
        same monotone interpolation), ``ordered`` (interpolated ordered
        fraction behind the front), ``hugoniot`` (the points used).

    Raises
    ------
    InputError
        The pressure lies outside the measured points' range.
    """
    from scipy.interpolate import PchipInterpolator
    from scipy.optimize import brentq
    try:
        P = float(pressure)
    except (TypeError, ValueError):
        raise InputError("pressure", pressure, "a positive pressure") from None
    if not (math.isfinite(P) and P > 0):
        raise InputError("pressure", pressure, "a positive pressure")
    h = hugoniot if hugoniot is not None else cd_hugoniot(material, J=J, direction=direction, rc=rc)
    u, Ps = _rising(h)
    if len(u) < 2 or not (Ps[0] <= P <= Ps[-1]):
        raise InputError("pressure", f"{P / units.GPa:g} GPa",
                         f"a pressure within the measured CD Hugoniot of {h['material']} (J={h['J']}): "
                         f"{Ps[0] / units.GPa:.3g}-{Ps[-1] / units.GPa:.3g} GPa")
    Pu = PchipInterpolator(u, Ps)
    us = brentq(lambda x: float(Pu(x)) - P, u[0], u[-1], xtol=1e-12 * u[-1])
    D = float(PchipInterpolator(h["u"], h["D"])(us))
    ordered = float(np.interp(us, h["u"], h["ordered"]))
    return {"u": float(us), "D": D, "ordered": ordered, "hugoniot": h}


def main(argv=None):
    """Measure CD Hugoniot points and append them to a CSV (the shipped table's maker)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("material")
    ap.add_argument("--J", default="none", help="comma-separated damping J values, 'none' = off")
    ap.add_argument("--u", required=True, help="comma-separated piston speeds, km/s")
    ap.add_argument("--direction", default="100")
    ap.add_argument("--rc", type=float, default=1.15)
    ap.add_argument("--out", default="cd_hugoniot.csv")
    a = ap.parse_args(argv)
    rows = []
    for j in a.J.split(","):
        J = None if j.strip() == "none" else float(j)
        got = measure_cd_hugoniot(a.material, [float(x) * units.km_s for x in a.u.split(",")], J=J,
                                  direction=a.direction, rc=a.rc)
        for r in got:
            print(", ".join(f"{c}={r[c]:.4g}" if isinstance(r[c], float) else f"{c}={r[c]}" for c in COLUMNS),
                  flush=True)
        rows += got
    try:
        with open(a.out) as fh:
            old = list(csv.DictReader(fh))
    except FileNotFoundError:
        old = []
    with open(a.out, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in old:
            w.writerow([r[c] for c in COLUMNS])
        for r in rows:
            w.writerow([f"{r[c]:.6g}" if isinstance(r[c], float) else r[c] for c in COLUMNS])


if __name__ == "__main__":
    main()
