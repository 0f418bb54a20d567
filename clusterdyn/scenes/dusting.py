"""Scene ``dusting``: a plane shock reaches a smooth free surface (CD paper, section 3.1).

The sample (docs/theory.md 1.3 and 1.8): aluminium clusters of size r0 in a
[100] fcc packing, ``length`` long along x and free along it, periodic across
with ``periods`` x ``periods`` lattice periods (two in the paper).  The
paper's sample is 5 mm long at r0 = 10 um (354 repeat cells, 5 664
clusters); the default here is 1 mm, and ``--set length=5mm`` runs the paper's.

The drive: a piston (the sample's first 1.5 r0, as in the ``shock`` scene)
moves at the particle velocity ``u`` for the whole run, so the shock that
reaches the rear surface has a flat top (no pressure profile behind the
front, the paper's set-up) and the surface releases into a steady plateau.
The run lasts ``duration``, by default 1.5 us per 5 mm of sample (the
paper's fig. 20 time for its sample): the shock crosses the sample in
0.4-0.8 us (u = 6-0.5 km/s), and the release from the rear surface reaches
the piston at about 1.1 us (u = 2 km/s).

Measured every frame: the *dispersed* clusters, the fragments of at most
``g_max`` clusters (default 10) whose centre of mass lies beyond the main
body's rear surface by more than b r0 (b = rc by default;
:func:`clusterdyn.analysis.dusting.dispersed`), counted per mm^2 of the
cross-section and as a mass fraction; and the free-surface velocity (mean
velocity of the clusters that started within ``probe`` of the rear face and
are not dispersed).  At the end: the number of clusters per layer along the
shock (layers ``layer`` r0 thick, 5 by default; the paper's fig. 20) and the
spectrum N(g) of the dispersed fragments.  The energy ledger of the dynamics
(kinetic, potential, piston work, damping loss) closes the run.

Damping: ``J = 50`` by default (free-surface scenes run damped,
docs/theory.md 1.3); ``J=none`` shows the artefact.
"""

import csv
import math
from dataclasses import dataclass

import numpy as np

from .. import units
from ..analysis.dusting import cross_section, dispersed, layer_counts
from ..analysis.fragment_graph import FragmentFinder
from ..analysis.fragment_spectra import G_MAX
from ..build.lattice import SQRT2
from ..errors import InputError
from ..md.damped import TIMESTEP_FACTOR
from .base import Param, Quantity, register_scene
from .common import ledger_joules, matplotlib_agg
from .lifecycle import SceneDef, Setup, Stage, scene_params
from .shock import build_shock

#: run time per sample length (the paper's 1.5 us for its 5 mm sample)
DURATION_PER_LENGTH = 1.5 * units.us / (5.0 * units.mm)
#: fewest repeat cells along the shock
MIN_CELLS = 10

PARAMS = [
    Param("u", 2.0, "particle velocity behind the shock (= piston speed)", unit="km/s", low=0.0, high=10.0,
          low_open=True),
    Param("length", 1.0, "sample length along the shock (the paper's: 5 mm)", unit="mm", low=0.0, low_open=True),
    Param("periods", 2, "lattice periods across (y and z; the paper's: 2)", kind="int", low=1),
    Param("r0", 10.0, "cluster size", unit="um", low=0.0, low_open=True),
    Param("rc", 1.1, "cutoff as a multiple of r0 (the paper's figs. 18 and 20: 1.1, fig. 19: 1.2)", low=1.0,
          high=1.414, low_open=True),
    Param("J", 50.0, "pair damping Gamma = c0/(J r0); none = off (shows the artefact)", low=0.0, low_open=True,
          optional=True),
    Param("noise", 10.0, "initial random velocity (rms), seeded", unit="m/s", low=0.0),
    Param("seed", 1, "random seed of the initial noise", kind="int", low=0),
    Param("g_max", G_MAX, "largest fragment counted as dispersed (clusters)", kind="int", low=1),
    Param("b", None, "bond distance of the fragments, in r0; none = rc", low=0.5, high=2.0, optional=True),
    Param("layer", 5.0, "thickness of the layers of the final profile, in r0", low=0.1),
    Param("probe", 3.0, "free-surface velocity: clusters that started within this depth of the rear face, "
          "in r0", low=0.5),
    Param("duration", None, "run time; none = 1.5 us per 5 mm of sample", unit="us", low=0.0, low_open=True,
          optional=True, restart=True),
    Param("frames", 100, "analysis frames over the run", kind="int", low=5),
    Param("dt_factor", TIMESTEP_FACTOR, "time step as a fraction of r0/(c0 + u) (shock scene's rule)", low=0.0,
          high=0.5, low_open=True),
    Param("dt_retries", 2, "times the run starts again with half the time step when the stiffness check "
          "stops it", kind="int", low=0),
]


