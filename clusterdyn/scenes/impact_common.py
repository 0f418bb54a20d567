"""Pieces shared by the impact scenes (``taylor``, ``hypervelocity``, ``multilayer``).

The energy ledger as quantities, radiograph images (PNG + CSV), the time-step
retry after a stiffness stop, and the damping default every impact scene
states:

**Damping default J = 50** (Gamma = c0/(50 r0), CD eq. 6).  Impact scenes have
free surfaces that shocks and release waves reach, and they count fragments:
without the pair damping, anharmonic high-frequency modes eject single
clusters from a free surface ("numerical dusting"), which would add false
fragments and stray debris; the CD paper shows Gamma = c0/(50 a) removes it
while leaving shock and release unchanged.  The price is a shock speed a few
per cent low at high u (2.3% at 3 km/s, 4-6% at 6 km/s in aluminium).  The
damping acts only between clusters within the cutoff, so free-flying
fragments keep their speed.  ``--set J=none`` runs undamped.
"""

import csv

import numpy as np

from .. import units
from ..analysis.impact import projected_density
from ..md.wall import Wall
from .base import Param, Quantity
from .common import matplotlib_agg

#: the impact scenes' damping default (module docstring)
IMPACT_J = 50.0


def projectile_params(dt_factor, dt_help):
    """The parameters a sphere-on-target scene shares: damping, cutoff, seed (the sphere's lattice
    orientation and the noise), noise, the time step ``dt_factor`` (default and help text given)
    and its retries."""
    return [
        Param("J", IMPACT_J, "damping Gamma = c0/(J r0); none = off (default 50: free surfaces, fragments)",
              low=0.0, low_open=True, optional=True),
        Param("rc", 1.15, "cutoff as a multiple of r0", low=1.0, high=1.414, low_open=True),
        Param("seed", 1, "random seed: the sphere's lattice orientation and the initial noise", kind="int", low=0),
        Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
        Param("dt_factor", dt_factor, dt_help, low=0.0, high=0.5, low_open=True),
        Param("dt_retries", 2, "times the run starts again with half the time step after a stiffness stop",
              kind="int", low=0),
    ]


def lateral_axes(ax):
    """The two axes across ``ax`` (0, 1 or 2), in order."""
    return [d for d in range(3) if d != ax]


def ledger(dyn):
    """The dynamics' energy ledger in joules (plain floats, encodable)."""
    led = dyn.energy_ledger()
    walls = [c for c in dyn.atoms.constraints if isinstance(c, Wall)]
    out = {k: float(led[k]) / units.J for k in ("kinetic0", "potential0", "kinetic", "potential", "damping_loss",
                                                 "wall_dissipated", "drive_work", "residual")}
    out["wall_work"] = float(sum(w.work for w in walls)) / units.J
    out["removed"] = float(led["removed_kinetic"] + led["removed_potential"]) / units.J
    out["removed_count"] = int(dyn.removed["count"])
    return out


def ledger_quantities(led):
    """Quantities (J) and one note line of a :func:`ledger` dict."""
    e0 = led["kinetic0"] if led["kinetic0"] > 0 else 1.0
    q = {
        "E_kinetic_initial": Quantity(led["kinetic0"], "J", note="kinetic energy at the start"),
        "E_kinetic": Quantity(led["kinetic"], "J", note="kinetic energy at the end"),
        "E_potential_change": Quantity(led["potential"] - led["potential0"], "J",
                                       note="pair (and wall) potential energy, end minus start"),
        "E_damping_loss": Quantity(led["damping_loss"], "J", note="energy removed by the pair damping"),
        "E_wall_work": Quantity(led["wall_work"], "J", note="work of the walls (a fixed wall does none)"),
        "E_wall_dissipated": Quantity(led["wall_dissipated"], "J", note="kinetic energy a sticking wall removed"),
        "E_residual": Quantity(led["residual"], "J", note="energy not accounted for (integration error)"),
    }
    removed = ""
    if led.get("removed_count", 0):
        q["E_removed"] = Quantity(led["removed"], "J", note=f"kinetic and pair energy of the {led['removed_count']} "
                                  "clusters removed outside the region of interest")
        removed = f", removed {led['removed']:.4g} ({led['removed_count']} clusters)"
    note = (f"energy ledger (J): kinetic {led['kinetic0']:.4g} -> {led['kinetic']:.4g}, potential change "
            f"{led['potential'] - led['potential0']:+.4g}, damping loss {led['damping_loss']:.4g}, wall work "
            f"{led['wall_work']:.3g}, wall dissipated {led['wall_dissipated']:.4g}{removed}, residual "
            f"{led['residual']:+.3g} ({100 * led['residual'] / e0:+.3f}% of the initial kinetic energy)")
    return q, note


def radiograph(positions, masses, axes, extent, pixel):
    """Projected density (kg/m^2) on the plane of ``axes`` with square pixels of ``pixel`` Angstrom.

    Returns ``(image, edges_h, edges_v)`` as float32/float64 arrays (encodable)."""
    ext = np.asarray(extent, dtype=float)
    bins = np.maximum(1, np.round((ext[:, 1] - ext[:, 0]) / pixel).astype(int))
    img, eh, ev = projected_density(positions, masses, axes, ext, bins)
    return (img / (units.kg / units.m ** 2)).astype(np.float32), eh, ev


