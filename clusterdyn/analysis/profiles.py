"""Binned profiles over a whole trajectory, as arrays ready to plot or write.

:class:`TrajectoryProfiles` (an analysis on :class:`~clusterdyn.analysis.base.Analysis`:
``TrajectoryProfiles(traj, ...).run(start, stop, step).results``; online
:meth:`TrajectoryProfiles.add`, or :class:`ProfileRecorder`, its form without a
trajectory) and its one-call form :func:`trajectory_profiles` run
:func:`clusterdyn.analysis.slabs.stress_profile` on every frame with one
fixed set of slabs, and stack the results: ``stress[f, b, c]`` is component c
(Voigt xx yy zz yz xz xy, lab frame) of slab b in frame f.  From an H5MD file
they need nothing but the path: the calculator (and so the virials) is
rebuilt from the file's metadata.  :func:`write_profiles_csv` writes one
frame (or several) as CSV in GPa, um, m/s and g/cm3.
"""

import csv
import math

import numpy as np

from .. import units
from ..errors import InputError
from .base import Analysis
from .slabs import stress_profile
from .stress import VOIGT_NAMES, particle_virials


def _frame_virials(atoms, virials, calc):
    if callable(virials):
        return np.asarray(virials(atoms))
    if virials is not None:
        return np.asarray(virials)
    results = getattr(atoms.calc, "results", {}) if atoms.calc is not None else {}
    if "virials" in results:
        return np.asarray(results["virials"])
    if calc is not None:
        return particle_virials(atoms, calc)
    if "stresses" in results and atoms.cell.rank == 3:
        return np.asarray(results["stresses"]) * atoms.get_volume()
    if atoms.calc is not None:
        return particle_virials(atoms)
    raise InputError("virials", None, "frames with a calculator (or stored virials/stresses), a "
                     "calculator `calc`, or a function atoms -> (N, 6) virials")


