"""Write an ASE run as H5MD 1.1 (the layout: :mod:`clusterdyn.io.h5md_format`).

:class:`H5MDWriter` is an observer for any ASE ``MolecularDynamics``
(``dyn.attach(writer, interval=n)``), with the run's metadata under
``/parameters`` (:mod:`clusterdyn.io.metadata`).
"""

import getpass
import warnings

import numpy as np

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.io._common import clusterdyn_version, dumps
from clusterdyn.io.h5md_format import (DEFAULT_OBSERVABLE_FUNCS, PAIRS, RESERVED, STANDARD_ARRAYS, TRAJ, UNITS,
                                       calc_property, chunks, fill_value, h5group, is_h5md_file, storage_dtype)
from clusterdyn.io.metadata import run_metadata, write_metadata

__all__ = ["H5MDWriter"]


def _split_source(argument, name, spec):
    """``spec`` or ``(spec, unit)`` -> (spec, unit or None)."""
    if isinstance(spec, tuple):
        if len(spec) != 2 or not isinstance(spec[1], str):
            raise InputError(f"{argument}[{name!r}]", spec,
                             "a source or a (source, unit string) pair")
        return spec
    return spec, None


def _check_name(argument, name):
    if not isinstance(name, str) or not name or "/" in name or name in (".", ".."):
        raise InputError(argument, name, "a non-empty name without '/'")


