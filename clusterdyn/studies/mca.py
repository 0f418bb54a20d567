"""MCA studies: the packing-independent elasticity table, its Cluster Dynamics contrast, the
degrading unload-reload cycle (and helpers the tests reuse).

    clusterdyn study mca-elasticity [--set size=L] [--out DIR]
    clusterdyn study mca-degrading [--set steps=N] [--out DIR]

``elasticity`` prints the table of Young's modulus, Poisson ratio, bulk and
shear modulus measured on fcc, hcp, simple cubic and random packings for
nu in {0, 0.15, 0.25, 0.35, 0.45} against the input, then the same test on a
Cluster Dynamics fcc packing of aluminium along [100] and [111] against the
nearest-neighbour central-force values (docs/theory.md 1.5), and writes both as
CSV and Markdown under ``DIR`` (default ``runs/mca-elasticity-size5``).  ``degrading`` runs a
load / unload / reload cycle of concrete and writes the curve (CSV, PNG) with
the fitted initial and unloading moduli.

The measurements are analysis: the MCA static tests are
:mod:`clusterdyn.analysis.mca_elastic`, the CD contrast :func:`clusterdyn.analysis.elastic.cd_elastic_constants`.
"""

import csv
import sys
import time
from pathlib import Path

import numpy as np

from .. import units
from ..analysis.elastic import cd_elastic_constants
from ..analysis.mca_elastic import elastic_case, relative_errors
from ..scenes.base import Param
from .base import Report, Study, register_study

PACKINGS = ("fcc", "hcp", "sc", "random")
NUS = (0.0, 0.15, 0.25, 0.35, 0.45)


