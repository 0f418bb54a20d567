"""One analysis shape, offline and online, after MDAnalysis' ``AnalysisBase``.

A subclass of :class:`Analysis` implements ``_prepare()``,
``_single_frame(atoms)`` and ``_conclude()``; the outcome is left in
``results`` (a dict with attribute access, like MDAnalysis' ``Results``).
The same subclass runs

* **offline**: ``Analysis(trajectory).run(start, stop, step)`` walks the
  frames of a trajectory, any of

  - a path of an H5MD file (opened with :class:`clusterdyn.io.H5MDReader` for
    the run; the analysis then sees the file's metadata through ``self.reader``:
    material table, calculator, drives),
  - an open :class:`~clusterdyn.io.H5MDReader`,
  - a sequence or iterable of :class:`ase.Atoms`,
  - a path of another file ``ase.io`` reads;

* **online**: ``analysis.attach(dyn, interval=n)`` analyses ``dyn.atoms``
  every ``n`` steps of a running dynamics (``self.reader`` is None, the
  frame index is the step); :meth:`Analysis.observe` analyses one
  configuration by hand; :meth:`Analysis.conclude` then fills ``results``.
"""

import itertools
import os

from ..errors import InputError

__all__ = ["Results", "Analysis", "is_h5md_path"]


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


class Analysis:
    """Base of analyses over frames, offline (a trajectory) or online (a running dynamics).

    Parameters
    ----------
    trajectory : path, H5MDReader, or sequence/iterable of ase.Atoms, optional
        See the module docstring; None for an analysis used online only.

    Attributes
    ----------
    results : Results
        Filled by :meth:`run` (offline) or :meth:`conclude` (online).
    reader : H5MDReader or None
        The open reader while :meth:`run` walks an H5MD trajectory.
    frames : list of int
        Indices of the frames analysed (online: the dynamics' step numbers).
    """

    def __init__(self, trajectory=None):
        self._trajectory = trajectory
        self.reader = None
        self.results = Results()
        self.frames = []
        self._prepared = False

    # -- to implement ----------------------------------------------------------
    def _prepare(self):
        """Called once before the first frame (``self.reader`` is set for H5MD files)."""

    def _single_frame(self, atoms):
        """Analyse one frame (``self._frame_index``: its index in the trajectory, or the step online)."""
        raise NotImplementedError

    def _conclude(self):
        """Called once after the last frame: fill ``self.results``."""

    # -- offline -----------------------------------------------------------------
    def _iter_frames(self, start, stop, step):
        traj = self._trajectory
        if traj is None:
            raise InputError("trajectory", None, "a trajectory to run over (or use the analysis online: "
                             "attach(dyn) / observe(atoms))")
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

    def _n_frames(self, start, stop, step):
        """The number of frames :meth:`run` will visit, or None when the trajectory is only iterable."""
        traj = self._trajectory
        n = getattr(traj, "n_frames", None)
        if n is None and hasattr(traj, "__len__") and not isinstance(traj, (str, bytes)):
            n = len(traj)
        return None if n is None else len(range(*slice(start, stop, step).indices(n)))

    def run(self, start=None, stop=None, step=None, progress=False):
        """Analyse frames ``start:stop:step`` (Python slice semantics); returns ``self``.

        ``progress``: a tqdm bar over the frames.
        """
        self._reset()
        frames = self._iter_frames(start, stop, step)
        bar = None
        if progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=self._n_frames(start, stop, step), desc=type(self).__name__, unit="frame",
                       leave=False)
        try:
            for i, atoms in frames:
                self.observe(atoms, i)
                if bar is not None:
                    bar.update(1)
        finally:
            frames.close()
            if bar is not None:
                bar.close()
        return self.conclude()

    # -- online ------------------------------------------------------------------
    def _reset(self):
        self.results = Results()
        self.frames = []
        self._prepared = False

    def observe(self, atoms, index=None):
        """Analyse one configuration now (``index``: its frame index; default the count so far)."""
        if not self._prepared:
            self._prepare()
            self._prepared = True
        i = len(self.frames) if index is None else index
        self._frame_index = i
        self.frames.append(i)
        self._single_frame(atoms)

    def attach(self, dyn, interval=1):
        """Analyse ``dyn.atoms`` every ``interval`` steps of ``dyn`` (an ASE observer; the frame index is
        ``dyn.nsteps``); call :meth:`conclude` after the run.  Returns ``self``."""
        self._reset()
        dyn.attach(self._observe_dyn, interval, dyn)
        return self

    def _observe_dyn(self, dyn):
        self.observe(dyn.atoms, int(dyn.nsteps))

    def conclude(self):
        """Fill ``results`` from the frames analysed so far; returns ``self``."""
        if not self._prepared:
            raise InputError("trajectory", "no frames", "at least one frame to analyse")
        self._conclude()
        return self
