"""Analyses over a trajectory, in the shape of MDAnalysis' ``AnalysisBase``.

A subclass of :class:`TrajectoryAnalysis` implements ``_prepare()``,
``_single_frame(atoms)`` and ``_conclude()``; ``run(start, stop, step)``
walks the frames and leaves the outcome in ``results`` (a dict with
attribute access, like MDAnalysis' ``Results``).  The trajectory is any of

- a path of an H5MD file (opened with :class:`clusterdyn.io.H5MDReader` for
  the run; the analysis then sees the file's metadata through ``self.reader``:
  material table, calculator, drives),
- an open :class:`~clusterdyn.io.H5MDReader`,
- a sequence or iterable of :class:`ase.Atoms`,
- a path of another file ``ase.io`` reads.
"""

import itertools
import os

from ..errors import InputError

__all__ = ["Results", "TrajectoryAnalysis", "is_h5md_path"]


class Results(dict):
    """The results of an analysis: a dict whose keys are also attributes."""

    def __getattr__(self, key):
        try:
            return self[key]
        except KeyError:
            raise AttributeError(key) from None

    def __setattr__(self, key, value):
        self[key] = value


def is_h5md_path(trajectory):
    """True when ``trajectory`` is the path of an HDF5 file (read as H5MD)."""
    if not (isinstance(trajectory, (str, bytes)) or hasattr(trajectory, "__fspath__")):
        return False
    path = os.fsdecode(trajectory)
    if path.endswith((".h5md", ".h5", ".hdf5")):
        return True
    if os.path.isfile(path):
        import h5py
        return h5py.is_hdf5(path)
    return False


class TrajectoryAnalysis:
    """Base of analyses over the frames of a trajectory (MDAnalysis' AnalysisBase shape).

    Parameters
    ----------
    trajectory : path, H5MDReader, or sequence/iterable of ase.Atoms
        See the module docstring.

    Attributes
    ----------
    results : Results
        Filled by :meth:`run`.
    reader : H5MDReader or None
        The open reader while :meth:`run` walks an H5MD trajectory.
    frames : list of int
        Indices of the frames analysed (after :meth:`run`).
    """

    def __init__(self, trajectory):
        self._trajectory = trajectory
        self.reader = None
        self.results = Results()
        self.frames = []

    # -- to implement ----------------------------------------------------------
    def _prepare(self):
        """Called once before the first frame (``self.reader`` is set for H5MD files)."""

    def _single_frame(self, atoms):
        """Analyse one frame (``self._frame_index``: its index in the trajectory)."""
        raise NotImplementedError

    def _conclude(self):
        """Called once after the last frame: fill ``self.results``."""

    # -- the loop ----------------------------------------------------------------
    def _iter_frames(self, start, stop, step):
        traj = self._trajectory
        sl = slice(start, stop, step)
        if hasattr(traj, "get_atoms") and hasattr(traj, "n_frames"):    # an H5MDReader
            self.reader = traj
            for i in range(*sl.indices(traj.n_frames)):
                yield i, traj.get_atoms(i)
            return
        if isinstance(traj, (str, bytes)) or hasattr(traj, "__fspath__"):
            if is_h5md_path(traj):
                from ..io.h5md_reader import H5MDReader
                with H5MDReader(os.fsdecode(traj)) as reader:
                    self.reader = reader
                    try:
                        for i in range(*sl.indices(reader.n_frames)):
                            yield i, reader.get_atoms(i)
                    finally:
                        self.reader = None
                return
            from ase.io import iread
            traj = iread(os.fsdecode(traj), index=":")
        if hasattr(traj, "__len__") and hasattr(traj, "__getitem__"):
            for i in range(*sl.indices(len(traj))):
                yield i, traj[i]
            return
        if (step or 1) < 0 or (start or 0) < 0 or (stop is not None and stop < 0):
            raise InputError("start/stop/step", (start, stop, step),
                             "non-negative values for a trajectory that is only iterable")
        yield from itertools.islice(enumerate(traj), start, stop, step)

    def run(self, start=None, stop=None, step=None):
        """Analyse frames ``start:stop:step`` (Python slice semantics); returns ``self``."""
        self.results = Results()
        self.frames = []
        frames = self._iter_frames(start, stop, step)
        prepared = False
        try:
            for i, atoms in frames:
                if not prepared:
                    self._prepare()
                    prepared = True
                self._frame_index = i
                self.frames.append(i)
                self._single_frame(atoms)
        finally:
            frames.close()
        if not prepared:
            raise InputError("trajectory", "no frames", "at least one frame to analyse")
        self._conclude()
        return self