def _cells(v):
    return max(1, int(round(v.length / (SQRT2 * v.r0))))


def _duration(v, length):
    return v.duration if v.duration is not None else DURATION_PER_LENGTH * length


@dataclass
class DustingSetup(Setup):
    """A built dusting run (ASE units): the piston shock and what its analysis needs (the checkpoint's
    payload, :class:`~clusterdyn.scenes.lifecycle.Setup`)."""

    piston_index: np.ndarray = None  #: rows of the piston layer
    probe: np.ndarray = None         #: rows of the rear layer (free-surface velocity)
    g_max: int = 0                   #: largest dispersed fragment (clusters)
    b: float = 0.0                   #: fragment bond length, in r0
    area: float = 0.0                #: cross-section (Angstrom^2)
    length: float = 0.0              #: sample length along x
    x_rear: float = 0.0              #: rear surface at set-up
    r0: float = 0.0
    u: float = 0.0
    cells: int = 0                   #: repeat cells along x
    nsteps: int = 0
    dt: float = 0.0
    mass: float = 0.0                #: mass of the sample without the piston


class DustingRecord:
    """Analysis state of a dusting run: dispersed clusters and free-surface velocity per frame.

    Parameters
    ----------
    setup : DustingSetup
        The running sample, its dynamics, the piston and probe rows, ``b``, ``g_max``, ``area``.
    """

    KEYS = ("t", "n_fragments", "n_clusters", "per_mm2", "mass_fraction", "surface", "fsv", "large_clusters")

    def __init__(self, setup):
        self.atoms, self.dyn = setup.atoms, setup.dyn
        n = len(self.atoms)
        self.exclude = np.zeros(n, bool)
        self.exclude[np.asarray(setup.piston_index, dtype=np.int64)] = True
        self.probe = np.asarray(setup.probe, dtype=np.int64)
        self.g_max, self.b, self.area = int(setup.g_max), float(setup.b), float(setup.area)
        self.finder = FragmentFinder(self.b, exclude=self.exclude)
        self.series = {k: [] for k in self.KEYS}

    def measure(self):
        """The :class:`~clusterdyn.analysis.dusting.Dispersed` of the current configuration."""
        f = self.finder.find(self.atoms)
        return dispersed(self.atoms, f, g_max=self.g_max, exclude=self.exclude, area=self.area)

    def frame(self, d):
        disp = self.measure()
        f = disp.fragments
        gone = disp.mask[np.maximum(f.labels[self.probe], 0)]
        keep = self.probe[~gone]
        v = self.atoms.get_velocities()[keep, 0]
        row = {"t": d.get_time(), "n_fragments": disp.n_fragments, "n_clusters": disp.n_clusters,
               "per_mm2": disp.per_mm2, "mass_fraction": disp.mass_fraction, "surface": disp.surface,
               "fsv": float(v.mean()) if len(v) else float("nan"), "large_clusters": disp.large_clusters}
        for k in self.KEYS:
            self.series[k].append(float(row[k]))

    def arrays(self):
        return {k: np.asarray(x, float) for k, x in self.series.items()}

    def get_state(self):
        return {"series": {k: list(x) for k, x in self.series.items()}}

    def set_state(self, st):
        self.series = {k: [float(x) for x in st["series"][k]] for k in self.KEYS}


