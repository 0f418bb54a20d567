"""MCA scenes: ``clusterdyn run mca-tension`` and ``clusterdyn run mca-compression``.

A brittle ceramic-like bar (default alumina: E 370 GPa, nu 0.22, sigma_t
0.3 GPa, sigma_c 2.5 GPa, Drucker-Prager beta = 8.33) of fcc automata
(d = 10 um, 16 x 5 x 5 d, ~400 automata) is pulled or pressed between two
grips (pistons along x with free lateral motion, non-rotating) whose speed
rises as a smooth ramp over the first 10% of the run, with 5% of critical
pair damping (quasi-static), 2% uniform scatter of the pair strengths
(seeded; it picks where the crack starts), friction coefficient of unlinked
pairs mu = 0.3 (:func:`~clusterdyn.scenes.mca_experiments.build_uniaxial`).

The scenes run on the scene lifecycle (:mod:`clusterdyn.scenes.lifecycle`):
checkpoints every ``checkpoint_every`` curve samples with ``--out``, and
``--restart`` continues a run bit for bit; on restart only ``h5md``,
``h5md_frames`` and ``checkpoint_every`` may change (``steps`` sets the
loading rate, ``frames`` the sampling of the curve: both are physics of the
measurement).  Written: stress-strain curve (CSV + PNG), crack pattern (PNG,
automata coloured by broken-link count), H5MD with per-automaton stress,
link counts and the linked pairs on every frame, and the result:
``peak_stress`` and ``strain_at_peak`` against the material strength, the
fragments, the broken links and the wall time.
"""

import csv

import numpy as np

from .. import units
from ..analysis.fragments import fragments
from ..errors import InputError
from ..materials import get_material
from .base import Param, Quantity, register_scene
from .lifecycle import SceneDef, Stage, scene_params
from .mca_experiments import UniaxialCurve, broken_links, build_uniaxial, uniaxial_per_particle

MATERIALS = ("alumina", "concrete")
#: fewest automaton sizes along the bar: pairs within 1.2 d of a grip never break, and a shorter bar
#: has no breakable pair left (4x3x3 and 3x3x3 pulled to 6 sigma_t/E broke no link, 5x3x3 broke 34)
MIN_LENGTH = 5


def _params():
    return scene_params([
        Param("material", "alumina", "brittle MCA material", kind="choice", choices=MATERIALS),
        Param("d", 10.0, "automaton size", unit="um", low=0.0, low_open=True),
        Param("size", (16, 5, 5), "bar length x width x height in automaton sizes", kind="ints", low=3),
        Param("packing", "fcc", "packing of the automata", kind="choice",
              choices=("fcc", "hcp", "sc", "random")),
        Param("steps", 3000, "time steps to the final strain (dt = 0.15 d / c_L); sets the loading rate",
              kind="int", low=100),
        Param("strain_max", 2.5, "final strain as a multiple of strength/E", low=0.1, low_open=True),
        Param("damping", 0.05, "fraction of critical damping of relative pair velocity", low=0.0,
              high=1.0),
        Param("scatter", 0.02, "relative scatter of pair strengths (uniform, seeded)", low=0.0,
              high=0.5),
        Param("mu", 0.3, "Coulomb friction coefficient of unlinked pairs", low=0.0),
        Param("seed", 0, "random seed (strength scatter, random packing)", kind="int", low=0),
        Param("frames", 150, "points of the stress-strain curve over the run", kind="int", low=5),
    ], h5md_frames=20, checkpoint_every=10)


def _material(v):
    mat = get_material(v.material)
    return mat.replace(extra={**mat.extra, "mu": v.mu})


