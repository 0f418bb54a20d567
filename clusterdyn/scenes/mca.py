"""MCA scenes: ``clusterdyn run mca-tension`` and ``clusterdyn run mca-compression``.

A brittle ceramic-like bar (default alumina: E 370 GPa, nu 0.22, sigma_t
0.3 GPa, sigma_c 2.5 GPa, Drucker-Prager beta = 8.33) of fcc automata
(d = 10 um, 16 x 5 x 5 d, ~400 automata) is pulled or pressed between two
grips whose velocity ramps up smoothly over the first 10% of the run, with 5%
of critical pair damping (quasi-static), 2% uniform scatter of the pair
strengths (seeded; it picks where the crack starts), friction coefficient of
unlinked pairs mu = 0.3.  Written: stress-strain curve (CSV + PNG), crack
pattern (PNG, automata coloured by broken-link count), H5MD with
per-automaton stress and link count when :class:`clusterdyn.io.H5MDWriter`
is available, and the result: ``peak_stress`` and ``strain_at_peak``, the
material strength with the relative error of the peak, and the wall time.
"""

import csv
import time

import numpy as np

from .. import units
from ..materials import get_material
from .base import Param, Quantity, SceneResult, register
from ..analysis.fragments import fragments
from .mca_experiments import broken_links, uniaxial

MATERIALS = ("alumina", "concrete")


def _params(mode):
    return [
        Param("material", "alumina", "brittle MCA material", kind="choice", choices=MATERIALS),
        Param("d", 10.0, "automaton size", unit="um", low=0.0, low_open=True),
        Param("size", (16, 5, 5), "bar length x width x height in automaton sizes", kind="ints", low=3),
        Param("packing", "fcc", "packing of the automata", kind="choice",
              choices=("fcc", "hcp", "sc", "random")),
        Param("steps", 3000, "time steps to the final strain (dt = 0.15 d / c_L)", kind="int", low=100),
        Param("strain_max", 2.5, "final strain as a multiple of strength/E", low=0.1, low_open=True),
        Param("damping", 0.05, "fraction of critical damping of relative pair velocity", low=0.0,
              high=1.0),
        Param("scatter", 0.02, "relative scatter of pair strengths (uniform, seeded)", low=0.0,
              high=0.5),
        Param("mu", 0.3, "Coulomb friction coefficient of unlinked pairs", low=0.0),
        Param("seed", 0, "random seed (strength scatter, random packing)", kind="int", low=0),
        Param("frames", 20, "H5MD frames", kind="int", low=1),
    ]


def run_uniaxial(mode, vals, out=None, progress=True):
    t0 = time.perf_counter()
    mat = get_material(vals["material"])
    mat = mat.replace(extra={**mat.extra, "mu": vals["mu"]})
    ref = mat.sigma_t if mode == "tension" else mat.sigma_c
    observers = []
    writer = None
    files = []
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    res = uniaxial(mat, mode, d=vals["d"], size=vals["size"], packing=vals["packing"],
                   strain_max=vals["strain_max"] * ref / mat.E, steps=vals["steps"],
                   damping=vals["damping"], scatter=vals["scatter"], seed=vals["seed"],
                   progress=progress, observers=observers,
                   h5md=(out / f"mca-{mode}.h5md") if out is not None else None,
                   frames=vals["frames"])
    st = res["dyn"].state
    strain, stress = res["strain"], res["stress"]
    GPa = units.GPa
    frag = np.sort(fragments(res["atoms"], pairs=st).g)[::-1]
    nbig = int(np.sum(frag >= 0.05 * len(res["atoms"])))
    if out is not None:
        files += _write_outputs(out, mode, res, mat)
    q = {
        "peak_stress": Quantity(res["peak_stress"] / GPa, "GPa", reference=ref / GPa,
                                note=f"vs the material's {'tensile' if mode == 'tension' else 'compressive'} strength"),
        "strain_at_peak": Quantity(res["strain_at_peak"], "", reference=ref / mat.E,
                                   note="vs strength / E"),
        ("tensile_strength" if mode == "tension" else "compressive_strength"):
            Quantity(ref / GPa, "GPa", note=mat.source.split(";")[0]),
        "fragments": Quantity(float(nbig), "", note="connected parts with >= 5% of the automata"),
        "broken_links": Quantity(float(np.sum(st.linked_p[:res["npairs0"]] == 0)), ""),
    }
    extra = {}
    if res.get("h5md_error"):
        extra["h5md"] = res["h5md_error"]
    r = SceneResult(f"mca-{mode}", q, time.perf_counter() - t0, files=files, extra=extra,
                    notes=[f"{len(res['atoms'])} automata, {st.npairs} pairs, dt = "
                           f"{res['dyn'].dt / units.ns:.4g} ns, friction mu = {vals['mu']}"])
    return r


def _write_outputs(out, mode, res, mat):
    from matplotlib import use
    use("Agg")
    import matplotlib.pyplot as plt
    files = []
    GPa = units.GPa
    csv_path = out / f"mca-{mode}-stress-strain.csv"
    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_ns", "strain", "stress_GPa"])
        for t, e, s in zip(res["time"], res["strain"], res["stress"]):
            w.writerow([t / units.ns, e, s / GPa])
    files.append(csv_path)
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(res["strain"] * 100, res["stress"] / GPa, "-", lw=1.5)
    ref = res["reference"] / GPa
    ax.axhline(ref, color="k", ls="--", lw=0.8, label=f"strength {ref:g} GPa")
    ax.set_xlabel(f"{mode} strain (%)")
    ax.set_ylabel(f"{mode} stress (GPa)")
    ax.set_title(f"MCA {mode}: {mat.name}")
    ax.legend()
    fig.tight_layout()
    p = out / f"mca-{mode}-stress-strain.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    files.append(p)
    files.append(crack_picture(res, out / f"mca-{mode}-cracks.png"))
    if res.get("h5md_path"):
        files.append(res["h5md_path"])
    return files


def crack_picture(res, path):
    """Automata (x-y projection and x-z) coloured by their broken-link count."""
    import matplotlib.pyplot as plt
    atoms, st = res["atoms"], res["dyn"].state
    nb = broken_links(st, res["npairs0"])[st.pair_rows(atoms)[5]]
    fig, axs = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
    for ax, (a, b) in zip(axs, [(0, 1), (0, 2)]):
        order = np.argsort(nb)
        sc = ax.scatter(atoms.positions[order, a] / units.um, atoms.positions[order, b] / units.um,
                        c=nb[order], s=18, cmap="inferno_r", vmin=0, vmax=max(1, nb.max()))
        ax.set_aspect("equal")
        ax.set_ylabel(f"{'xyz'[b]} (um)")
    axs[-1].set_xlabel("x (um)")
    fig.colorbar(sc, ax=axs, label="broken links")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


@register("mca-tension", "MCA uniaxial tension of a brittle bar: peak stress vs tensile strength",
          _params("tension"))
def mca_tension(vals, out=None, progress=True):
    return run_uniaxial("tension", vals, out, progress)


@register("mca-compression", "MCA uniaxial compression of a brittle bar: peak stress vs compressive "
          "strength", _params("compression"))
def mca_compression(vals, out=None, progress=True):
    return run_uniaxial("compression", vals, out, progress)