def elasticity_table(nus=NUS, packings=PACKINGS, size=5.0, out=None, stream=sys.stdout):
    rows = []
    t0 = time.perf_counter()
    for nu in nus:
        for pk in packings:
            row = elastic_case(nu, pk, size=size)
            row.update({f"err_{k}": v for k, v in relative_errors(row).items()})
            rows.append(row)
    g = units.GPa
    head = ("| packing | nu in | E (GPa) | err E | nu | err nu | K (GPa) | err K | G (GPa) | err G |\n"
            "|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        lines.append(f"| {r['packing']} | {r['nu_in']:.2f} | {r['E'] / g:.2f} | {100 * r['err_E']:+.2f}% | "
                     f"{r['nu']:.4f} | {('%+.4f' % r['err_nu']) if r['nu_in'] == 0 else ('%+.2f%%' % (100 * r['err_nu']))} | "
                     f"{r['K'] / g:.2f} | {100 * r['err_K']:+.2f}% | {r['G'] / g:.2f} | {100 * r['err_G']:+.2f}% |")
    text = "\n".join(lines)
    if stream is not None:
        print(text, file=stream)
        print(f"(input E = 100 GPa; err nu absolute for nu = 0; {time.perf_counter() - t0:.1f} s)",
              file=stream)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "elasticity.md").write_text(text + "\n")
        with open(out / "elasticity.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            keys = ["packing", "nu_in", "E", "nu", "K", "G", "err_E", "err_nu", "err_K", "err_G"]
            w.writerow([k + ("_GPa" if k in "EKG" else "") for k in keys])
            for r in rows:
                w.writerow([r[k] / g if k in ("E", "K", "G") else r[k] for k in keys])
    return rows


# -- Cluster Dynamics contrast: the same test on a pair-potential fcc packing ------------------

CD_KEYS = ("C11", "C12", "C44", "B", "E", "nu_xy", "nu_xz")


def cd_contrast_table(material="Al", r0=5 * units.um, directions=((1, 0, 0), (1, 1, 1)), strain=1e-5,
                      out=None, stream=sys.stdout):
    """The CD contrast rows (measured and analytic) for each direction; Markdown and CSV in ``out``."""
    g = units.GPa
    rows = [cd_elastic_constants(material, r0, d, strain) for d in directions]

    def fmt(k, v):
        return f"{v:.4f}" if k.startswith("nu") else f"{v / g:.3f}"

    head = ("| CD " + str(rows[0]["material"]) + " fcc, x along | C11 (GPa) | C12 (GPa) | C44 (GPa) | "
            "B (GPa) | E_x (GPa) | nu_xy | nu_xz | largest rel. diff. |\n|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        an = r["analytic"]
        dev = max(abs(r[k] - an[k]) / abs(an[k]) for k in CD_KEYS)
        lines.append(f"| {r['direction']} measured | " + " | ".join(fmt(k, r[k]) for k in CD_KEYS)
                     + f" | {dev:.1e} |")
        lines.append(f"| {r['direction']} analytic | " + " | ".join(fmt(k, an[k]) for k in CD_KEYS) + " |  |")
    text = "\n".join(lines)
    if stream is not None:
        print(text, file=stream)
        print(f"(pair potential, r0 = {r0 / units.um:g} um, rc = 1.15 r0; analytic: C11 = 2k/a, "
              "C12 = C44 = k/a, k = -f'(r0), a = sqrt(2) r0, B = rho0 c0^2, E and nu from the "
              "rotated cubic tensor; strain +-%g)" % strain, file=stream)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        with open(out / "elasticity_cd.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["direction", "kind"] + [k + ("" if k.startswith("nu") else "_GPa") for k in CD_KEYS])
            for r in rows:
                for kind, src in (("measured", r), ("analytic", r["analytic"])):
                    w.writerow([r["direction"], kind] + [src[k] if k.startswith("nu") else src[k] / g
                                                         for k in CD_KEYS])
    return rows, text


# -- degrading response: load / unload / reload ---------------------------------------------

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
    from ..materials import get_material
    from ..scenes.mca_experiments import uniaxial

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
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
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


def _degrading_materials():
    from ..materials import get_material, material_names
    return tuple(n for n in material_names() if getattr(get_material(n), "response", None)
                 in ("degrading", "plastic-degrading"))


def _cd_materials():
    from ..materials import cd_material_names
    return tuple(cd_material_names())


ELASTICITY_PARAMS = [
    Param("size", 5.0, "box edge of the elasticity samples in automaton sizes", low=2.0),
    Param("material", "Al", "Cluster Dynamics material of the contrast", kind="choice", choices=_cd_materials()),
]
DEGRADING_PARAMS = [
    Param("material", "concrete", "degrading MCA material", kind="choice", choices=_degrading_materials()),
    Param("steps", 6000, "steps of the whole load-unload-reload cycle", kind="int", low=100),
    Param("peak", 0.95, "peak strain as a fraction of sigma_t/E", low=0.0, high=1.0, low_open=True),
    Param("damping", 0.1, "viscous damping of relative pair velocity", low=0.0),
]


class ElasticityStudy(Study):
    """``clusterdyn study mca-elasticity``: the packing-independence table and its CD contrast."""

    name = "mca-elasticity"
    summary = "MCA's packing-independent E, nu, K, G on fcc, hcp, sc and random packings, and the Cluster Dynamics contrast"
    params = ELASTICITY_PARAMS

    def tag(self, run):
        return f"size{run.v['size']:g}"

    def collect(self, run, plan):
        stream = None if run.quiet else sys.stdout
        rows = elasticity_table(size=run.v["size"], out=run.folder, stream=stream)
        cd_rows, cd_text = cd_contrast_table(material=run.v["material"], out=run.folder, stream=stream)
        return rows, cd_rows, cd_text

    def report(self, run, collected):
        rows, cd_rows, cd_text = collected
        md = run.folder / "elasticity.md"
        md.write_text(md.read_text() + "\nCluster Dynamics contrast (same test, pair potential):\n\n"
                      + cd_text + "\n")
        return Report({"study": "mca-elasticity", "rows": rows, "cd_rows": cd_rows}, files=[md])


class DegradingStudy(Study):
    """``clusterdyn study mca-degrading``: a load / unload / reload cycle of a degrading material."""

    name = "mca-degrading"
    summary = "a load / unload / reload cycle of a degrading MCA material"
    params = DEGRADING_PARAMS

    def tag(self, run):
        return run.v["material"]

    def collect(self, run, plan):
        v = run.v
        return degrading_cycle(v["material"], steps=v["steps"], peak=v["peak"], damping=v["damping"],
                               out=run.folder, stream=None if run.quiet else sys.stdout)

    def report(self, run, res):
        keep = ("E_initial", "E_unloading", "E_reloading", "peak_stress", "stress_at_zero_strain", "D_mean",
                "strain_max", "seconds")
        out_d = {k: res[k] for k in keep}
        out_d.update({"study": "mca-degrading", "material": res["material"].name})
        return Report(out_d, files=[run.folder / "degrading_cycle.csv", res["png"]])


elasticity_study = register_study(ElasticityStudy())
degrading_study = register_study(DegradingStudy())