def surface_plateau(t, fsv, u):
    """Arrival time (first frame above u) and plateau (median after the arrival, over the later 90%
    of the remaining frames) of a free-surface velocity series; NaN if the shock has not arrived."""
    ok = np.isfinite(fsv)
    up = np.nonzero(ok & (fsv > u))[0]
    if not len(up):
        return float("nan"), float("nan")
    ta = t[up[0]]
    win = ok & (t > ta + 0.1 * (t[-1] - ta))
    if not win.any():
        return float(ta), float("nan")
    return float(ta), float(np.median(fsv[win]))


class DustingScene(SceneDef):
    """The ``dusting`` scene on the lifecycle (module docstring)."""

    name = "dusting"
    description = ("plane shock (piston at u) onto a smooth free surface: clusters dispersed per mm^2 and as a "
                   "mass fraction against time, clusters per layer (CD paper figs. 18-20)")
    params = scene_params(PARAMS, h5md_frames=20)
    setup_class = DustingSetup

    def estimate_particles(self, v):
        from .lifecycle import fcc_count
        return fcc_count(v.length * (v.periods * SQRT2 * v.r0) ** 2, v.r0)

    def check(self, v):
        n = _cells(v)
        if n < MIN_CELLS:
            raise InputError("length", f"{v.length / units.mm:g}mm",
                             f"at least {MIN_CELLS} repeat cells (sqrt 2 r0 = {SQRT2 * v.r0 / units.um:g} um "
                             f"each): {MIN_CELLS * SQRT2 * v.r0 / units.mm:.3g} mm or more")
        if v.probe > n * SQRT2 / 2:
            raise InputError("probe", f"{v.probe:g}", f"a depth in [0.5, {n * SQRT2 / 2:.4g}] r0 (half the "
                             f"sample's length: the probe must stay near the rear face)")
        if v.periods * SQRT2 < 2.0 * v.rc:
            raise InputError("periods", v.periods, f"a cross-section at least 2 rc r0 wide "
                             f"({math.ceil(2 * v.rc / SQRT2)} periods at rc = {v.rc:g})")

    def setup(self, v, stage):
        n = _cells(v)
        s = build_shock("Al", v.u, "100", (n, v.periods, v.periods), v.r0, v.rc, v.J,
                        v.noise, v.seed, v.dt_factor)
        atoms, dyn = s.atoms, s.dyn
        x = atoms.positions[:, 0]
        r0 = v.r0
        probe = np.nonzero(x > x.max() - v.probe * r0)[0]
        length = float(np.ptp(x)) + r0 / SQRT2
        setup = DustingSetup(atoms, dyn, piston_index=s.piston_index, probe=probe, g_max=v.g_max,
                             b=v.b if v.b is not None else v.rc, area=cross_section(atoms), length=length,
                             x_rear=float(x.max()), r0=r0, u=v.u, cells=n,
                             nsteps=int(math.ceil(_duration(v, length) / dyn.dt)), dt=dyn.dt,
                             mass=float(atoms.get_masses()[~s.piston_mask].sum()))
        dyn.start_ledger()
        return setup

    def attach(self, v, stage, setup):
        if v.duration is not None:          # a restart may lengthen the run
            setup.nsteps = int(math.ceil(v.duration / setup.dyn.dt))
        rec = DustingRecord(setup)
        return Stage(stage, setup.atoms, setup.dyn, int(setup.nsteps), v.frames, on_frame=rec.frame, analysis=rec)

    def retry(self, v, stage, exc, attempt):
        if exc.quantity != "timestep" or attempt > v.dt_retries:
            return None
        note = f"dt factor {v.dt_factor:g}: stopped at step {exc.step} by the stiffness check"
        return v.replace(dt_factor=0.5 * v.dt_factor, retried=v.retried + (note,))

    def finish(self, v, stage):
        rec, atoms, info = stage.analysis, stage.atoms, stage.info
        disp = rec.measure()
        g, ng = disp.spectrum()
        xc, nl = layer_counts(atoms, v.layer * info["r0"], exclude=rec.exclude)
        L = stage.dyn.energy_ledger()
        return {"series": rec.arrays(), "layers_x": xc, "layers_n": nl, "t_end": stage.dyn.get_time(),
                "spectrum_g": g, "spectrum_n": ng, "surface": disp.surface, "ledger": L, "n": len(atoms),
                "nsteps": stage.nsteps, "t_run": stage.t_run, "info": info,
                "nbuilds": atoms.calc.nl.nbuilds}

    def analyse(self, v, summaries):
        sm = summaries[0]
        s, info, L = sm["series"], sm["info"], sm["ledger"]
        u = v.u
        per_layer = 4 * v.periods ** 2 / 2          # clusters in one (200) plane of the cross-section
        ta, plateau = surface_plateau(s["t"], s["fsv"], u)
        resid = L["residual"] / L["energy_in"]
        q = {
            "dispersed_per_mm2": Quantity(s["per_mm2"][-1], "1/mm2",
                                          note=f"clusters in fragments of <= {v.g_max} beyond the rear surface "
                                               f"at t = {sm['t_end'] / units.us:.3g} us"),
            "dispersed_clusters": Quantity(s["n_clusters"][-1], "",
                                           note=f"on a cross-section of {info['area'] / units.um ** 2:.0f} um^2"),
            "dispersed_fragments": Quantity(s["n_fragments"][-1], ""),
            "monolayers": Quantity(s["n_clusters"][-1] / per_layer, "",
                                   note=f"dispersed clusters / {per_layer:g} (one (200) plane)"),
            "mass_fraction": Quantity(s["mass_fraction"][-1], "", note="dispersed mass / sample mass"),
            "max_per_mm2": Quantity(float(np.max(s["per_mm2"])), "1/mm2", note="largest count over the run"),
            "large_ejected_clusters": Quantity(s["large_clusters"][-1], "",
                                               note=f"clusters in fragments of > {v.g_max} beyond the surface"),
            "fsv_plateau": Quantity(plateau / units.km_s, "km/s", 2 * u / units.km_s,
                                    note="free-surface velocity plateau vs 2u (acoustic doubling, approximate)"),
            "t_arrival": Quantity(ta / units.us, "us", note="shock at the rear surface (free surface above u)"),
            "ledger_residual": Quantity(resid, "", note="energy ledger residual / energy put in"),
        }
        notes = [f"{sm['n']} clusters ({info['cells']} cells x {v.periods} x {v.periods}), sample "
                 f"{info['length'] / units.mm:.3f} mm, {sm['nsteps']} steps of {info['dt'] / units.ns:.4g} ns, "
                 f"{sm['t_run']:.1f} s stepping, {sm['nbuilds']} list builds",
                 "drive: piston (first 1.5 r0) at u for the whole run",
                 f"dispersed: fragments of <= {v.g_max} clusters whose centre lies > b r0 beyond the main "
                 f"body's (largest fragment's) rear surface (b = {info['b']:g}); damping {'off' if v.J is None else 'J = %g' % v.J}",
                 "energy ledger (J): kinetic {kinetic:.6g}, potential {potential:.6g}, piston work {drive_work:.6g}, "
                 "layer kinetic {layer_kinetic:.6g}, damping loss {damping_loss:.6g}, energy in {energy_in:.6g}, "
                 "residual {residual:.3g}".format(**ledger_joules(L))]
        for r in v.retried:
            notes.append(f"time step halved after a stop: {r}")
        extra = {"ledger_J": ledger_joules(L), "n_particles": sm["n"], "n_steps": sm["nsteps"],
                 "stepping_time_s": sm["t_run"],
                 "spectrum": {"g": sm["spectrum_g"].tolist(), "N": sm["spectrum_n"].tolist()},
                 "t_end_us": sm["t_end"] / units.us, "area_um2": info["area"] / units.um ** 2,
                 "clusters_per_plane": per_layer, "surface_mm": sm["surface"] / units.mm,
                 "series": {"t_us": (s["t"] / units.us).tolist(), "per_mm2": s["per_mm2"].tolist(),
                            "mass_fraction": s["mass_fraction"].tolist(), "fsv_km_s": (s["fsv"] / units.km_s).tolist()},
                 "layers": {"x_mm": (sm["layers_x"] / units.mm).tolist(), "n": sm["layers_n"].tolist(),
                            "thickness_r0": v.layer}}
        return q, notes, extra

    def report(self, v, summaries, result, out):
        sm = summaries[0]
        files = [write_dusting_csv(out / "dusting_time.csv", sm), write_layers_csv(out / "dusting_layers.csv", sm)]
        files.append(plot_dusting(sm, v, out / "dusting.png"))
        return files


