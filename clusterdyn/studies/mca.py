"""MCA studies: the packing-independent elasticity table, its Cluster Dynamics contrast, the
degrading unload-reload cycle.

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
:mod:`clusterdyn.analysis.mca_elastic`, the CD contrast
:func:`clusterdyn.analysis.elastic.cd_elastic_constants`; the cycle is
:func:`clusterdyn.scenes.mca_material_point.degrading_cycle`.
"""

import csv
import sys
import time
from pathlib import Path

from .. import units
from ..analysis.elastic import cd_elastic_constants
from ..analysis.mca_elastic import elastic_case, relative_errors
from ..scenes.base import Param
from ..scenes.mca_material_point import degrading_cycle
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
