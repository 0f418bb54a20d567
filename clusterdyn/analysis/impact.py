"""Impact measures: Taylor-rod outlines, holes in plates, ejecta cones, debris clouds, radiographs.

Every function works on plain arrays (positions in Angstrom, masses in amu)
so that it serves a run in progress, a finished Atoms and an H5MD frame
alike; the definitions are those of docs/impact.md:

* **Taylor rod** (:func:`axial_outline`, :func:`taylor_measures`,
  :func:`taylor_yield`): the outline r(z) is, in slabs of a given width
  along the rod's axis, the ``q``-th percentile (default 98) of the clusters'
  radial distances from the axis, plus an offset (the scene calibrates it on
  the undeformed rod so that its outline is D0/2).  From it: the final length
  Lf, the undeformed length X (the rear part whose outline stays within 2% of
  D0/2), the largest diameter Df and the diameter W at 0.2 L0 from the
  impact face; Taylor's one-dimensional yield estimate
  ``Y = rho0 V^2 (L0 - X) / (2 (L0 - Lf) ln(L0/X))``.
* **Hole in a plate** (:func:`hole_diameter`): the clusters of the plate
  near its mid-plane are projected on it; on a square mesh the empty cells
  connected to the impact point form the perforation, and its diameter is
  that of the circle of equal area.
* **Cone** (:func:`cone_half_angle`): the half-angle about a direction that
  holds a given fraction of the mass (the backward ejecta cone).
* **Radiograph** (:func:`projected_density`): mass per unit area projected
  along one axis.
* **Taylor data** (:func:`taylor_tests`, :func:`find_taylor_test`,
  :func:`taylor_outline`): the 6061-T6 tests shipped in ``clusterdyn/data``
  (Wilkins and Guinan 1973, Gust 1982).
"""

import csv
import math
from importlib import resources

import numpy as np

from .. import units
from ..errors import InputError, check_positive

__all__ = ["axial_outline", "taylor_measures", "taylor_yield", "outline_deviation", "hole_diameter", "plate_hole",
           "cone_half_angle", "projected_density", "taylor_tests", "find_taylor_test", "taylor_outline",
           "ROOM_TEMPERATURE_K"]

#: tests at or below this initial temperature count as room temperature (K)
ROOM_TEMPERATURE_K = 300.0
#: the rear part of a Taylor rod counts as undeformed while its radius stays within this of D0/2
UNDEFORMED_TOL = 0.02
#: W is the diameter at this fraction of L0 from the impact face
W_AT = 0.2


# ----------------------------------------------------------------------------- Taylor rods
def _lateral(axis):
    return [d for d in range(3) if d != axis]


def axial_outline(positions, axis, width, *, center=None, q=98.0, lo=None, hi=None, min_count=3):
    """Outline of a body of revolution: per slab along ``axis``, a percentile of the radial distance.

    Parameters
    ----------
    positions : (N, 3) float, Angstrom
    axis : int
        The body's axis (0, 1, 2).
    width : float
        Slab width, Angstrom.
    center : (2,) float, optional
        The axis' position across (the two other coordinates in increasing
        axis order), Angstrom.  Default: the mean of the positions.
    q : float
        Percentile of the radial distances taken as the slab's radius (0-100).
    lo, hi : float, optional
        Range along ``axis`` (default: the positions' extent).
    min_count : int
        Slabs with fewer particles get NaN.

    Returns
    -------
    dict
        ``z`` (nb,) slab centres, ``r`` (nb,) radius (NaN in sparse slabs),
        ``count`` (nb,) particles per slab, ``edges`` (nb+1,), all Angstrom.
    """
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0:
        raise InputError("positions", f"array of shape {pos.shape}", "a non-empty (N, 3) array")
    check_positive("width", width)
    if not 0.0 <= q <= 100.0:
        raise InputError("q", q, "a percentile in [0, 100]")
    z = pos[:, axis]
    lat = pos[:, _lateral(axis)]
    c = lat.mean(axis=0) if center is None else np.asarray(center, dtype=float)
    r = np.hypot(lat[:, 0] - c[0], lat[:, 1] - c[1])
    lo = z.min() if lo is None else float(lo)
    hi = z.max() + 1e-9 * width if hi is None else float(hi)
    nb = max(1, int(math.ceil((hi - lo) / width)))
    edges = lo + width * np.arange(nb + 1)
    idx = np.floor((z - lo) / width).astype(np.int64)
    ok = (idx >= 0) & (idx < nb)
    idx, rr = idx[ok], r[ok]
    order = np.argsort(idx, kind="stable")
    idx, rr = idx[order], rr[order]
    count = np.bincount(idx, minlength=nb)
    start = np.concatenate([[0], np.cumsum(count)])
    out = np.full(nb, np.nan)
    for b in range(nb):
        if count[b] >= min_count:
            out[b] = np.percentile(rr[start[b]:start[b + 1]], q)
    return {"z": 0.5 * (edges[1:] + edges[:-1]), "r": out, "count": count, "edges": edges}