def write_dusting_csv(path, sm):
    s = sm["series"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_us", "dispersed_fragments", "dispersed_clusters", "dispersed_per_mm2", "mass_fraction",
                    "surface_um", "free_surface_velocity_km_s", "large_ejected_clusters"])
        for k in range(len(s["t"])):
            w.writerow([f"{s['t'][k] / units.us:.6g}", int(s["n_fragments"][k]), int(s["n_clusters"][k]),
                        f"{s['per_mm2'][k]:.6g}", f"{s['mass_fraction'][k]:.6g}", f"{s['surface'][k] / units.um:.6g}",
                        f"{s['fsv'][k] / units.km_s:.6g}", int(s["large_clusters"][k])])
    return path


def write_layers_csv(path, sm):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x_um", "clusters"])
        for x, n in zip(sm["layers_x"], sm["layers_n"]):
            w.writerow([f"{x / units.um:.6g}", int(n)])
    return path


def plot_dusting(sm, v, path):
    plt = matplotlib_agg()
    s = sm["series"]
    t = s["t"] / units.us
    fig, axs = plt.subplots(1, 3, figsize=(15, 4.2))
    ax = axs[0]
    ax.plot(t, s["per_mm2"], "C0-", label="dispersed clusters per mm^2")
    ax.set_xlabel("t (us)")
    ax.set_ylabel("dispersed clusters per mm^2", color="C0")
    ax2 = ax.twinx()
    ax2.plot(t, 100 * s["mass_fraction"], "C1--", label="mass fraction")
    ax2.set_ylabel("dispersed mass fraction (%)", color="C1")
    ax.set_title(f"u = {v.u / units.km_s:g} km/s, rc = {v.rc:g}, "
                 f"{'no damping' if v.J is None else 'J = %g' % v.J}, g <= {v.g_max}")
    axs[1].plot(t, s["fsv"] / units.km_s, "k-")
    axs[1].axhline(2 * v.u / units.km_s, color="gray", ls=":", lw=0.8, label="2u")
    axs[1].set_xlabel("t (us)")
    axs[1].set_ylabel("free-surface velocity (km/s)")
    axs[1].legend(fontsize=8)
    axs[1].set_title("rear free surface")
    x = sm["layers_x"] / units.mm
    axs[2].step(x, sm["layers_n"], where="mid", lw=0.8)
    axs[2].axvline(sm["surface"] / units.mm, color="r", lw=0.6, ls="--", label="main body's rear surface")
    axs[2].set_xlabel("x (mm)")
    axs[2].set_ylabel(f"clusters per layer ({v.layer:g} r0 thick)")
    axs[2].set_title(f"layers at t = {sm['t_end'] / units.us:.3g} us (CD paper fig. 20)")
    axs[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


register_scene(DustingScene())
