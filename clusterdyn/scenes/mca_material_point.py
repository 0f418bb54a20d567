"""MCA material-point tests: a cylinder between frictionless platens to large strain
(:func:`compression_flow`), and the load / unload / reload cycle of a degrading bar
(:func:`degrading_cycle`).

**Compression between platens** (docs/mca.md, "Large strain"; ``clusterdyn study
mca-compression-flow`` sweeps it).
A cylinder of ``across`` automata across its diameter D0 and the same height
(fcc, Johnson-Cook 6061-T6 by default) is squeezed along z by its two end
layers, driven as frictionless platens (:class:`~clusterdyn.md.Piston`,
``lateral="free"``: each automaton of a platen layer keeps its own lateral
velocity).  The platens approach at ``U = edot H(t) / 2`` each, ``H`` the
distance of the platen layers, so the true strain rate is ``edot`` after a
smooth start (half cosine over ``ramp`` of the run), to ``strain`` (0.6
engineering = 0.92 true).  The run uses the large-strain switching of
:class:`~clusterdyn.mca.MCADynamics` (``remesh_strain``).

Measured (every ``samples``-th of the run): true strain ``ln(H0/H)``; axial
true stress ``F H / V0`` (F the mean of the two platens' recorded forces; exact
for an isochoric body, the volume change is measured separately); the
volume from the model's own cells at each re-tessellation; plastic strain
``e_p = e_true - sigma/E``; the input curve ``(A + B e_p^n)(1 + C ln(edot/eps0))``
at the measured rate; the energy ledger (:meth:`MCADynamics.ledger`) with the
platens' work as the work in; the total momentum.

**The degrading cycle** (``clusterdyn study mca-degrading``): a bar in tension (the
:func:`clusterdyn.scenes.mca_experiments.uniaxial` test) whose grips follow
:func:`load_unload_reload`: load, unload to zero strain, reload; the initial, unloading and
reloading moduli are fitted on the windows :data:`FIT_WINDOWS`.
"""

import csv
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from .. import units
from ..build.mca import mca_packing
from ..build.shapes import Cylinder
from ..errors import InputError
from ..materials import get_material
from ..mca import MCA, MCADynamics
from ..mca.dynamics import default_timestep, wave_speeds
from ..mca.response.plastic import jc_flow_stress
from ..md import Piston, Table
from .common import matplotlib_agg
from .mca_experiments import uniaxial


# --------------------------------------------------------------------------- compression between platens
def _table(times, values):
    return Table(times, values)


def _hull_volume(pos):
    return float(ConvexHull(pos).volume)