class UniaxialScene(SceneDef):
    instability_hint = ("on the command line the time step is fixed by d; a slower loading is more steps, "
                        "--set steps= above {steps}")
    """``mca-tension`` / ``mca-compression`` on the lifecycle (module docstring)."""

    params = _params()

    def __init__(self, mode):
        self.mode = mode
        self.name = f"mca-{mode}"
        self.h5md_stem = self.name
        strength = "tensile" if mode == "tension" else "compressive"
        self.description = f"MCA uniaxial {mode} of a brittle bar: peak stress vs {strength} strength"

    def check(self, v):
        if v.size[0] < MIN_LENGTH:
            raise InputError("size", "x".join(map(str, v.size)),
                             f"at least {MIN_LENGTH} automaton sizes along the bar (pairs within 1.2 d of a "
                             f"grip never break: a shorter bar has no gauge section); e.g. {MIN_LENGTH}x{v.size[1]}x{v.size[2]}")

    def setup(self, v, stage):
        mat = _material(v)
        ref = mat.sigma_t if self.mode == "tension" else mat.sigma_c
        s = build_uniaxial(mat, self.mode, d=v.d, size=v.size, packing=v.packing,
                           strain_max=v.strain_max * ref / mat.E, steps=v.steps, damping=v.damping,
                           scatter=v.scatter, seed=v.seed)
        lo, hi = s.grips
        info = {"L0": s.L0, "area": s.area, "sign": s.sign, "reference": float(s.reference),
                "npairs0": int(s.npairs0), "steps": int(s.steps), "lo": lo.index.copy(), "hi": hi.index.copy()}
        return s.atoms, s.dyn, info

    def attach(self, v, stage, atoms, dyn, info):
        curve = UniaxialCurve(info["L0"], info["area"], info["sign"], info["lo"], info["hi"])
        return Stage(stage, atoms, dyn, int(info["steps"]), v.frames, info, on_frame=curve.add, analysis=curve,
                     per_particle=uniaxial_per_particle(dyn, int(info["npairs0"])))

    def finish(self, v, stage):
        atoms, st = stage.atoms, stage.dyn.state
        n0 = int(stage.info["npairs0"])
        frag = np.sort(fragments(atoms, pairs=st).g)[::-1]
        return {"curve": stage.analysis.get_state(), "n": len(atoms), "npairs": int(st.npairs),
                "broken": int(np.sum(st.linked_p[:n0] == 0)),
                "fragments": int(np.sum(frag >= 0.05 * len(atoms))), "dt": float(stage.dyn.dt),
                "t_run": stage.t_run, "positions": atoms.positions.copy(),
                "broken_n": broken_links(st, n0)[st.pair_rows(atoms)[5]], "reference": stage.info["reference"]}

    def analyse(self, v, summaries):
        sm = summaries[0]
        mat = _material(v)
        ref = sm["reference"]
        peak, e_peak = UniaxialCurve.from_state(sm["curve"]).peak()
        GPa = units.GPa
        strength = "tensile" if self.mode == "tension" else "compressive"
        q = {
            "peak_stress": Quantity(peak / GPa, "GPa", reference=ref / GPa,
                                    note=f"vs the material's {strength} strength"),
            "strain_at_peak": Quantity(e_peak, "", reference=ref / mat.E, note="vs strength / E"),
            f"{strength}_strength": Quantity(ref / GPa, "GPa", note=mat.source.split(";")[0]),
            "fragments": Quantity(float(sm["fragments"]), "", note="connected parts with >= 5% of the automata"),
            "broken_links": Quantity(float(sm["broken"]), ""),
        }
        notes = [f"{sm['n']} automata, {sm['npairs']} pairs, dt = {sm['dt'] / units.ns:.4g} ns, "
                 f"friction mu = {v.mu}"]
        extra = {"n_automata": sm["n"], "n_pairs": sm["npairs"], "stepping_time_s": sm["t_run"]}
        return q, notes, extra

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        mode = self.mode
        plt = _plt()
        GPa = units.GPa
        t, e, s = (np.asarray(sm["curve"][k], float) for k in ("time", "strain", "stress"))
        csv_path = out / f"mca-{mode}-stress-strain.csv"
        with open(csv_path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["time_ns", "strain", "stress_GPa"])
            for row in zip(t / units.ns, e, s / GPa):
                w.writerow(row)
        fig, ax = plt.subplots(figsize=(5, 3.5))
        ax.plot(e * 100, s / GPa, "-", lw=1.5)
        ref = sm["reference"] / GPa
        ax.axhline(ref, color="k", ls="--", lw=0.8, label=f"strength {ref:g} GPa")
        ax.set_xlabel(f"{mode} strain (%)")
        ax.set_ylabel(f"{mode} stress (GPa)")
        ax.set_title(f"MCA {mode}: {v.material}")
        ax.legend()
        fig.tight_layout()
        png = out / f"mca-{mode}-stress-strain.png"
        fig.savefig(png, dpi=120)
        plt.close(fig)
        return [csv_path, png, crack_picture(sm["positions"], sm["broken_n"], out / f"mca-{mode}-cracks.png")]


def _plt():
    from .common import matplotlib_agg
    return matplotlib_agg()


def crack_picture(positions, broken_n, path):
    """Automata (x-y and x-z projections) coloured by their broken-link count; the PNG's path."""
    plt = _plt()
    nb = np.asarray(broken_n)
    fig, axs = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
    order = np.argsort(nb)
    for ax, (a, b) in zip(axs, [(0, 1), (0, 2)]):
        sc = ax.scatter(positions[order, a] / units.um, positions[order, b] / units.um,
                        c=nb[order], s=18, cmap="inferno_r", vmin=0, vmax=max(1, nb.max()))
        ax.set_aspect("equal")
        ax.set_ylabel(f"{'xyz'[b]} (um)")
    axs[-1].set_xlabel("x (um)")
    fig.colorbar(sc, ax=axs, label="broken links")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


register_scene(UniaxialScene("tension"))
register_scene(UniaxialScene("compression"))