class H5MDWriter:
    """Write an ASE simulation to an H5MD 1.1 file that MDAnalysis reads.

    Attach it to any ASE dynamics, ``dyn.attach(writer, interval=n)``; each
    call writes one frame of the Atoms it was built with.  The layout is in
    the module docstring.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; use the ``.h5md`` extension so that
        ``MDAnalysis.Universe(path)`` recognises it without a topology.
    atoms : ase.Atoms
        The Atoms being simulated (the same object, not a copy).
    mode : {'w', 'a'}
        ``'w'`` creates or overwrites; ``'a'`` appends to an existing file
        written with the same layout (creates it when missing).
    dyn : ase.md.md.MolecularDynamics, optional
        The dynamics; each frame gets ``step = dyn.nsteps`` and
        ``time = dyn.get_time()``, and ``dyn.todict()`` is stored as its
        description.  Without it the writer counts frames (continuing after
        the last stored step in mode ``'a'``) and ``time = step * timestep``.
    timestep : float, optional
        ASE time units per counted step when ``dyn`` is None.  Default: 1 ps
        (MDAnalysis' own default frame spacing).
    observables : dict, optional
        Scalar or small-vector observables ``{name: callable(atoms)}`` or
        ``{name: (callable(atoms), unit_string)}``, stored as returned under
        ``/observables/<name>``.  They are added to the default set:
        ``dt`` (frame spacing, 'ps') and ``kinetic_energy`` always,
        ``potential_energy`` and ``total_energy`` when a calculator is
        attached (energies in 'kJ mol-1'); a value of None removes a default.
    per_particle : dict, optional
        Extra per-particle series ``{name: callable(atoms) -> (N, ...) array}``
        or ``{name: 'arrayname'}`` (an ``atoms.arrays`` key), optionally as
        ``(source, unit_string)``, stored as returned under
        ``particles/trajectory/<name>`` (MDAnalysis skips them).  Every
        ``atoms.arrays`` entry other than positions, numbers, momenta and
        masses (``id``, ``material``, ``grain``, ``radius``, ...) is written
        by default under its own name; a value of None removes one.
    compression : {'gzip', 'lzf', None} or int
        HDF5 filter for per-particle values (an int is a gzip level 0-9),
        applied after HDF5's byte-shuffle filter.
    sort_by_id : bool
        Write rows in increasing ``atoms.arrays['id']`` order when that
        array exists.
    restart_step : int, optional
        Mode ``'a'`` only: drop the stored frames with ``step >
        restart_step`` before appending (restarting from a checkpoint taken
        at that step), see :meth:`truncate_after_step`.
    parameters : dict, optional
        Scene parameters, stored as JSON text in ``/parameters/scene``.
    author : str, optional
        Stored in ``/h5md/author``; default: the login name.
    wrap : bool
        Write periodic coordinates wrapped into the box with an ``image``
        series (default), or as ``atoms.positions`` holds them.
    pair_state : None, False or callable, optional
        Linked pairs written on every frame under
        ``/connectivity/linked_pairs``: a ``callable(atoms) -> (P, 2)``
        array of particle ids; None (default) takes
        ``atoms.calc.state.linked_pairs()`` when the calculator's state has
        it (MCA), else writes none; False writes none.

    Notes
    -----
    A frame is written after all its values have been computed, then the
    file is flushed.  A frame whose step equals the last stored step
    replaces it (a restarted run re-emitting its first frame does not
    duplicate it); a step below the last stored one raises
    :class:`~clusterdyn.errors.InputError`, since H5MD steps must increase.

    The run's metadata (calculator, material table, r0, damping, drives and
    walls, units) goes under ``/parameters`` when the writer is made and
    again at its first frame (:meth:`write_metadata`), so that
    :class:`H5MDReader` can rebuild the calculator and analyses can run from
    the file alone.  Masses are stored once; a frame whose masses differ from
    the first frame's raises :class:`~clusterdyn.errors.InputError`.

    Forces come from the calculator's result cache when it is valid
    (``calc.get_property('forces', atoms, allow_calculation=False)``), as
    ASE's own trajectory writer does, and are the raw calculator forces
    (constraints not applied).  Without a calculator at the first frame no
    ``force`` group is written.
    """

    def __init__(self, path, atoms, *, mode="w", dyn=None, timestep=None,
                 observables=None, per_particle=None, compression="gzip",
                 sort_by_id=True, restart_step=None, parameters=None, author=None, wrap=True,
                 pair_state=None):
        import h5py

        if mode not in ("w", "a"):
            raise InputError("mode", mode, "'w' (create/overwrite) or 'a' (append)")
        if not (compression is None or compression in ("gzip", "lzf")
                or (isinstance(compression, (int, np.integer))
                    and not isinstance(compression, bool) and 0 <= compression <= 9)):
            raise InputError("compression", compression, "'gzip', 'lzf', None or a gzip level 0-9")
        if observables is not None and not isinstance(observables, dict):
            raise InputError("observables", observables, "a dict {name: callable(atoms)}")
        if per_particle is not None and not isinstance(per_particle, dict):
            raise InputError("per_particle", per_particle,
                             "a dict {name: callable(atoms) or atoms.arrays key}")
        if restart_step is not None and mode != "a":
            raise InputError("restart_step", restart_step, "None unless mode='a'")
        if timestep is not None and not (np.isfinite(timestep) and timestep > 0):
            raise InputError("timestep", timestep, "a finite time > 0 in ASE units")
        if len(atoms) == 0:
            raise InputError("atoms", atoms, "at least one particle")
        if not (pair_state is None or pair_state is False or callable(pair_state)):
            raise InputError("pair_state", pair_state,
                             "None (the linked pairs of an MCA calculator's state, if any), False "
                             "(none) or a callable(atoms) -> (P, 2) particle ids")

        self.path = str(path)
        self.atoms = atoms
        self.dyn = dyn
        self.timestep = units.PS if timestep is None else float(timestep)
        self.compression = compression
        self.sort_by_id = bool(sort_by_id)
        self.wrap = bool(wrap) and bool(np.any(atoms.pbc))
        self.natoms = len(atoms)
        self._user_observables = dict(observables or {})
        self._user_per_particle = dict(per_particle or {})
        for name, spec in self._user_observables.items():
            _check_name("observables", name)
            if spec is not None:
                func, _ = _split_source("observables", name, spec)
                if not callable(func):
                    raise InputError(f"observables[{name!r}]", func, "a callable(atoms) -> float")
        for name, spec in self._user_per_particle.items():
            _check_name("per_particle", name)
            if name in RESERVED:
                raise InputError("per_particle", name, f"a name other than {RESERVED}")
            if spec is not None:
                src, _ = _split_source("per_particle", name, spec)
                if not (callable(src) or isinstance(src, str)):
                    raise InputError(f"per_particle[{name!r}]", src,
                                     "a callable(atoms) -> (N, ...) array or an atoms.arrays key")
                if isinstance(src, str) and src not in atoms.arrays:
                    raise InputError(f"per_particle[{name!r}]", src,
                                     f"a key of atoms.arrays {sorted(atoms.arrays)}")

        self._pbc = np.array(atoms.pbc, dtype=bool)
        #: where the cell goes: box/edges with a periodic axis (H5MD), else box/cell (readers then
        #: see an open box; MDAnalysis applies no minimum image)
        self._box_key = "edges" if self._pbc.any() else "cell"
        self._pair_state_arg = pair_state
        self._mass_fixed = True  # masses stored once (time-independent); files before: per frame
        self._mass_ref = None
        self._ids0 = None          # sorted ids of the first frame: the rows of every frame
        self._layout = None      # set on the first frame (mode 'w') or from the file ('a')
        self._warned = set()

        existing = mode == "a" and is_h5md_file(self.path)
        if mode == "a" and not existing:
            import os
            if os.path.exists(self.path):
                raise InputError("path", self.path, "an H5MD file written by clusterdyn to append to",
                                 hint="file exists but has no particles/trajectory")
        self._file = h5py.File(self.path, "a" if existing else "w")
        try:
            if existing:
                self._open_existing(restart_step)
            else:
                self._write_header(author)
            if parameters is not None:
                self._write_json("scene", parameters)
            if dyn is not None and hasattr(dyn, "todict"):
                try:
                    self.set_description(dyn.todict())
                except Exception:  # pragma: no cover - a todict that fails is not fatal
                    pass
            try:
                self.write_metadata()
            except InputError:
                pass             # written again at the first frame, where an error is raised
            self._file.flush()
        except BaseException:
            self._file.close()
            raise

    # ------------------------------------------------------------------ setup
    def _write_header(self, author):
        f = self._file
        h = f.require_group("h5md")
        h.attrs["version"] = np.array([1, 1], dtype=np.int32)
        if author is None:
            try:
                author = getpass.getuser()
            except Exception:
                author = "unknown"
        h.require_group("author").attrs["name"] = str(author)
        c = h.require_group("creator")
        c.attrs["name"] = "clusterdyn"
        c.attrs["version"] = clusterdyn_version()
        traj = f.require_group(TRAJ)
        box = traj.require_group("box")
        box.attrs["dimension"] = 3
        box.attrs["boundary"] = ["periodic" if p else "none" for p in self._pbc]
        self._nframes = 0
        self._last_step = None

    def _open_existing(self, restart_step):
        f = self._file
        traj = f[TRAJ]
        if "position" not in traj:       # created but no frame written yet: start afresh
            self._nframes = 0
            self._last_step = None
            if restart_step is not None:
                self.truncate_after_step(restart_step)
            return
        n = traj["position/value"].shape[1]
        if n != self.natoms:
            # fewer particles than stored: a run that removes particles (its dynamics has a region
            # of interest, or the file already has removed rows)
            removing = getattr(self.dyn, "region", None) is not None or (
                "id" in traj and traj["id/value"].shape[0] > 0 and bool(np.any(traj["id/value"][-1] < 0)))
            if not (self.natoms < n and removing and self.sort_by_id and "id" in self.atoms.arrays):
                raise InputError("atoms", f"{self.natoms} particles",
                                 f"{n} particles, as stored in {self.path}", hint="cannot append")
            self.natoms = n        # particles were removed: rows by id, fill values for the others
        if "id" in traj and traj["id/value"].shape[0] > 0:
            self._ids0 = np.sort(np.asarray(traj["id/value"][0], dtype=np.int64))
        boundary = [b.decode() if isinstance(b, bytes) else str(b)
                    for b in traj["box"].attrs["boundary"]]
        pbc = np.array([b == "periodic" for b in boundary])
        if not np.array_equal(pbc, self._pbc):
            raise InputError("atoms.pbc", self._pbc.tolist(),
                             f"{pbc.tolist()} as stored in {self.path}", hint="cannot append")
        self._step_ds = traj["position/step"]
        self._time_ds = traj["position/time"]
        self._nframes = int(self._step_ds.shape[0])
        self._last_step = int(self._step_ds[-1]) if self._nframes else None
        self._mass_fixed = "mass" in traj and not isinstance(traj["mass"], h5group())
        if self._mass_fixed:
            self._mass_ref = np.asarray(traj["mass"][()], dtype=np.float64)
        # the layout stored in the file
        self._box_key = "edges" if "edges" in traj["box"] or (
            "cell" not in traj["box"] and self._pbc.any()) else "cell"
        layout = {"edges": self._box_key in traj["box"],
                  "particles": [k for k in traj if k != "box" and isinstance(traj[k], h5group())
                                and "value" in traj[k]],
                  "observables": list(f["observables"]) if "observables" in f else [],
                  "pairs": PAIRS in f}
        self._file_layout = layout
        if restart_step is not None:
            self.truncate_after_step(restart_step)

    def _write_json(self, name, obj):
        g = self._file.require_group("parameters")
        if name in g:
            del g[name]
        g.create_dataset(name, data=dumps(obj))

    def set_description(self, description):
        """Store ``description`` (e.g. ``dyn.todict()``) as JSON in ``/parameters/dynamics``.

        Parameters
        ----------
        description : dict
            JSON-able mapping; numpy values are converted.
        """
        self._write_json("dynamics", description)
        self._file.flush()

    def write_metadata(self):
        """Store the run's metadata under ``/parameters`` (see :mod:`clusterdyn.io.metadata`).

        Called when the writer is made and again at its first frame (so a
        calculator or constraints attached in between are described): the
        calculator and its material table, the dynamics' damping, the
        constraints and drives, and the unit system.
        """
        write_metadata(self._file, run_metadata(self.atoms, self.dyn))
        self._file.flush()

    # --------------------------------------------------------------- sources
    def _observable_specs(self, atoms):
        specs = {"dt": (None, UNITS["time"])}      # filled in by write()
        specs["kinetic_energy"] = DEFAULT_OBSERVABLE_FUNCS["kinetic_energy"]
        if atoms.calc is not None and "energy" in getattr(atoms.calc, "implemented_properties",
                                                          ("energy",)):
            specs["potential_energy"] = DEFAULT_OBSERVABLE_FUNCS["potential_energy"]
            specs["total_energy"] = DEFAULT_OBSERVABLE_FUNCS["total_energy"]
        for name, spec in self._user_observables.items():
            if spec is None:
                specs.pop(name, None)
            else:
                specs[name] = _split_source("observables", name, spec)
        return specs

    def _particle_specs(self, atoms):
        specs = {}
        for name in atoms.arrays:
            if name in STANDARD_ARRAYS:
                continue
            if name in RESERVED:
                raise InputError("atoms.arrays", name,
                                 f"array names other than {RESERVED}",
                                 hint="rename it or drop it with per_particle={name!r: None}")
            if atoms.arrays[name].dtype.kind not in "fiubc":
                if name not in self._user_per_particle:
                    self._warn_once(("array", name),
                                    f"H5MDWriter: atoms.arrays[{name!r}] has dtype "
                                    f"{atoms.arrays[name].dtype}; not written (H5MD series "
                                    "are numeric)")
                continue
            specs[name] = (name, None)
        for name, spec in self._user_per_particle.items():
            if spec is None:
                specs.pop(name, None)
            else:
                specs[name] = _split_source("per_particle", name, spec)
        return specs

    def _make_layout(self, atoms):
        cell = np.asarray(atoms.cell[:], dtype=np.float64)
        has_force = atoms.calc is not None and "forces" in getattr(
            atoms.calc, "implemented_properties", ("forces",))
        return {"edges": bool(np.any(cell != 0.0)),
                "force": has_force,
                "image": self.wrap,
                "particles": self._particle_specs(atoms),
                "observables": self._observable_specs(atoms),
                "pairs": self._pair_source(atoms)}

    def _pair_source(self, atoms):
        """callable(atoms) -> (P, 2) ids of linked pairs, or None (see ``pair_state``)."""
        arg = self._pair_state_arg
        if arg is False:
            return None
        if callable(arg):
            return arg
        # duck-typed: an MCA calculator's state exposes linked_pairs()
        if callable(getattr(getattr(atoms.calc, "state", None), "linked_pairs", None)):
            return lambda a: a.calc.state.linked_pairs()
        return None

    def _check_layout_against_file(self, layout):
        fl = self._file_layout
        want_p = {"position", "velocity", "species"} | set(layout["particles"])
        if not self._mass_fixed:
            want_p.add("mass")
        if layout["force"]:
            want_p.add("force")
        if layout["image"]:
            want_p.add("image")
        have_p = set(fl["particles"])
        problems = []
        if want_p != have_p:
            if want_p - have_p:
                problems.append(f"per-particle series not in the file: {sorted(want_p - have_p)}")
            if have_p - want_p:
                problems.append(f"series in the file this writer would not write: "
                                f"{sorted(have_p - want_p)}")
        want_o, have_o = set(layout["observables"]), set(fl["observables"])
        if want_o != have_o:
            if want_o - have_o:
                problems.append(f"observables not in the file: {sorted(want_o - have_o)}")
            if have_o - want_o:
                problems.append(f"observables in the file this writer would not write: "
                                f"{sorted(have_o - want_o)}")
        if (layout["pairs"] is not None) != fl["pairs"]:
            problems.append("linked pairs (connectivity) " + (
                "missing from the file" if layout["pairs"] is not None
                else "in the file but this writer has no pair state"))
        if layout["edges"] != fl["edges"]:
            problems.append("box/edges " + ("missing from the file" if layout["edges"]
                                            else "in the file but the cell is zero"))
        if problems:
            raise InputError("mode", "a", f"the same layout as {self.path}",
                             hint="; ".join(problems)
                             + "; pass per_particle/observables with None values to drop series, "
                               "or write a new file")

    # ------------------------------------------------------------ datasets
    def _new_value(self, group, name, sample, unit=None, compress=True):
        """Create ``group/name/value`` shaped (0, *sample.shape) and link step/time."""
        sample = np.asarray(sample)
        dtype = storage_dtype(sample)
        g = group.require_group(name)
        kw = {}
        if compress and self.compression is not None and sample.ndim >= 1:
            kw["compression"] = self.compression
            # byte shuffle first: float64 coordinates then compress by ~12% instead of ~5%,
            # and gzip runs ~30% faster (a standard HDF5 filter, read by every HDF5 reader)
            kw["shuffle"] = True
        ds = g.create_dataset("value", shape=(0,) + sample.shape,
                              maxshape=(None,) + sample.shape, dtype=dtype,
                              chunks=chunks(sample.shape, dtype.itemsize) if sample.ndim
                              else (1024,), fillvalue=fill_value(dtype), **kw)
        if unit is not None:
            ds.attrs["unit"] = unit
        if "step" not in g:
            g["step"] = self._step_ds
        if "time" not in g:
            g["time"] = self._time_ds
        return ds

    def _create_datasets(self, frame):
        f = self._file
        traj = f[TRAJ]
        pos = traj.require_group("position")
        self._step_ds = pos.create_dataset("step", shape=(0,), maxshape=(None,),
                                           dtype=np.int64, chunks=(1024,))
        self._time_ds = pos.create_dataset("time", shape=(0,), maxshape=(None,),
                                           dtype=np.float64, chunks=(1024,))
        self._time_ds.attrs["unit"] = UNITS["time"]
        self._new_value(traj, "position", frame["position"], UNITS["length"])
        if "edges" in frame:
            self._new_value(traj["box"], self._box_key, frame["edges"], UNITS["length"], compress=False)
            if self._box_key == "cell":
                traj["box/cell"].attrs["description"] = (
                    "the Atoms' cell of an open box (every boundary 'none'): clusterdyn keeps it here, "
                    "not in box/edges, so that readers (MDAnalysis) see no periodic box")
        self._new_value(traj, "velocity", frame["velocity"], UNITS["velocity"])
        if "force" in frame:
            self._new_value(traj, "force", frame["force"], UNITS["force"])
        if "image" in frame:
            self._new_value(traj, "image", frame["image"])
        self._new_value(traj, "species", frame["species"])
        if self._mass_fixed:     # time-independent H5MD element: one (N,) dataset
            if "mass" in traj:
                del traj["mass"]
            traj.create_dataset("mass", data=frame["mass"]).attrs["unit"] = UNITS["mass"]
            self._mass_ref = np.array(frame["mass"])
        else:
            self._new_value(traj, "mass", frame["mass"], UNITS["mass"])
        if "pairs" in frame:
            self._new_pairs(frame["pairs"])
        for name, (_, unit) in self._layout["particles"].items():
            self._new_value(traj, name, frame["particles"][name], unit)
        if self._layout["observables"]:
            obs = f.require_group("observables")
            for name, (_, unit) in self._layout["observables"].items():
                self._new_value(obs, name, frame["observables"][name], unit, compress=False)

    def _new_pairs(self, pairs):
        """``/connectivity/linked_pairs``: (F, P, 2) int64 ids padded with -1, P grows."""
        f = self._file
        g = f.require_group(PAIRS)
        width = max(1024, min(len(pairs), 65536))
        kw = {}
        if self.compression is not None:
            kw = {"compression": self.compression, "shuffle": True}
        ds = g.create_dataset("value", shape=(0, len(pairs), 2), maxshape=(None, None, 2),
                              dtype=np.int64, chunks=(1, width, 2), fillvalue=-1, **kw)
        ds.attrs["fill_value"] = -1
        g.attrs["particles_group"] = f[TRAJ].ref
        g.attrs["values"] = "id"       # entries are particle ids (particles/trajectory/id)
        g["step"] = self._step_ds
        g["time"] = self._time_ds

    def _value_datasets(self):
        f = self._file
        traj = f[TRAJ]
        out = [traj[k]["value"] for k in traj if k != "box" and isinstance(traj[k], h5group())
               and "value" in traj[k]]
        for key in ("edges", "cell"):
            if key in traj["box"] and isinstance(traj["box"][key], h5group()):
                out.append(traj["box"][key]["value"])
        if PAIRS in f:
            out.append(f[PAIRS]["value"])
        if "observables" in f:
            out += [f["observables"][k]["value"] for k in f["observables"]
                    if "value" in f["observables"][k]]
        return out

    def _resize(self, n):
        for ds in self._value_datasets():
            ds.resize(n, axis=0)
        self._step_ds.resize(n, axis=0)
        self._time_ds.resize(n, axis=0)
        self._nframes = n
        self._last_step = int(self._step_ds[n - 1]) if n else None

    def truncate_after_step(self, step):
        """Drop every stored frame with ``step`` greater than ``step``.

        Call it (or pass ``restart_step=``) before appending the frames of a
        run restarted from a checkpoint taken at ``step``, so that the file
        holds no frame twice.

        Parameters
        ----------
        step : int
            The last integration step to keep.

        Returns
        -------
        int
            Number of frames dropped.
        """
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)):
            raise InputError("step", step, "an integer integration step")
        if self._nframes == 0:
            return 0
        steps = self._step_ds[:]
        keep = int(np.searchsorted(steps, int(step), side="right"))
        dropped = self._nframes - keep
        if dropped:
            self._resize(keep)
            self._file.flush()
        return dropped

    # --------------------------------------------------------------- frames
    def _sort_order(self, atoms):
        if not self.sort_by_id or "id" not in atoms.arrays:
            return None
        ids = atoms.arrays["id"]
        if ids.ndim != 1:
            raise InputError("atoms.arrays['id']", f"shape {ids.shape}", "shape (N,)")
        d = np.diff(ids)
        if np.all(d > 0):
            return None
        order = np.argsort(ids, kind="stable")
        if np.any(np.diff(ids[order]) == 0):
            dup = ids[order][np.flatnonzero(np.diff(ids[order]) == 0)[0]]
            raise InputError("atoms.arrays['id']", f"duplicate id {dup}",
                             "unique particle ids (needed by sort_by_id=True)")
        return order

    def _warn_once(self, key, msg):
        if key not in self._warned:
            self._warned.add(key)
            warnings.warn(msg, RuntimeWarning, stacklevel=3)

    def _collect(self, atoms):
        """All values of one frame, rows in output order, in file units."""
        n = len(atoms)
        dest = None                # rows of the present particles when some were removed
        if n == self.natoms and self._ids0 is None and self.sort_by_id and "id" in atoms.arrays:
            self._ids0 = np.sort(np.asarray(atoms.arrays["id"], dtype=np.int64))
        if n != self.natoms:
            if n > self.natoms or self._ids0 is None or "id" not in atoms.arrays:
                raise InputError("atoms", f"{n} particles",
                                 f"{self.natoms} particles (H5MD frames need a fixed count; fewer only when "
                                 "particles with an 'id' array were removed and sort_by_id=True)")
            ids = np.asarray(atoms.arrays["id"], dtype=np.int64)
            dest = np.searchsorted(self._ids0, np.sort(ids))
            if np.any(dest >= self.natoms) or not np.array_equal(self._ids0[np.minimum(dest, self.natoms - 1)],
                                                                 np.sort(ids)):
                raise InputError("atoms.arrays['id']", "ids not in the first frame",
                                 "the ids of particles present in the first frame (removed ones are filled)")
        if not np.array_equal(np.asarray(atoms.pbc, dtype=bool), self._pbc):
            raise InputError("atoms.pbc", atoms.pbc.tolist(),
                             f"{self._pbc.tolist()} as when the writer was created")
        layout = self._layout
        order = self._sort_order(atoms)

        def rows(a):
            a = np.asarray(a)
            a = a if order is None else a[order]
            if dest is None:
                return a
            full = np.full((self.natoms,) + a.shape[1:], fill_value(a.dtype), dtype=a.dtype)
            full[dest] = a
            return full

        pos = np.asarray(atoms.positions, dtype=np.float64)
        if layout["image"]:
            # H5MD images: wrapped position + image @ box = unwrapped position
            img = np.floor(np.linalg.solve(np.asarray(atoms.cell[:]).T, pos.T).T)
            img[:, ~np.asarray(atoms.pbc, dtype=bool)] = 0.0
            pos = pos - img @ np.asarray(atoms.cell[:], dtype=np.float64)
        frame = {"position": rows(pos),
                 "velocity": rows(atoms.get_velocities()) * units.VEL_TO_A_PER_PS,
                 "species": rows(atoms.numbers),
                 "mass": rows(atoms.get_masses()).astype(np.float64)}
        if layout["image"]:
            frame["image"] = rows(img.astype(np.int32))
        if layout["edges"]:
            frame["edges"] = np.array(atoms.cell[:], dtype=np.float64)
        elif np.any(np.asarray(atoms.cell[:]) != 0.0):
            raise InputError("atoms.cell", atoms.cell.tolist(),
                             "a zero cell, as at the first frame (no box/edges stored)")
        if layout["force"]:
            if atoms.calc is None:
                self._warn_once("force", "H5MDWriter: atoms has no calculator any more; "
                                         "writing NaN forces")
                frame["force"] = np.full((n, 3), np.nan)
            else:
                frame["force"] = rows(calc_property(atoms, "forces")) * units.FORCE_TO_KJMOL_A
        parts = {}
        for name, (src, _) in layout["particles"].items():
            if isinstance(src, str):
                if src not in atoms.arrays:
                    raise InputError(f"per_particle[{name!r}]", src,
                                     f"a key of atoms.arrays {sorted(atoms.arrays)}",
                                     hint="the array disappeared during the run")
                val = atoms.arrays[src]
            else:
                val = src(atoms)
            val = np.asarray(val)
            if val.dtype.kind not in "fiubc":
                raise InputError(f"per_particle[{name!r}]", f"dtype {val.dtype}",
                                 "a numeric or boolean array",
                                 hint="drop it with per_particle={%r: None}" % name)
            if val.ndim == 0 or val.shape[0] != n:
                raise InputError(f"per_particle[{name!r}]", f"shape {val.shape}",
                                 f"an array of shape ({n}, ...)")
            parts[name] = rows(val)
        frame["particles"] = parts
        if layout["pairs"] is not None:
            pairs = np.asarray(layout["pairs"](atoms))
            if pairs.dtype.kind not in "iu" or pairs.ndim != 2 or pairs.shape[1] != 2:
                raise InputError("pair_state", f"array of dtype {pairs.dtype}, shape {pairs.shape}",
                                 "integer particle ids of shape (P, 2)")
            pairs = np.sort(pairs.astype(np.int64), axis=1)
            frame["pairs"] = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        obs = {}
        for name, (func, _) in layout["observables"].items():
            if func is None:                       # dt: set by write()
                obs[name] = np.float64(np.nan)
                continue
            if atoms.calc is None and name in ("potential_energy", "total_energy") \
                    and func is DEFAULT_OBSERVABLE_FUNCS[name][0]:
                self._warn_once(name, f"H5MDWriter: no calculator; writing NaN {name}")
                obs[name] = np.float64(np.nan)
                continue
            obs[name] = np.asarray(func(atoms))
        frame["observables"] = obs
        return frame

    def _check_shapes(self, frame):
        traj = self._file[TRAJ]
        items = [("position", frame["position"], traj), ("velocity", frame["velocity"], traj),
                 ("species", frame["species"], traj)]
        if not self._mass_fixed:
            items.append(("mass", frame["mass"], traj))
        if "force" in frame:
            items.append(("force", frame["force"], traj))
        if "image" in frame:
            items.append(("image", frame["image"], traj))
        items += [(k, v, traj) for k, v in frame["particles"].items()]
        if frame["observables"]:
            items += [(k, v, self._file["observables"]) for k, v in frame["observables"].items()]
        for name, val, group in items:
            want = group[name]["value"].shape[1:]
            if np.shape(val) != want:
                raise InputError(name, f"shape {np.shape(val)}",
                                 f"shape {want} as in the first frame")

    def write(self, *, step=None, time=None):
        """Write one frame of ``self.atoms``.

        Parameters
        ----------
        step : int, optional
            Integration step; default ``dyn.nsteps`` or the frame counter.
        time : float, optional
            Simulation time in ASE units; default ``dyn.get_time()`` or
            ``step * timestep``.

        Returns
        -------
        int
            Index of the frame written.
        """
        atoms = self.atoms
        if self._file is None:
            raise InputError("writer", self.path, "an open H5MDWriter", hint="it was closed")
        if step is None:
            if self.dyn is not None:
                step = int(self.dyn.nsteps)
            else:
                step = 0 if self._last_step is None else self._last_step + 1
        if time is None:
            time = self.dyn.get_time() if self.dyn is not None else step * self.timestep
        step = int(step)

        if self._layout is None:
            layout = self._make_layout(atoms)
            if hasattr(self, "_file_layout"):
                self._check_layout_against_file(layout)
            self.write_metadata()
            self._layout = layout
        frame = self._collect(atoms)
        present = ~np.isnan(frame["mass"])
        if self._mass_fixed and self._mass_ref is not None \
                and not np.array_equal(frame["mass"][present], self._mass_ref[present]):
            raise InputError("atoms masses", "changed since the first frame",
                             "fixed masses (stored once, as a time-independent H5MD element)",
                             hint="each row must be the same particle in every frame: give the "
                                  "Atoms an 'id' array (sort_by_id=True) if they are re-sorted")

        if self._last_step is not None and step < self._last_step:
            raise InputError("step", step, f"a step >= {self._last_step}, the last one stored",
                             hint="H5MD steps must increase; to restart from an earlier step use "
                                  "H5MDWriter(..., mode='a', restart_step=...) or "
                                  "truncate_after_step()")
        if not hasattr(self, "_step_ds"):
            self._create_datasets(frame)
        else:
            self._check_shapes(frame)

        if self._last_step is not None and step == self._last_step:
            i = self._nframes - 1        # same step again: replace, never duplicate
        else:
            i = self._nframes
            for ds in self._value_datasets():
                ds.resize(i + 1, axis=0)
        f = self._file
        traj = f[TRAJ]
        traj["position/value"][i] = frame["position"]
        traj["velocity/value"][i] = frame["velocity"]
        traj["species/value"][i] = frame["species"]
        if not self._mass_fixed:
            traj["mass/value"][i] = frame["mass"]
        if "pairs" in frame:
            ds = f[PAIRS]["value"]
            p = frame["pairs"]
            if len(p) > ds.shape[1]:
                ds.resize(len(p), axis=1)
            row = np.full((ds.shape[1], 2), -1, dtype=np.int64)
            row[:len(p)] = p
            ds[i] = row
        if "edges" in frame:
            traj["box"][self._box_key]["value"][i] = frame["edges"]
        if "force" in frame:
            traj["force/value"][i] = frame["force"]
        if "image" in frame:
            traj["image/value"][i] = frame["image"]
        for name, val in frame["particles"].items():
            traj[name]["value"][i] = val
        for name, val in frame["observables"].items():
            f["observables"][name]["value"][i] = val
        if i == self._nframes:
            self._step_ds.resize(i + 1, axis=0)
            self._time_ds.resize(i + 1, axis=0)
        self._step_ds[i] = step
        time_ps = float(time) * units.TIME_TO_PS
        self._time_ds[i] = time_ps
        if "dt" in self._layout["observables"] and self._layout["observables"]["dt"][0] is None:
            dt = f["observables/dt/value"]
            if i > 0:
                dt[i] = time_ps - float(self._time_ds[i - 1])
                if i == 1:
                    dt[0] = dt[1]
            else:                                  # provisional until the second frame
                dt[0] = (self.dyn.dt if self.dyn is not None and hasattr(self.dyn, "dt")
                         else self.timestep) * units.TIME_TO_PS
        self._nframes = i + 1
        self._last_step = step
        f.flush()
        return i

    __call__ = write

    @property
    def nframes(self):
        """Number of frames stored."""
        return self._nframes

    def close(self):
        """Flush and close the file (idempotent).  The file is closed even when the flush
        fails (a full disk): the error is raised after, once."""
        f, self._file = self._file, None
        if f is not None:
            try:
                f.flush()
            finally:
                f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