class TrajectoryProfiles(Analysis):
    """Stress, intensity, density and velocity profiles on one fixed set of slabs, frame by frame.

    The one slab-profile recorder, on the :class:`~clusterdyn.analysis.base.Analysis` base:

    * offline, ``TrajectoryProfiles(trajectory, ...).run(start, stop, step)``
      fills ``results`` with the arrays listed under Returns of
      :func:`trajectory_profiles`;
    * online, :meth:`add` profiles one configuration with the virials the
      run already has (:class:`ProfileRecorder` is this class without a
      trajectory), :meth:`arrays` stacks the frames, :meth:`get_state` /
      :meth:`set_state` carry them through checkpoints; ``attach(dyn)`` also
      works (virials then as for a frame, below).

    Parameters
    ----------
    trajectory : path, H5MDReader, sequence/iterable of ase.Atoms, or None
        Frames (all with a 3-D cell; its cross-section is the slab area).  An
        H5MD file written by clusterdyn needs nothing else: the calculator
        comes from its metadata (:meth:`clusterdyn.io.H5MDReader.calculator`).
        Other paths are read with ``ase.io``.  None: online use only.
    width : float, optional
        Slab width, Angstrom.  Default (H5MD files only): ``sqrt(2) r0`` of
        the largest r0 of the material table, the fcc cube edge (two lattice
        planes along [100]; the slab of the shock scene in that direction).
    axis : int
        Profile direction (0, 1, 2).
    lo, hi : float, optional
        Slab range along ``axis``; default the first frame's extent, widened
        by 20% on each side so that moving material stays inside.
    virials : callable or None
        ``virials(atoms) -> (N, 6)`` eV; default: the frame's stored
        ``virials`` (or ``stresses`` times the volume), else ``calc``.
    calc : ASE calculator, optional
        Used on frames without stored virials (e.g. a ClusterDynamics).
        Default for an H5MD file: the calculator rebuilt from the file.
    times : array, optional
        Time of each analysed frame (ASE units); default
        ``atoms.info['time']`` or the frame index.
    exclude : callable, bool mask or "drives", optional
        ``exclude(atoms) -> bool mask`` or a mask of particles left out (a
        piston); ``"drives"``: the particles the file's stored constraints
        and drives act on (H5MD files only).

    Raises
    ------
    clusterdyn.errors.InputError
        No frames; an H5MD file without the metadata the defaults need (one
        line naming the missing ``/parameters`` entries).
    """

    KEYS = ("stress", "von_mises", "pressure", "density", "velocity", "count")

    def __init__(self, trajectory=None, width=None, axis=0, lo=None, hi=None, virials=None, calc=None,
                 times=None, exclude=None):
        super().__init__(trajectory)
        if axis not in (0, 1, 2):
            raise InputError("axis", axis, "0, 1 or 2")
        if width is not None and not (np.isfinite(width) and width > 0):
            raise InputError("width", width, "a slab width > 0 (Angstrom)")
        if isinstance(exclude, str) and exclude != "drives":
            raise InputError("exclude", exclude, "a callable, a bool mask or 'drives'")
        self.width, self.axis, self.lo, self.hi = width, axis, lo, hi
        self.virials, self.calc, self.times, self.exclude = virials, calc, times, exclude
        self._clear(width)

    def _clear(self, width):
        """Start a new set of frames on slabs of ``width`` (the slabs are fixed by the first frame)."""
        self._w = width
        self.edges = None
        self._prof = {k: [] for k in self.KEYS}
        self._t = []

    # -- one frame, online ----------------------------------------------------------------
    def add(self, atoms, virials, time, exclude=None):
        """Profile one configuration with its ``virials`` ((N, 6) eV) at ``time``; returns the profile."""
        if self.edges is None:
            x = atoms.positions[:, self.axis]
            span = x.max() - x.min()
            a = x.min() - 0.2 * span if self.lo is None else self.lo
            b = x.max() + 0.2 * span if self.hi is None else self.hi
            nb = max(1, int(np.ceil((b - a) / self._w)))
            self.edges = a + self._w * np.arange(nb + 1)
        p = stress_profile(atoms, self._w, virials, axis=self.axis, lo=self.edges[0],
                           hi=self.edges[-1], exclude=exclude)
        for k in self.KEYS:
            self._prof[k].append(p[k])
        self._t.append(float(time))
        return p

    def get_state(self):
        """Everything needed to resume (for checkpoints)."""
        return {"width": self._w, "axis": self.axis, "lo": self.lo, "hi": self.hi, "edges": self.edges,
                "frames": {k: list(v) for k, v in self._prof.items()}, "t": list(self._t)}

    def set_state(self, st):
        """Resume from :meth:`get_state` (in place)."""
        self._w, self.axis, self.lo, self.hi = st["width"], int(st["axis"]), st["lo"], st["hi"]
        self.edges = None if st["edges"] is None else np.asarray(st["edges"], float)
        self._prof = {k: [np.asarray(x) for x in st["frames"][k]] for k in self.KEYS}
        self._t = [float(x) for x in st["t"]]

    def arrays(self):
        """The frames so far, stacked: ``t``, ``edges``, ``x`` and the profiles (see :func:`trajectory_profiles`)."""
        if self.edges is None:
            raise InputError("trajectory", "no frames", "at least one frame")
        res = {k: np.array(v) for k, v in self._prof.items()}
        res["t"] = np.asarray(self._t, float)
        res["edges"] = self.edges
        res["x"] = 0.5 * (self.edges[1:] + self.edges[:-1])
        return res

    # -- the Analysis protocol -------------------------------------------------------------
    def _prepare(self):
        reader = self.reader
        width, calc = self.width, self.calc
        if width is None:
            if reader is None:
                raise InputError("width", None, "a slab width (Angstrom); it has a default only "
                                 "for H5MD files with a material table")
            from ..io.metadata import materials_from_metadata
            r0 = materials_from_metadata(reader.metadata, reader.path)[2]
            if r0 is None:
                raise InputError("width", None, "a slab width (Angstrom)",
                                 hint=f"{reader.path} has no r0 in its material table")
            width = math.sqrt(2.0) * max(r0)
        if calc is None and self.virials is None and reader is not None:
            calc = reader.calculator()
        if self.exclude == "drives" and reader is None:
            raise InputError("exclude", "drives", "a callable or a bool mask (\"drives\" needs an "
                             "H5MD file with its constraints)")
        self._calc = calc
        self._clear(width)
        self._n = 0

    def _single_frame(self, atoms):
        ex = self.exclude
        if isinstance(ex, str):
            ex = self.reader.drive_mask(self._frame_index)
        elif callable(ex):
            ex = ex(atoms)
        t = self.times[self._n] if self.times is not None else \
            atoms.info.get("time", float(self._frame_index))
        self.add(atoms, _frame_virials(atoms, self.virials, self._calc), t, exclude=ex)
        self._n += 1

    def _conclude(self):
        self.results.update(self.arrays())
        self.results["frames"] = np.asarray(self.frames, dtype=np.int64)
        self.results["width"] = self._w