def taylor_measures(z, r, L0, D0, *, face=0.0, top=None):
    """Lf, X, Df and W of a Taylor rod from its outline.

    Parameters
    ----------
    z, r : (nb,) float, Angstrom
        Outline (slab centres and radii, :func:`axial_outline` plus the
        calibration offset), z increasing away from the impact face.
    L0, D0 : float
        Initial length and diameter, Angstrom.
    face : float
        Position of the impact face along z (the wall plane), Angstrom.
    top : float, optional
        Position of the rear face (default: the last slab's upper edge).

    Returns
    -------
    dict
        ``Lf`` (rear face - impact face), ``X`` (undeformed rear length: from
        the rear face down to the lower edge of the first slab, counted from
        the impact face, that starts a stretch of ``D0/2`` whose radii all
        stay within ``(1 + 0.02) D0/2``: the deformed zone is what lies below
        it, and neither noise in the outline nor a small flare at the rear
        end moves X; ``Lf`` if the outline is within the tolerance from the
        impact face on, 0 if no such stretch exists), ``Df`` (twice the
        largest radius), ``W`` (twice the radius at ``0.2 L0`` from the
        impact face, interpolated), all Angstrom.
    """
    z = np.asarray(z, dtype=float)
    r = np.asarray(r, dtype=float)
    ok = np.isfinite(r)
    z, r = z[ok], r[ok]
    if len(z) == 0:
        raise InputError("r", "all NaN", "an outline with at least one populated slab")
    w = z[1] - z[0] if len(z) > 1 else 0.0
    top = z[-1] + 0.5 * w if top is None else float(top)
    Lf = top - face
    ok_r = r <= (1.0 + UNDEFORMED_TOL) * 0.5 * D0
    run = max(1, int(math.ceil(0.5 * D0 / w))) if w > 0 else 1
    X = 0.0
    for k in range(len(z)):
        if ok_r[k:k + run].all() and k + run <= len(z):
            X = top - (z[k] - 0.5 * w) if k else Lf
            break
    zW = face + W_AT * L0
    W = 2.0 * float(np.interp(zW, z, r)) if z[0] <= zW <= z[-1] else float("nan")
    return {"Lf": float(Lf), "X": float(min(X, Lf)), "Df": 2.0 * float(r.max()), "W": W}


def taylor_yield(rho0, V, L0, Lf, X):
    """Taylor's one-dimensional yield estimate (ASE units in, ASE pressure out).

    .. math::  Y = \\frac{\\rho_0 V^2 (L_0 - X)}{2 (L_0 - L_f) \\ln(L_0/X)}

    NaN when the rod did not shorten (Lf >= L0) or X is not in (0, L0).
    """
    if not (Lf < L0 and 0.0 < X < L0):
        return float("nan")
    return float(rho0 * V ** 2 * (L0 - X) / (2.0 * (L0 - Lf) * math.log(L0 / X)))


def outline_deviation(z, r, z_exp, r_exp, D0):
    """Mean of ``|r(z) - r_exp(z)|`` over the experimental outline's points, over ``D0/2``.

    ``r`` is interpolated at ``z_exp``; beyond the ends of the computed
    outline it is 0 (no material there), so a rod that came out too short
    pays for the missing length.
    """
    z = np.asarray(z, float)
    r = np.asarray(r, float)
    ok = np.isfinite(r)
    z, r = z[ok], r[ok]
    ze = np.asarray(z_exp, float)
    re = np.asarray(r_exp, float)
    rc = np.interp(ze, z, r, left=0.0, right=0.0)
    inside = (ze >= z[0] - 1e-9) & (ze <= z[-1] + 1e-9)
    rc = np.where(inside, rc, 0.0)
    return float(np.mean(np.abs(rc - re)) / (0.5 * D0))


