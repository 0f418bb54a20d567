"""Binned profiles over a whole trajectory, as arrays ready to plot or write.

:func:`trajectory_profiles` runs :func:`clusterdyn.analysis.slabs.stress_profile`
on every frame with one fixed set of slabs (:class:`ProfileRecorder`, also usable
as an observer during a run), and stacks the results:
``stress[f, b, c]`` is component c (Voigt xx yy zz yz xz xy, lab frame) of
slab b in frame f.  :func:`write_profiles_csv` writes one frame (or several)
as CSV in GPa, um, m/s and g/cm3.
"""

import csv

import numpy as np

from .. import units
from ..errors import InputError
from .slabs import stress_profile
from .stress import VOIGT_NAMES, particle_virials


def _frames(trajectory):
    if isinstance(trajectory, (str, bytes)) or hasattr(trajectory, "__fspath__"):
        from ase.io import iread
        return iread(str(trajectory), index=":")
    return iter(trajectory)


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


class ProfileRecorder:
    """Collect slab profiles frame by frame on one fixed set of slabs.

    ``add(atoms, virials, time)`` profiles one frame
    (:func:`~clusterdyn.analysis.slabs.stress_profile`); :meth:`arrays`
    stacks them into the dict :func:`trajectory_profiles` returns.  Use it
    from a dynamics observer when the run is not stored.
    """

    KEYS = ("stress", "von_mises", "pressure", "density", "velocity", "count")

    def __init__(self, width, axis=0, lo=None, hi=None):
        self.width, self.axis, self.lo, self.hi = width, axis, lo, hi
        self.edges = None
        self.frames = {k: [] for k in self.KEYS}
        self.t = []

    def add(self, atoms, virials, time, exclude=None):
        if self.edges is None:
            x = atoms.positions[:, self.axis]
            span = x.max() - x.min()
            a = x.min() - 0.2 * span if self.lo is None else self.lo
            b = x.max() + 0.2 * span if self.hi is None else self.hi
            nb = max(1, int(np.ceil((b - a) / self.width)))
            self.edges = a + self.width * np.arange(nb + 1)
        p = stress_profile(atoms, self.width, virials, axis=self.axis, lo=self.edges[0],
                           hi=self.edges[-1], exclude=exclude)
        for k in self.KEYS:
            self.frames[k].append(p[k])
        self.t.append(float(time))
        return p

    def get_state(self):
        """Everything needed to resume (for checkpoints)."""
        return {"width": self.width, "axis": self.axis, "lo": self.lo, "hi": self.hi, "edges": self.edges,
                "frames": {k: list(v) for k, v in self.frames.items()}, "t": list(self.t)}

    def set_state(self, st):
        """Resume from :meth:`get_state` (in place)."""
        self.width, self.axis, self.lo, self.hi = st["width"], int(st["axis"]), st["lo"], st["hi"]
        self.edges = None if st["edges"] is None else np.asarray(st["edges"], float)
        self.frames = {k: [np.asarray(x) for x in st["frames"][k]] for k in self.KEYS}
        self.t = [float(x) for x in st["t"]]

    def arrays(self):
        if self.edges is None:
            raise InputError("trajectory", "no frames", "at least one frame")
        res = {k: np.array(v) for k, v in self.frames.items()}
        res["t"] = np.asarray(self.t, float)
        res["edges"] = self.edges
        res["x"] = 0.5 * (self.edges[1:] + self.edges[:-1])
        return res


def trajectory_profiles(trajectory, width, axis=0, lo=None, hi=None, virials=None, calc=None,
                        times=None, exclude=None):
    """Stress, intensity, density and velocity profiles for every frame of a trajectory.

    Parameters
    ----------
    trajectory : iterable of ase.Atoms, or a path ase.io can read
        Frames (all with a 3-D cell; its cross-section is the slab area).
    width : float
        Slab width, Angstrom.
    lo, hi : float, optional
        Slab range along ``axis``; default the first frame's extent, widened
        by 20% on each side so that moving material stays inside.
    virials : callable or None
        ``virials(atoms) -> (N, 6)`` eV; default: the frame's stored
        ``virials`` (or ``stresses`` times the volume), else ``calc``.
    calc : ASE calculator, optional
        Used on frames without stored virials (e.g. a ClusterDynamics).
    times : array, optional
        Time of each frame (ASE units); default ``atoms.info['time']`` or the
        frame index.
    exclude : callable, optional
        ``exclude(atoms) -> bool mask`` of particles left out (a piston).

    Returns
    -------
    dict of arrays
        ``t`` (nf,), ``x`` (nb,), ``edges`` (nb+1,), ``stress`` (nf, nb, 6)
        eV/A^3, ``von_mises`` (nf, nb), ``pressure`` (nf, nb), ``density``
        (nf, nb) amu/A^3, ``velocity`` (nf, nb, 3) A/time, ``count`` (nf, nb).
    """
    rec = ProfileRecorder(width, axis, lo, hi)
    for i, atoms in enumerate(_frames(trajectory)):
        ex = exclude(atoms) if callable(exclude) else exclude
        t = times[i] if times is not None else atoms.info.get("time", float(i))
        rec.add(atoms, _frame_virials(atoms, virials, calc), t, exclude=ex)
    return rec.arrays()


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
