"""Fragments of a run: one configuration (:func:`fragments`), a trajectory (:class:`FragmentAnalysis`)
or during a run (:class:`FragmentObserver`).

A fragment is a connected component of the bond graph (CD: pairs closer than
``b r0_ab``; MCA: linked pairs), found by
:class:`~clusterdyn.analysis.fragment_graph.FragmentFinder` (the bond rules and
the periodic treatment: :mod:`clusterdyn.analysis.fragment_graph`); the result
is a :class:`~clusterdyn.analysis.fragment_spectra.Fragments`.

Entry points: :func:`fragments` (one Atoms), :class:`FragmentAnalysis`
(every frame of an H5MD file or a list of Atoms, in the shape of
MDAnalysis' ``AnalysisBase``) and :class:`FragmentObserver` (during a run,
``dyn.attach(obs, interval=n)``; its :meth:`FragmentObserver.observables`
feed an H5MD writer).
"""

import numpy as np

from ..errors import InputError
from .base import Analysis, Results
from .fragment_graph import FragmentFinder, _bond_factor, _calc_parameter, _material_ids, _r0_per_material
from .fragment_spectra import G_MAX

__all__ = ["fragments", "FragmentAnalysis", "FragmentObserver"]


def fragments(atoms, b=None, *, r0=None, pairs=None, volumes=None, exclude=None):
    """Fragments (connected components of the bond graph) of one configuration.

    Parameters
    ----------
    atoms : ase.Atoms
        Open or periodic orthorhombic cell.  Masses and momenta are read;
        ``arrays['material']`` gives the material id (default all 0).
    b : float, optional
        Bond distance as a multiple of r0 (CD): particles closer than
        ``b r0_ab`` are bonded, ``r0_ab = (r0_a + r0_b)/2``.  Default: the
        cutoff ``rc`` of the Atoms' calculator (a
        :class:`~clusterdyn.calculators.ClusterDynamics`).  Not used with ``pairs``.
    r0 : float or sequence of float, optional
        Cluster size per material id, Angstrom.  Default
        ``atoms.info['cd_r0']`` (set by the builders), else the calculator's ``r0``.
    pairs : None, (i_p, j_p) arrays, MCA state, or callable
        None: CD bonds by distance.  Two int arrays of particle rows: the
        bonded pairs (each taken at its minimum image).  An MCA state
        (:class:`clusterdyn.mca.state.MCAState`): its linked pairs.  A
        callable ``pairs(atoms) -> (i_p, j_p)``.
    volumes : (N,) array or callable, optional
        Particle volumes, Angstrom^3.  Default: the MCA state's cell volumes
        (``omega_n``); for CD ``r0^3 / sqrt 2`` of the particle's material;
        else ``(2 radius)^3 / sqrt 2`` from ``arrays['radius']``.
    exclude : (N,) bool array or callable, optional
        Particles left out of every fragment (a piston, a wall layer); their
        label is -1.

    Returns
    -------
    Fragments

    Raises
    ------
    clusterdyn.errors.InputError
        No bond distance or r0 can be found, bad pair rows, a triclinic periodic cell.

    Examples
    --------
    >>> from clusterdyn.build import fcc_packing               # doctest: +SKIP
    >>> f = fragments(fcc_packing("Al", 10 * units.um), b=1.15)
    >>> f.n_fragments, f.spectrum()
    """
    return FragmentFinder(b, r0=r0, pairs=pairs, volumes=volumes, exclude=exclude).find(atoms)


def _frame_summary(f, g_max):
    return {"n_fragments": f.n_fragments,
            "largest": int(f.g.max()) if f.n_fragments else 0,
            "n_small": f.count(g_max),
            "small_mass_fraction": f.mass_fraction(g_max),
            "nbonds": f.nbonds}