# ----------------------------------------------------------------------------- plates and clouds
def hole_diameter(points, center, cell, *, extent=None):
    """Equal-area diameter of the perforation around ``center`` in a set of points on a plane.

    Parameters
    ----------
    points : (N, 2) float, Angstrom
        The plate's clusters projected on its plane.
    center : (2,) float
        The impact point on the plane.
    cell : float
        Mesh size (a cluster size r0 is the natural choice), Angstrom.
    extent : (2, 2) float, optional
        ``[[lo0, hi0], [lo1, hi1]]`` of the mesh (default: the points' extent).

    Returns
    -------
    dict
        ``d`` (diameter of the circle of the hole's area, Angstrom; 0 when
        the cell at ``center`` holds a point; NaN when the empty region
        reaches the mesh's edge, i.e. the plate is cut through to its rim),
        ``area`` (Angstrom^2), ``cells`` (number of empty cells), ``mask``
        (the hole's cells, bool (n0, n1)), ``edges`` (two arrays of mesh edges).
    """
    from scipy import ndimage
    p = np.asarray(points, dtype=float)
    check_positive("cell", cell)
    if extent is None:
        if len(p) == 0:
            raise InputError("points", "empty", "the plate's projected clusters (or an extent)")
        extent = [[p[:, 0].min(), p[:, 0].max()], [p[:, 1].min(), p[:, 1].max()]]
    ext = np.asarray(extent, dtype=float)
    n = np.maximum(1, np.ceil((ext[:, 1] - ext[:, 0]) / cell).astype(np.int64))
    e0 = ext[0, 0] + cell * np.arange(n[0] + 1)
    e1 = ext[1, 0] + cell * np.arange(n[1] + 1)
    occ = np.zeros(n, bool)
    if len(p):
        i = np.floor((p[:, 0] - ext[0, 0]) / cell).astype(np.int64)
        j = np.floor((p[:, 1] - ext[1, 0]) / cell).astype(np.int64)
        ok = (i >= 0) & (i < n[0]) & (j >= 0) & (j < n[1])
        occ[i[ok], j[ok]] = True
    ci = int(math.floor((center[0] - ext[0, 0]) / cell))
    cj = int(math.floor((center[1] - ext[1, 0]) / cell))
    empty_mask = np.zeros(n, bool)
    out = {"d": 0.0, "area": 0.0, "cells": 0, "mask": empty_mask, "edges": (e0, e1)}
    if not (0 <= ci < n[0] and 0 <= cj < n[1]):
        raise InputError("center", list(center), "a point inside the mesh")
    if occ[ci, cj]:
        return out
    lab, _ = ndimage.label(~occ)
    mask = lab == lab[ci, cj]
    cells = int(mask.sum())
    area = cells * cell * cell
    edge = mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()
    out.update(d=float("nan") if edge else 2.0 * math.sqrt(area / math.pi), area=float(area), cells=cells,
               mask=mask)
    return out


def plate_hole(positions, axis, lo, hi, center, cell, extent):
    """The perforation of a plate: :func:`hole_diameter` of the points between ``lo`` and ``hi``
    along ``axis`` (the plate's slab), projected on the plane of the two other axes.

    ``center`` (2,) and ``extent`` (2, 2) are in the plane's coordinates (the
    two other axes in increasing order), Angstrom.  A slab that holds a
    through-channel gives the channel's narrowest cross-section (the
    projection of every layer of the slab).
    """
    p = np.asarray(positions, dtype=float)
    z = p[:, axis]
    sel = (z >= lo) & (z <= hi)
    return hole_diameter(p[sel][:, _lateral(axis)], center, cell, extent=extent)


def cone_half_angle(vectors, masses, direction, fraction=0.9):
    """Half-angle about ``direction`` of the cone holding ``fraction`` of the mass (radians).

    ``vectors`` (N, 3) point from the cone's apex to each particle (or are
    velocities); the answer is the mass-weighted ``fraction`` quantile of
    their angles to ``direction``.  NaN for no particles.
    """
    v = np.asarray(vectors, dtype=float)
    m = np.asarray(masses, dtype=float)
    if len(v) == 0:
        return float("nan")
    if not 0.0 < fraction <= 1.0:
        raise InputError("fraction", fraction, "a fraction in (0, 1]")
    n = np.asarray(direction, dtype=float)
    n = n / np.linalg.norm(n)
    norm = np.linalg.norm(v, axis=1)
    ok = norm > 0
    ang = np.arccos(np.clip((v[ok] @ n) / norm[ok], -1.0, 1.0))
    w = m[ok]
    order = np.argsort(ang)
    cum = np.cumsum(w[order]) / w.sum()
    k = int(np.searchsorted(cum, fraction - 1e-12))
    return float(ang[order][min(k, len(ang) - 1)])