def radiograph_frame(positions, masses, axis, lateral, radius, r0, t, pixels=(300, 500)):
    """A radiograph frame dict (``t``, ``image``, ``edges_h``, ``edges_v``) of the plane of ``lateral``
    (horizontal) and ``axis`` (vertical), framing the body of ``radius`` and 99.9% of the particles."""
    pos = np.asarray(positions)
    half = max(radius, float(np.quantile(np.abs(pos[:, lateral]), 0.999))) + 2 * r0
    z = pos[:, axis]
    ext = [[-half, half], [float(np.quantile(z, 0.0005)) - 2 * r0, float(np.quantile(z, 0.9995)) + 2 * r0]]
    pixel = max(r0, 2 * half / pixels[0], (ext[1][1] - ext[1][0]) / pixels[1])
    img, eh, ev = radiograph(pos, masses, (lateral, axis), ext, pixel)
    return {"t": float(t), "image": img, "edges_h": eh, "edges_v": ev}


def write_radiographs(frames, png, csv_path, labels=("x", "z"), title=""):
    """Radiograph panels (one per time) as a PNG and the images behind it as CSV.

    ``frames``: list of dicts with ``t`` (ASE time), ``image`` (kg/m^2),
    ``edges_h``, ``edges_v`` (Angstrom).  The PNG shows log10 of the areal
    density (grey: dark = dense, as on a film); the CSV has one row per
    non-empty pixel: time (us), pixel centre (mm) and areal density (kg/m^2).
    """
    plt = matplotlib_agg()
    n = len(frames)
    fig, axs = plt.subplots(1, n, figsize=(3.2 * n + 0.6, 4.2), squeeze=False)
    vmax = max((float(np.max(f["image"])) for f in frames), default=1.0) or 1.0
    for ax, f in zip(axs[0], frames):
        img = np.asarray(f["image"], dtype=float)
        eh, ev = np.asarray(f["edges_h"]) / units.mm, np.asarray(f["edges_v"]) / units.mm
        with np.errstate(divide="ignore"):
            lg = np.log10(np.where(img > 0, img, np.nan))
        im = ax.imshow(lg.T, origin="lower", extent=[eh[0], eh[-1], ev[0], ev[-1]], cmap="gray_r",
                       vmin=np.log10(vmax) - 3.0, vmax=np.log10(vmax), aspect="equal")
        ax.set_title(f"t = {f['t'] / units.us:.3g} us")
        ax.set_xlabel(f"{labels[0]} (mm)")
        ax.set_ylabel(f"{labels[1]} (mm)")
    fig.colorbar(im, ax=list(axs[0]), shrink=0.8, label="log10 areal density (kg/m^2)")
    if title:
        fig.suptitle(title)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_us", f"{labels[0]}_mm", f"{labels[1]}_mm", "areal_density_kg_m2"])
        for f in frames:
            img = np.asarray(f["image"])
            eh, ev = np.asarray(f["edges_h"]), np.asarray(f["edges_v"])
            ch = 0.5 * (eh[1:] + eh[:-1]) / units.mm
            cv = 0.5 * (ev[1:] + ev[:-1]) / units.mm
            ii, jj = np.nonzero(img > 0)
            tt = f"{f['t'] / units.us:.6g}"
            for i, j in zip(ii, jj):
                w.writerow([tt, f"{ch[i]:.5g}", f"{cv[j]:.5g}", f"{img[i, j]:.5g}"])
    return [png, csv_path]


def retry_halved_dt(v, exc, attempt, key="dt_factor", retries_key="dt_retries"):
    """Parameters for another attempt with half the time step after a stiffness stop, or None."""
    if getattr(exc, "quantity", None) not in ("timestep", "displacement per step / r0") \
            or attempt > v.get(retries_key, 0):
        return None
    note = (f"dt factor {v[key]:g}: stopped at step {exc.step} ({exc.quantity} {exc.value:.4g} > limit "
            f"{exc.limit:.4g})")
    return v.replace(**{key: 0.5 * v[key]}, retried=v.retried + (note,))


def parse_times(text, name, default):
    """Times in us from ``"auto"`` (-> ``default``, a list of ASE times) or ``"1,2.5,10"``."""
    from ..errors import InputError
    if str(text).strip().lower() == "auto":
        return list(default)
    try:
        ts = [float(s) * units.us for s in str(text).split(",") if s.strip()]
    except ValueError:
        raise InputError(name, text, "auto or times in us like 2,5,10") from None
    if not ts or any(t < 0 for t in ts):
        raise InputError(name, text, "auto or non-negative times in us like 2,5,10")
    return sorted(ts)


#: particle-steps per second assumed for the run-time estimate of :func:`announce_cost` (2 cores,
#: damped CD in an open box; measured 0.6-1.2e7 on the impact scenes' study runs)
THROUGHPUT = 8.0e6
#: runs estimated longer than this (s) are announced before they start
ANNOUNCE_S = 180.0


def announce_cost(scene, n, nsteps):
    """Warn (logging, on stderr) before a run estimated to take more than a few minutes."""
    est = n * nsteps / THROUGHPUT
    if est > ANNOUNCE_S:
        import logging
        logging.getLogger("clusterdyn").warning(
            "%s: %d clusters x up to %d steps: about %.0f min of stepping on 2 cores (a study-size run)",
            scene, n, nsteps, est / 60.0)
    return est