def compression_flow(across=6, material="Al6061-T6", strain=0.6, transits=40.0, damping=0.05,
                     remesh_strain=0.1, D0=6.0 * units.mm, samples=120, courant=None, stream=None, ramp=0.05,
                     inherit="automata"):
    """Run one compression; returns a dict of arrays and summary numbers (module docstring).

    ``ramp``: the platens' start, the fraction of the run over which their speed rises (half
    cosine); ``inherit``: what a linked pair that survives a switch starts from
    (:meth:`clusterdyn.mca.state.MCAState.retessellate`)."""
    if not 0.0 < ramp < 0.5:
        raise InputError("ramp", ramp, "a fraction of the run in (0, 0.5)")
    if not (isinstance(across, (int, np.integer)) and across >= 4):
        raise InputError("across", across, "an integer number of automata >= 4")
    if not 0.0 < strain < 0.8:
        raise InputError("strain", strain, "an engineering strain in (0, 0.8)")
    mat = get_material(material)
    jc = mat.extra.get("johnson_cook")
    if jc is None:
        raise InputError("material", mat.name, "a material with a Johnson-Cook record (e.g. Al6061-T6)")
    t_start = time.perf_counter()
    d = D0 / across
    cyl = Cylinder(center=(0.5 * D0 + d, 0.5 * D0 + d, 0.0), radius=0.5 * D0, length=D0, axis=2)
    atoms = mca_packing(mat, d, cyl, "fcc")
    z = atoms.positions[:, 2]
    lay = 0.25 * d
    lo = np.nonzero(z < z.min() + lay)[0]
    hi = np.nonzero(z > z.max() - lay)[0]
    H0 = float(z.max() - z.min())
    cl = wave_speeds(mat)[0]
    dt = default_timestep(atoms) if courant is None else default_timestep(atoms, courant=courant)
    eps_end = -math.log(1.0 - strain)
    T = transits * H0 / cl
    ramp = ramp * T
    edot = eps_end / (T - 0.5 * ramp)
    t = np.linspace(0.0, T, 4001)
    rate = np.where(t < ramp, 0.5 * edot * (1 - np.cos(np.pi * t / ramp)), edot)
    eps = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))])
    U = 0.5 * rate * H0 * np.exp(-eps)
    atoms.calc = MCA()
    top = Piston(hi, _table(t, -U), direction=(0, 0, 1), lateral="free")
    bot = Piston(lo, _table(t, U), direction=(0, 0, 1), lateral="free")
    atoms.set_constraint([bot, top])
    dyn = MCADynamics(atoms, dt, damping=damping, remesh_strain=remesh_strain)
    st = dyn.state
    st.set_inherit(inherit)
    V0 = float(st.omega_n.sum())
    Vi0 = st.interior_volume[0]
    layers = np.concatenate([lo, hi])
    m_l = atoms.get_masses()[layers]

    def layer_ke():        # the platens' own kinetic energy along z (their work beyond the recorded one)
        return 0.5 * float(np.sum(m_l * atoms.get_velocities()[layers, 2] ** 2))

    ke_l0 = layer_ke()
    hull0 = _hull_volume(atoms.positions)
    nsteps = int(math.ceil(T / dt))
    every = max(1, nsteps // samples)
    rows = []
    m = atoms.get_masses()
    p_scale = float(np.sum(m) * np.max(U))
    last_vol = (0, V0, Vi0)
    for k in range(0, nsteps + 1, every):
        if k:
            dyn.run(min(every, nsteps - (k - every)) if k > nsteps else every)
        zz = atoms.positions[:, 2]
        H = float(zz[hi].mean() - zz[lo].mean())
        F = 0.5 * (top.force[2] - bot.force[2])      # compressive force (positive)
        led = dyn.ledger(external_work=top.work + bot.work + layer_ke() - ke_l0)
        P = atoms.get_momenta().sum(axis=0)
        if dyn.remesh_log and dyn.remesh_log[-1]["step"] != last_vol[0]:
            last_vol = (dyn.remesh_log[-1]["step"], float(st.omega_n.sum()), st.interior_volume[0])
        rows.append({"step": st.step, "time": st.time, "H": H, "F": F, "V_cells": last_vol[1], "V_interior": last_vol[2],
                     "hull": _hull_volume(atoms.positions) / hull0 - 1.0, "p_z": float(P[2]), "p_xy": float(np.hypot(P[0], P[1])), **led,
                     "remeshes": dyn.remesh_count, "stored": dyn.stored_work})
        if stream and len(rows) % 10 == 0:
            print(f"  across {across}: step {st.step}/{nsteps}, e_true {math.log(H0 / H):.3f}, "
                  f"remeshes {dyn.remesh_count}", file=stream, flush=True)
        if k >= nsteps:
            break
    H = np.array([r["H"] for r in rows])
    F = np.array([r["F"] for r in rows])
    e_true = np.log(H0 / H)
    vol = np.array([r["V_interior"] for r in rows]) / Vi0 - 1.0       # the interior's density
    vol_cells = np.array([r["V_cells"] for r in rows]) / V0 - 1.0     # every cell, surface closure included
    sig = F * H / (V0 * (1.0 + vol))           # F / A, A = V / H
    ep = np.maximum(e_true - sig / mat.E, 0.0)
    target = jc_flow_stress(jc, ep, edot * units.s)
    res = {"across": across, "n": len(atoms), "steps": nsteps, "dt": dt, "edot_per_s": edot * units.s,
           "e_true": e_true, "stress": sig, "e_p": ep, "target": target, "volume_change": vol, "volume_change_cells": vol_cells,
           "rows": rows, "dyn": dyn, "atoms": atoms, "material": mat, "p_scale": p_scale,
           "seconds": time.perf_counter() - t_start}
    w = (e_true >= 0.01) & (e_true <= e_true.max())
    res["max_error"] = float(np.max(np.abs(sig[w] / target[w] - 1))) if w.any() else float("nan")
    res["rms_error"] = float(np.sqrt(np.mean((sig[w] / target[w] - 1) ** 2))) if w.any() else float("nan")
    res["mean_error"] = float(np.mean(sig[w] / target[w] - 1)) if w.any() else float("nan")
    plastic = e_true > 0.02
    res["max_volume_change"] = float(np.max(np.abs(vol[plastic]))) if plastic.any() else 0.0
    res["momentum_rel"] = float(max(r["p_xy"] for r in rows) / p_scale)
    last = rows[-1]
    res["ledger"] = {k: last[k] for k in ("kinetic", "rotational", "elastic", "plastic", "damping",
                                          "switching", "splitting", "volume", "wall", "work_in", "initial", "residual")}
    res["ledger_residual_rel"] = float(abs(last["residual"]) / max(last["plastic"], 1e-300))
    res["remeshes"] = dyn.remesh_count
    return res


# --------------------------------------------------------------------------- the degrading cycle
def load_unload_reload(s):
    """Load fraction s in [0, 1] -> strain / strain_max: load, unload to zero strain, reload."""
    if s < 0.4:
        return s / 0.4
    if s < 0.6:
        return 1 - (s - 0.4) / 0.2
    return (s - 0.6) / 0.4


#: load-fraction windows of the slope fits (away from the turning points)
FIT_WINDOWS = {"initial": (0.04, 0.22), "unloading": (0.43, 0.57), "reloading": (0.65, 0.95)}


def degrading_cycle(material="concrete", size=(16, 5, 5), steps=6000, peak=0.95, damping=0.1,
                    out=None, stream=sys.stdout):
    """Load / unload / reload cycle of a degrading material (bar in tension, fcc, d = 1 A).

    The grips follow :func:`load_unload_reload` to ``strain_max = peak sigma_t / E`` (load over
    the first 40% of the steps, unload to zero strain over 20%, reload over 40%).
    Slopes are fitted on the windows :data:`FIT_WINDOWS`; ``D_mean`` is the mean
    damage of the linked pairs in the middle half of the bar at the end.
    Writes ``degrading_cycle.csv`` and ``degrading_cycle.png`` in ``out``.

    Returns
    -------
    dict with ``strain``, ``stress`` (eV/Angstrom^3), ``s`` (load fraction), the
    fitted ``E_initial``, ``E_unloading``, ``E_reloading`` (eV/Angstrom^3), ``peak_stress``,
    ``stress_at_zero_strain`` (end of unloading), ``D_mean`` and the material.
    """
    mat = get_material(material)
    em = peak * mat.sigma_t / mat.E
    t0 = time.perf_counter()
    r = uniaxial(mat, "tension", size=size, strain_max=em, steps=steps, path=load_unload_reload, damping=damping)
    e, sg = r["strain"], r["stress"]
    s = r["time"] / (steps * r["dyn"].dt)
    fits = {}
    for name, (a, b) in FIT_WINDOWS.items():
        w = (s >= a) & (s <= b)
        fits[name] = np.polyfit(e[w], sg[w], 1)
    st = r["dyn"].state
    atoms = r["atoms"]
    i_p, j_p = st.pair_rows(atoms)[:2]
    x = atoms.positions[:, 0]
    lo, hi = np.percentile(x, 25), np.percentile(x, 75)
    gauge = (st.linked_p == 1) & (x[i_p] > lo) & (x[i_p] < hi) & (x[j_p] > lo) & (x[j_p] < hi)
    D_mean = float(st.D_p[gauge].mean())
    k0 = int(np.argmin(np.abs(s - 0.6)))
    res = {"material": mat, "strain": e, "stress": sg, "s": s, "strain_max": em,
           "E_initial": fits["initial"][0], "E_unloading": fits["unloading"][0],
           "E_reloading": fits["reloading"][0], "fits": fits, "peak_stress": sg.max(),
           "stress_at_zero_strain": sg[k0], "D_mean": D_mean, "seconds": time.perf_counter() - t0,
           "size": size, "steps": steps}
    g = units.GPa
    lines = [f"{mat.name}: E = {mat.E / g:.2f} GPa, sigma_t = {mat.sigma_t / units.MPa:.3g} MPa; bar "
             f"{size[0]}x{size[1]}x{size[2]} d fcc, {steps} steps, strain_max = {em:.3g} "
             f"({peak:g} sigma_t/E), damping {damping:g}",
             f"initial modulus    {res['E_initial'] / g:8.3f} GPa  = {res['E_initial'] / mat.E:.3f} E",
             f"unloading modulus  {res['E_unloading'] / g:8.3f} GPa  = {res['E_unloading'] / mat.E:.3f} E",
             f"reloading modulus  {res['E_reloading'] / g:8.3f} GPa  = {res['E_reloading'] / mat.E:.3f} E",
             f"peak stress {res['peak_stress'] / mat.sigma_t:.3f} sigma_t; at zero strain after unloading "
             f"{res['stress_at_zero_strain'] / mat.sigma_t:+.3f} sigma_t; mean damage of gauge pairs "
             f"D = {D_mean:.3f} (1 - D = {1 - D_mean:.3f}); {res['seconds']:.1f} s"]
    if stream is not None:
        print("\n".join(lines), file=stream)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        phase = np.where(s < 0.4, "load", np.where(s < 0.6, "unload", "reload"))
        with open(out / "degrading_cycle.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["load_fraction", "strain", "stress_GPa", "stress_over_sigma_t", "phase"])
            for row in zip(s, e, sg / g, sg / mat.sigma_t, phase):
                w.writerow(row)
        (out / "degrading_cycle.txt").write_text("\n".join(lines) + "\n")
        res["png"] = _plot_cycle(res, out / "degrading_cycle.png")
    return res


def _plot_cycle(res, path):
    plt = matplotlib_agg()
    mat, e, sg, s = res["material"], res["strain"], res["stress"], res["s"]
    st = mat.sigma_t
    g = units.GPa
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    for (a, b), lab, c in (((0, 0.4), "load", "C0"), ((0.4, 0.6), "unload", "C3"), ((0.6, 1.01), "reload", "C2")):
        w = (s >= a - 1e-9) & (s <= b)
        ax.plot(e[w] * 1e4, sg[w] / st, color=c, lw=1.6, label=lab)
    x = np.linspace(0.0, res["strain_max"], 2)
    for name, ls in (("initial", "--"), ("unloading", ":")):
        m, c0 = res["fits"][name]
        E = res[f"E_{name}"]
        ax.plot(x * 1e4, (m * x + c0) / st, "k" + ls, lw=1.0,
                label=f"{name} fit: {E / g:.1f} GPa = {E / mat.E:.2f} E")
    # damage onset in uniaxial tension: Drucker-Prager sigma_eq = beta sigma = sigma_d
    onset = mat.extra.get("sigma_d", 0.7 * mat.sigma_c) * mat.sigma_t / mat.sigma_c
    ax.axhline(onset / st, color="0.6", lw=0.8, ls="-.", label="damage onset (sigma_d / beta)")
    ax.set_xlabel("strain (1e-4)")
    ax.set_ylabel("stress / sigma_t")
    ax.set_title(f"{mat.name}: load, unload to zero strain, reload")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)