def projected_density(positions, masses, axes, extent, bins):
    """Mass per unit area projected on the plane of two ``axes`` (a radiograph's view).

    Parameters
    ----------
    positions : (N, 3) float, Angstrom
    masses : (N,) float, amu
    axes : (2,) int
        The image's horizontal and vertical axes (the third is summed over).
    extent : (2, 2) float
        ``[[lo_h, hi_h], [lo_v, hi_v]]``, Angstrom.
    bins : (2,) int
        Pixels along each axis.

    Returns
    -------
    (image, edges_h, edges_v)
        ``image`` (bins_h, bins_v) in amu/Angstrom^2.
    """
    p = np.asarray(positions, dtype=float)
    ext = np.asarray(extent, dtype=float)
    H, eh, ev = np.histogram2d(p[:, axes[0]], p[:, axes[1]], bins=bins, range=ext,
                               weights=np.asarray(masses, dtype=float))
    return H / ((eh[1] - eh[0]) * (ev[1] - ev[0])), eh, ev


# ----------------------------------------------------------------------------- Taylor data
def _data(name):
    return resources.files("clusterdyn") / "data" / name


def _num(x):
    x = x.strip()
    return float(x) if x else None


def taylor_test_label(t):
    """A Taylor test's short name: 'WG 373/L23' (Wilkins-Guinan, speed, length) or 'G358' (Gust)."""
    if t["source"].startswith("Gust"):
        return f"G{t['V_m_s']:g}"
    return f"WG {t['V_m_s']:g}/L{round(t['L0_mm']):d}"


def taylor_tests():
    """The Taylor tests of aluminium 6061-T6 (``clusterdyn/data/taylor_6061t6.csv``).

    Returns
    -------
    list of dict
        One per test: ``source``, ``T0_K``, ``rho0_kg_m3``, ``D0_mm``,
        ``L0_mm``, ``V_m_s``, ``Lf_mm``, ``X_mm``, ``Df_mm``, ``W_mm`` (None
        where not measured) and ``name`` (the key of its outline in
        ``taylor_6061t6_outlines.csv`` when there is one, else a name of the
        same form).
    """
    with _data("taylor_6061t6.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    names = set(_outlines())
    out = []
    for r in rows:
        d = {"source": r["source"]}
        for k in ("T0_K", "rho0_kg_m3", "D0_mm", "L0_mm", "V_m_s", "Lf_mm", "X_mm", "Df_mm", "W_mm"):
            d[k] = _num(r[k])
        by_length = f"{d['source']}_V{d['V_m_s']:g}_L{d['L0_mm']:g}"
        by_temp = f"{d['source']}_V{d['V_m_s']:g}_{d['T0_K']:g}K"
        d["name"] = by_temp if by_temp in names else by_length
        d["has_outline"] = d["name"] in names
        out.append(d)
    return out


def _outlines():
    with _data("taylor_6061t6_outlines.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    out = {}
    for r in rows:
        out.setdefault(r["test"], []).append((float(r["z_mm"]), float(r["r_mm"])))
    return out


def taylor_outline(name):
    """The digitised final outline of a test: ``(z, r)`` arrays in Angstrom, z from the impact face,
    sorted by z; None if the test has no outline."""
    rows = _outlines().get(name)
    if rows is None:
        return None
    a = np.array(sorted(rows))
    return a[:, 0] * units.mm, a[:, 1] * units.mm


def find_taylor_test(L0, D0, V, rtol=0.005):
    """The room-temperature test with this ``L0``, ``D0`` and ``V`` (ASE units) within ``rtol``, or None."""
    for t in taylor_tests():
        if t["T0_K"] is not None and t["T0_K"] > ROOM_TEMPERATURE_K:
            continue
        if (abs(t["L0_mm"] * units.mm - L0) <= rtol * L0 and abs(t["D0_mm"] * units.mm - D0) <= rtol * D0
                and abs(t["V_m_s"] * units.m_s - V) <= rtol * V):
            return t
    return None