class ProfileRecorder(TrajectoryProfiles):
    """:class:`TrajectoryProfiles` without a trajectory: ``ProfileRecorder(width, axis, lo, hi)``, then
    :meth:`~TrajectoryProfiles.add` per frame from a dynamics observer when the run is not stored."""

    def __init__(self, width, axis=0, lo=None, hi=None):
        super().__init__(None, width, axis, lo, hi)


def trajectory_profiles(trajectory, width=None, axis=0, lo=None, hi=None, virials=None, calc=None,
                        times=None, exclude=None, start=None, stop=None, step=None):
    """Stress, intensity, density and velocity profiles for every frame of a trajectory.

    The one-call form of :class:`TrajectoryProfiles` (same parameters; see
    there), ``TrajectoryProfiles(...).run(start, stop, step).results``.
    ``trajectory_profiles("shock.h5md")`` works from the file alone.

    Returns
    -------
    Results (a dict with attribute access) of arrays
        ``t`` (nf,), ``x`` (nb,), ``edges`` (nb+1,), ``stress`` (nf, nb, 6)
        eV/A^3, ``von_mises`` (nf, nb), ``pressure`` (nf, nb), ``density``
        (nf, nb) amu/A^3, ``velocity`` (nf, nb, 3) A/time, ``count`` (nf, nb),
        ``frames`` (nf,) the trajectory indices analysed, ``width`` (A).
    """
    return TrajectoryProfiles(trajectory, width, axis, lo, hi, virials, calc, times,
                              exclude).run(start, stop, step).results


def write_profiles_csv(path, profiles, frames=None):
    """Write profiles (from :func:`trajectory_profiles`) as CSV: one row per (frame, slab).

    Columns: t_ns, x_um, count, density_g_cm3, u_x_m_s, u_y_m_s, u_z_m_s,
    s_xx_GPa ... s_xy_GPa, von_mises_GPa, pressure_GPa.  Empty slabs are skipped.
    """
    nf = len(profiles["t"])
    frames = range(nf) if frames is None else frames
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_ns", "x_um", "count", "density_g_cm3", "u_x_m_s", "u_y_m_s", "u_z_m_s"]
                   + [f"s_{n}_GPa" for n in VOIGT_NAMES] + ["von_mises_GPa", "pressure_GPa"])
        for f in frames:
            for b, x in enumerate(profiles["x"]):
                if profiles["count"][f, b] == 0:
                    continue
                w.writerow([f"{profiles['t'][f] / units.ns:.6g}", f"{x / units.um:.6g}",
                            int(profiles["count"][f, b]),
                            f"{profiles['density'][f, b] / units.g_cm3:.6g}"]
                           + [f"{v / units.m_s:.6g}" for v in profiles["velocity"][f, b]]
                           + [f"{v / units.GPa:.6g}" for v in profiles["stress"][f, b]]
                           + [f"{profiles['von_mises'][f, b] / units.GPa:.6g}",
                              f"{profiles['pressure'][f, b] / units.GPa:.6g}"])
    return path