class FragmentAnalysis(Analysis):
    """Fragments of every frame of a trajectory (:class:`~clusterdyn.analysis.base.Analysis`).

    Parameters
    ----------
    trajectory : str, os.PathLike, H5MDReader, sequence of ase.Atoms, or None
        An H5MD file (read with :class:`clusterdyn.io.H5MDReader`), an open
        reader, or a list of Atoms; None for online use only
        (``FragmentAnalysis(None, b=1.15).attach(dyn, interval=n)``, then
        :meth:`conclude` after the run: the same results over the steps taken).
    b, r0, pairs, volumes, exclude
        As :func:`fragments`.  For a file, ``b`` and ``r0`` default to the
        scene parameters stored in it (``/parameters/scene``: ``rc``, ``r0``)
        when the frames carry no calculator or ``cd_r0``; ``pairs`` may be a
        callable ``pairs(atoms) -> (i_p, j_p)`` evaluated per frame.
    g_max : int, default 10
        Fragments of at most ``g_max`` particles are counted as small.
    keep : bool, default True
        Keep every frame's :class:`Fragments` in ``results.fragments``
        (per-particle labels: 8 bytes per particle per frame).

    Attributes
    ----------
    results : Results
        After :meth:`run` (or :meth:`conclude` online), arrays over the analysed frames: ``frames``,
        ``steps``, ``times`` (ASE time), ``n_fragments``, ``largest`` (g of
        the largest fragment), ``n_small``, ``small_mass_fraction``,
        ``nbonds``, and ``fragments`` (list of :class:`Fragments`) with ``keep``.

    Examples
    --------
    >>> fa = FragmentAnalysis("run.h5md", b=1.15).run(step=10)   # doctest: +SKIP
    >>> fa.results.n_fragments, fa.results.fragments[-1].spectrum()
    """

    def __init__(self, trajectory, b=None, *, r0=None, pairs=None, volumes=None, exclude=None,
                 g_max=G_MAX, keep=True):
        is_path = isinstance(trajectory, (str, bytes)) or hasattr(trajectory, "__fspath__")
        if trajectory is not None and not (is_path or (hasattr(trajectory, "__len__")
                                                       and hasattr(trajectory, "__getitem__"))):
            raise InputError("trajectory", type(trajectory).__name__,
                             "an H5MD path, an H5MDReader, a sequence of ase.Atoms, or None (online use)")
        super().__init__(trajectory)
        self._pairs = pairs
        self.finder = FragmentFinder(b, r0=r0, pairs=pairs, volumes=volumes, exclude=exclude)
        self.g_max = int(g_max)
        self.keep = bool(keep)

    def _prepare(self):
        self._rows = []
        self._frags = []
        src = self.reader if self.reader is not None else self._trajectory
        params = getattr(src, "parameters", None) or {}
        self._file_b = params.get("rc") if isinstance(params, dict) else None
        self._file_r0 = params.get("r0") if isinstance(params, dict) else None
        meta = getattr(src, "metadata", None)
        calc = (meta or {}).get("calculator") if isinstance(meta, dict) else None
        if isinstance(calc, dict) and calc.get("rc") is not None:
            self._file_b = float(calc["rc"])          # the run's cutoff from the file's metadata
        self.finder.pairs = self._pairs
        if self._pairs is None and getattr(src, "has", {}).get("pairs"):
            self.finder.pairs = _file_pairs(src)      # MCA: the linked pairs stored on every frame

    def _single_frame(self, atoms):
        fin = self.finder
        b, r0 = fin.b, fin.r0
        if fin.pairs is None:
            if b is None and _calc_parameter(atoms, "rc") is None:
                fin.b = self._file_b
            if r0 is None and "cd_r0" not in atoms.info:
                fin.r0 = self._file_r0
        try:
            f = fin.find(atoms)
        finally:
            fin.b, fin.r0 = b, r0
        index = self._frame_index
        row = _frame_summary(f, self.g_max)
        row["frame"] = index
        row["step"] = atoms.info.get("step", index)
        row["time"] = atoms.info.get("time", np.nan)
        self._rows.append(row)
        if self.keep:
            self._frags.append(f)

    def _conclude(self):
        r = self.results
        cols = ("frame", "step", "time", "n_fragments", "largest", "n_small", "small_mass_fraction",
                "nbonds")
        names = ("frames", "steps", "times", "n_fragments", "largest", "n_small", "small_mass_fraction",
                 "nbonds")
        for c, name in zip(cols, names):
            r[name] = np.array([row[c] for row in self._rows])
        r["g_max"] = self.g_max
        if self.keep:
            r["fragments"] = self._frags


def _file_pairs(reader):
    """``pairs(atoms) -> (i_p, j_p)``: rows of the pairs linked on the frame ``atoms`` came from."""
    def pairs(atoms):
        ids = np.asarray(atoms.arrays["id"], dtype=np.int64)
        row = np.full(int(ids.max()) + 1, -1, np.int64)
        row[ids] = np.arange(len(ids))
        frame = atoms.info.get("frame")
        if frame is None:
            steps = np.asarray(reader.steps)
            frame = int(np.nonzero(steps == atoms.info["step"])[0][0])
        lp = reader.linked_pairs(frame)
        return row[lp[:, 0]], row[lp[:, 1]]
    return pairs


class FragmentObserver(Analysis):
    """Fragment counts during a run: ``dyn.attach(FragmentObserver(atoms, dyn=dyn), interval=n)``.

    Each call finds the fragments of ``atoms`` (:class:`FragmentFinder`) and
    records the step, time and counts.  :meth:`observables` gives the same
    counts as H5MD observables (``H5MDWriter(..., observables=obs.observables())``);
    a frame is analysed once even when both the observer and the writer ask.

    Parameters
    ----------
    atoms : ase.Atoms
        The Atoms being simulated (the same object).
    b, r0, pairs, volumes, exclude
        As :func:`fragments` (``pairs`` may be the run's MCA state).
    dyn : MolecularDynamics, optional
        Gives each record its step (``dyn.nsteps``) and time (``dyn.get_time()``).
    g_max : int, default 10
        Fragments of at most ``g_max`` particles are counted as small.
    keep : bool, default False
        Keep every analysed :class:`Fragments` in ``results.fragments``.

    Attributes
    ----------
    last : Fragments or None
        The latest analysis.
    results : Results
        Lists ``steps``, ``times``, ``n_fragments``, ``largest``, ``n_small``,
        ``small_mass_fraction``, ``nbonds`` (see :meth:`arrays`).
    """

    NAMES = ("n_fragments", "largest", "n_small", "small_mass_fraction", "nbonds")

    def __init__(self, atoms, b=None, *, r0=None, pairs=None, volumes=None, exclude=None, dyn=None,
                 g_max=G_MAX, keep=False):
        super().__init__(None)
        self.atoms = atoms
        self.dyn = dyn
        self.finder = FragmentFinder(b, r0=r0, pairs=pairs, volumes=volumes, exclude=exclude)
        self.g_max = int(g_max)
        self.keep = bool(keep)
        self.last = None
        self._key = None
        self._summary = None
        self._reset()
        # fail now, not at the first call, when no bond rule can be found
        if pairs is None:
            _bond_factor(atoms, b)
            if _r0_per_material(atoms, r0, int(_material_ids(atoms).max(initial=0)) + 1) is None:
                raise InputError("r0", None, "cluster sizes: r0= or Atoms from a clusterdyn builder "
                                             "(atoms.info['cd_r0'])")

    def _state_key(self, atoms):
        """What the fragments depend on that changes during a run: positions and MCA links."""
        linked = getattr(self.finder.pairs, "linked_p", None)
        return (atoms.positions.copy(), None if linked is None else np.array(linked))

    def _current(self, atoms=None):
        atoms = self.atoms if atoms is None else atoms
        key = self._state_key(atoms)
        if self._key is not None and all(
                (a is None and b is None) or (a is not None and b is not None and a.shape == b.shape
                                              and np.array_equal(a, b))
                for a, b in zip(key, self._key)):
            return self._summary
        f = self.finder.find(atoms)
        self.last = f
        self._summary = _frame_summary(f, self.g_max)
        self._key = key
        return self._summary

    def _reset(self):
        super()._reset()
        # the record grows with every call (it is the result: _conclude has nothing to add)
        self.results = Results(steps=[], times=[], fragments=[], **{k: [] for k in self.NAMES})

    def _single_frame(self, atoms):
        s = self._current(atoms)
        r = self.results
        r.steps.append(int(self.dyn.nsteps) if self.dyn is not None else len(r.steps))
        r.times.append(float(self.dyn.get_time()) if self.dyn is not None else np.nan)
        for k in self.NAMES:
            r[k].append(s[k])
        if self.keep:
            r.fragments.append(self.last)

    def __call__(self):
        """Analyse :attr:`atoms` now (``dyn.attach(obs, interval=n)``)."""
        self.observe(self.atoms, int(self.dyn.nsteps) if self.dyn is not None else None)

    def arrays(self):
        """The records as arrays: ``steps``, ``times`` (ASE time) and the counts."""
        return {k: np.asarray(v) for k, v in self.results.items() if k != "fragments"}

    def observables(self, names=("n_fragments", "largest", "n_small", "small_mass_fraction")):
        """``{name: callable(atoms)}`` for :class:`clusterdyn.io.H5MDWriter`'s ``observables``.

        Counts are dimensionless (no unit string): ``n_fragments``,
        ``largest`` (particles in the largest fragment), ``n_small``
        (fragments of at most ``g_max`` particles), ``small_mass_fraction``,
        ``nbonds``.
        """
        out = {}
        for name in names:
            if name not in self.NAMES:
                raise InputError("names", name, f"names among {self.NAMES}")
            out[f"fragments_{name}"] = (lambda a, _k=name: self._current(a)[_k])
        return out
