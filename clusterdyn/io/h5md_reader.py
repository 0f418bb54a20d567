"""Read H5MD files (ours or any with ``particles/<group>``) back as ASE Atoms in ASE units, with the
run's metadata (the layout: :mod:`clusterdyn.io.h5md_format`)."""

import numpy as np

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.io._common import open_h5_read, read_json_dataset
from clusterdyn.io.h5md_format import PAIRS, TO_ASE, h5group
from clusterdyn.io.metadata import calculator_from_metadata, materials_from_metadata, read_metadata

__all__ = ["H5MDReader", "read_h5md"]


def _unit_factor(kind, ds, path):
    unit = ds.attrs.get("unit")
    if unit is None:
        return 1.0
    if isinstance(unit, bytes):
        unit = unit.decode()
    try:
        return TO_ASE[kind][str(unit)]
    except KeyError:
        raise InputError(f"{ds.name} unit", str(unit), sorted(TO_ASE[kind]),
                         hint=f"in {path}") from None


class H5MDReader:
    """Read frames of an H5MD file (ours or any with ``particles/<group>``) as ASE Atoms.

    Besides the frames it gives the run's metadata (:attr:`metadata`), the
    material table (:meth:`materials`), a calculator rebuilt from the file
    (:meth:`calculator`), the particles held by drives (:meth:`drive_mask`)
    and, for MCA runs, the linked pairs of every frame (:meth:`linked_pairs`).

    Parameters
    ----------
    path : str or os.PathLike
        The H5MD file.  It is opened read-only without file locking, so a
        file still being written by a running simulation can be inspected.

    Attributes
    ----------
    n_frames : int
    n_particles : int
    steps : (F,) int64 ndarray
    times : (F,) float64 ndarray, ASE time units
    observables : list of str
        Names under ``/observables``.
    per_particle : list of str
        Per-particle series other than position, velocity, force, species,
        mass (e.g. ``id``, ``material``, ``grain``).

    Examples
    --------
    >>> with H5MDReader('run.h5md') as r:                  # doctest: +SKIP
    ...     atoms = r[-1]
    ...     steps, times, epot = r.get_observable('potential_energy')
    """

    def __init__(self, path):
        self.path = str(path)
        what = "an H5MD file"
        self._file = open_h5_read(self.path, what)
        try:
            if "particles" not in self._file or not len(self._file["particles"]):
                raise InputError("path", self.path, what, hint="no /particles group")
            self.group_name = "trajectory" if "trajectory" in self._file["particles"] \
                else list(self._file["particles"])[0]
            g = self._file["particles"][self.group_name]
            self._g = g
            self._elements = [k for k in g if k != "box" and isinstance(g[k], h5group())
                              and "value" in g[k]]
            # masses: one time-independent (N,) dataset, or per frame in older files
            self._mass_ds = g["mass"] if "mass" in g and not isinstance(g["mass"], h5group()) \
                else None
            self._meta = None
            self._mat_info = None
            first = next((k for k in ("position", "velocity", "force") if k in g), None)
            if first is None:
                if "h5md" not in self._file:
                    raise InputError("path", self.path, what,
                                     hint=f"particles/{self.group_name} has no position, "
                                          "velocity or force")
                self._first = None               # H5MD file created, no frame written yet
                self.n_frames = self.n_particles = 0
            else:
                self._first = g[first]
                self.n_frames = int(self._first["value"].shape[0])
                self.n_particles = int(self._first["value"].shape[1])
        except InputError:
            self._file.close()
            raise
        except (KeyError, OSError, ValueError) as exc:
            self._file.close()
            raise InputError("path", self.path, what, hint=f"unreadable: {exc}") from None

    # --------------------------------------------------------------- metadata
    @property
    def steps(self):
        g = self._first
        if g is None:
            return np.zeros(0, dtype=np.int64)
        if "step" in g:
            return np.asarray(g["step"][: self.n_frames], dtype=np.int64)
        return np.arange(self.n_frames, dtype=np.int64)

    @property
    def times(self):
        g = self._first
        if g is None:
            return np.zeros(0)
        if "time" not in g:
            return self.steps.astype(np.float64) * units.PS
        return np.asarray(g["time"][: self.n_frames], dtype=np.float64) \
            * _unit_factor("time", g["time"], self.path)

    @property
    def observables(self):
        f = self._file
        return list(f["observables"]) if "observables" in f else []

    @property
    def per_particle(self):
        return [k for k in self._elements
                if k not in ("position", "velocity", "force", "species", "mass", "image")]

    @property
    def has(self):
        """Which of position, velocity, force, species, mass, box edges are stored."""
        out = {k: k in self._elements
               for k in ("position", "velocity", "force", "species", "mass")}
        out["mass"] = out["mass"] or self._mass_ds is not None
        out["edges"] = "box" in self._g and ("edges" in self._g["box"] or "cell" in self._g["box"])
        out["pairs"] = PAIRS in self._file
        return out

    @property
    def pbc(self):
        if "box" not in self._g or "boundary" not in self._g["box"].attrs:
            return np.zeros(3, dtype=bool)
        b = self._g["box"].attrs["boundary"]
        return np.array([(x.decode() if isinstance(x, bytes) else str(x)) == "periodic"
                         for x in np.atleast_1d(b)], dtype=bool)

    @property
    def parameters(self):
        """Scene parameters stored by the writer (dict) or None."""
        return read_json_dataset(self._file.get("parameters"), "scene")

    @property
    def description(self):
        """Dynamics description (``dyn.todict()``) stored by the writer, or None."""
        return read_json_dataset(self._file.get("parameters"), "dynamics")

    @property
    def metadata(self):
        """The run's metadata (:func:`clusterdyn.io.metadata.read_metadata`), a dict.

        ``scene``, ``dynamics``, ``calculator``, ``materials`` (the material
        table), ``damping`` and ``J``, ``units``, ``constraints`` (drives and
        walls, with the ``ids`` they act on), ``creator``, ``version``;
        sections the file lacks are None.
        """
        if self._meta is None:
            self._meta = read_metadata(self._file)
        return self._meta

    def materials(self):
        """Material records of the stored material table, indexed by material id.

        Raises
        ------
        clusterdyn.errors.InputError
            The file has no material table (written without the run's metadata).
        """
        return materials_from_metadata(self.metadata, self.path)[1]

    def calculator(self):
        """A new ClusterDynamics with the stored rc, skin, n_table, attraction and material table.

        It gives the same forces, energies and virials on the stored frames as
        the run's calculator (to the round-off of the stored positions).

        Raises
        ------
        clusterdyn.errors.InputError
            The file lacks the calculator or material metadata, or the run's
            calculator was not a ClusterDynamics.
        """
        return calculator_from_metadata(self.metadata, self.path)

    def drive_mask(self, frame=0):
        """(N,) bool: the rows of ``frame`` that a stored constraint or drive acts on.

        Raises
        ------
        clusterdyn.errors.InputError
            The file has no constraint metadata, or it names particle ids and
            the file has no ``id`` series.
        """
        meta = self.metadata
        if meta["constraints"] is None:
            raise InputError("path", self.path, "an H5MD file with /parameters/constraints",
                             hint="missing /parameters/constraints, needed for the driven "
                                  "particles; the file was written without the run's metadata")
        i = self._index(frame)
        mask = np.zeros(self.n_particles, dtype=bool)
        for c in meta["constraints"]:
            ids = c.get("ids")
            if ids is None:
                continue
            if c.get("particles") == "row":
                mask[ids] = True
                continue
            if "id" not in self._elements:
                raise InputError("path", self.path, "an H5MD file with an 'id' series",
                                 hint="the stored constraints name particle ids")
            mask |= np.isin(self._g["id"]["value"][i], ids)
        return mask

    def linked_pairs(self, frame=-1):
        """(P, 2) int64 particle ids (i < j) of the pairs linked at ``frame`` (MCA pair state).

        Raises
        ------
        clusterdyn.errors.InputError
            The file holds no pair state (not an MCA run, or written before it was stored).
        """
        if PAIRS not in self._file:
            raise InputError("path", self.path, f"an H5MD file with /{PAIRS}",
                             hint=f"missing /{PAIRS} (the MCA pair state per frame): not an "
                                  "MCA run, or written before the pair state was stored")
        i = self._index(frame)
        row = np.asarray(self._file[PAIRS]["value"][i], dtype=np.int64)
        return row[row[:, 0] >= 0]

    def _material_info(self):
        """{info key: value} for frames: cd_materials/cd_r0 or mca_materials/mca_dim (cached)."""
        if self._mat_info is None:
            meta = self.metadata
            info = {}
            calc = meta.get("calculator") or {}
            if meta.get("materials") is not None:
                try:
                    names, _, r0 = materials_from_metadata(meta, self.path)
                except InputError:
                    names = r0 = None   # analysis asking for the calculator gets the error
                if names is not None and calc.get("class") == "ClusterDynamics" and r0 is not None:
                    info = {"cd_materials": names, "cd_r0": r0}
                elif names is not None and calc.get("class") == "MCA":
                    info = {"mca_materials": names}
                    if calc.get("dim") is not None:
                        info["mca_dim"] = int(calc["dim"])
            self._mat_info = info
        return self._mat_info

    @property
    def creator(self):
        h = self._file.get("h5md")
        if h is None or "creator" not in h:
            return None
        a = h["creator"].attrs
        return {k: (v.decode() if isinstance(v, bytes) else str(v)) for k, v in a.items()}

    def units(self):
        """``{series name: unit string}`` for every stored series that has one."""
        out = {}
        for k in self._elements:
            u = self._g[k]["value"].attrs.get("unit")
            if u is not None:
                out[k] = u.decode() if isinstance(u, bytes) else str(u)
        if self._mass_ds is not None and "unit" in self._mass_ds.attrs:
            u = self._mass_ds.attrs["unit"]
            out["mass"] = u.decode() if isinstance(u, bytes) else str(u)
        if self._first is not None and "time" in self._first \
                and "unit" in self._first["time"].attrs:
            out["time"] = str(self._first["time"].attrs["unit"])
        for k in self.observables:
            g = self._file["observables"][k]
            if isinstance(g, h5group()) and "value" in g and "unit" in g["value"].attrs:
                out[f"observables/{k}"] = str(g["value"].attrs["unit"])
        return out

    # ----------------------------------------------------------------- frames
    def _index(self, frame):
        n = self.n_frames
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) \
                or not -n <= frame < n:
            if not n:
                raise InputError("frame", frame, "an existing frame",
                                 hint=f"{self.path} has no frames yet")
            raise InputError("frame", frame, f"an integer in [{-n}, {n}) for {self.path}")
        return int(frame) % n

    def get_observable(self, name):
        """One observable over all frames, as stored.

        Returns
        -------
        steps : (F,) int64 ndarray
        times : (F,) float64 ndarray, ASE time units
        values : (F, ...) ndarray, in the unit of ``units()['observables/<name>']``
        """
        if name not in self.observables:
            raise InputError("name", name, f"one of {self.observables}")
        g = self._file["observables"][name]
        values = g["value"][:]
        steps = g["step"][:] if "step" in g else self.steps
        if "time" in g:
            times = g["time"][:] * _unit_factor("time", g["time"], self.path)
        else:
            times = self.times
        return np.asarray(steps), np.asarray(times), values

    def get_atoms(self, frame=-1):
        """Frame ``frame`` as :class:`ase.Atoms` in ASE units.

        Positions, velocities (via momenta), masses, numbers, cell, pbc and
        every extra per-particle series (``atoms.arrays``) of that frame;
        stored forces and ``potential_energy`` are attached through a
        :class:`~ase.calculators.singlepoint.SinglePointCalculator`.
        ``atoms.info`` gets ``step``, ``time`` (ASE units) and ``frame``,
        and the material table's ``cd_materials`` / ``cd_r0`` (or
        ``mca_materials`` / ``mca_dim``) when the file stores it.
        """
        from ase import Atoms
        from ase.calculators.singlepoint import SinglePointCalculator

        i = self._index(frame)
        g = self._g
        try:
            n = self.n_particles
            numbers = g["species"]["value"][i] if "species" in self._elements \
                else np.zeros(n, dtype=int)
            if "position" in self._elements:
                pos = g["position"]["value"][i].astype(np.float64) \
                    * _unit_factor("length", g["position"]["value"], self.path)
            else:
                pos = np.zeros((n, 3))
            cell = np.zeros((3, 3))
            key = "edges" if "box" in g and "edges" in g["box"] else "cell"
            if "box" in g and key in g["box"]:   # box/cell: clusterdyn's cell of an open box
                e = g["box"][key]
                if isinstance(e, h5group()):          # time-dependent box
                    ev, edges = e["value"], e["value"][i]
                else:                                  # fixed box
                    ev, edges = e, e[()]
                edges = np.asarray(edges, dtype=np.float64) * _unit_factor("length", ev, self.path)
                cell = np.diag(edges) if edges.shape == (3,) else edges
            if "image" in self._elements:          # back to unwrapped positions
                pos = pos + g["image"]["value"][i].astype(np.float64) @ cell
            atoms = Atoms(numbers=numbers, positions=pos, cell=cell, pbc=self.pbc)
            if self._mass_ds is not None:
                atoms.set_masses(np.asarray(self._mass_ds[()], dtype=np.float64)
                                 * _unit_factor("mass", self._mass_ds, self.path))
            elif "mass" in self._elements:
                atoms.set_masses(g["mass"]["value"][i].astype(np.float64)
                                 * _unit_factor("mass", g["mass"]["value"], self.path))
            if "velocity" in self._elements:
                vel = g["velocity"]["value"][i].astype(np.float64) \
                    * _unit_factor("velocity", g["velocity"]["value"], self.path)
                atoms.set_velocities(vel)
            for name in self.per_particle:
                if name in atoms.arrays:
                    continue
                val = g[name]["value"]
                if val.ndim >= 2 and val.shape[0] == self.n_frames and val.shape[1] == n:
                    atoms.new_array(name, val[i])
            results = {}
            if "force" in self._elements:
                results["forces"] = g["force"]["value"][i].astype(np.float64) \
                    * _unit_factor("force", g["force"]["value"], self.path)
            if "id" in atoms.arrays and np.any(atoms.arrays["id"] < 0):
                keep = atoms.arrays["id"] >= 0       # rows of particles removed from the run
                atoms = atoms[keep]
                if "forces" in results:
                    results["forces"] = results["forces"][keep]
            if "potential_energy" in self.observables:
                ov = self._file["observables"]["potential_energy"]
                if isinstance(ov, h5group()) and "value" in ov and ov["value"].shape[0] > i:
                    results["energy"] = float(ov["value"][i]) \
                        * _unit_factor("energy", ov["value"], self.path)
            if results:
                atoms.calc = SinglePointCalculator(atoms, **results)
            atoms.info["step"] = int(self.steps[i])
            atoms.info["time"] = float(self.times[i])
            atoms.info["frame"] = i
            for k, v in self._material_info().items():
                atoms.info[k] = list(v) if isinstance(v, list) else v
        except InputError:
            raise
        except (KeyError, OSError, ValueError, IndexError) as exc:
            raise InputError("path", self.path, "a readable H5MD file",
                             hint=f"frame {i}: {exc}") from None
        return atoms

    def __len__(self):
        return self.n_frames

    def __getitem__(self, frame):
        """One frame (an int) as Atoms, or a list of them for a slice or an ASE index string
        (``reader[::2]``, ``reader[':']``, ``reader['-3:']``)."""
        index = _index(frame)
        if isinstance(index, slice):
            return [self.get_atoms(i) for i in range(self.n_frames)[index]]
        return self.get_atoms(index)

    def __iter__(self):
        for i in range(self.n_frames):
            yield self.get_atoms(i)

    def close(self):
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _index(frame):
    """An int, or a slice for a slice or an ASE index string (``':'``, ``'::2'``, ``'-1'``)."""
    if isinstance(frame, str):
        from ase.io.formats import string2index
        try:
            return string2index(frame)
        except ValueError:
            raise InputError("frame", frame, "an int, a slice or an ASE index string like ':' or '::2'") from None
    if isinstance(frame, slice):
        return frame
    if isinstance(frame, (bool, np.bool_)) or not isinstance(frame, (int, np.integer)):
        raise InputError("frame", frame, "an int, a slice or an ASE index string like ':' or '::2'")
    return int(frame)


def read_h5md(path, frame=-1):
    """Read a frame (or, with a slice, frames) of an H5MD file as :class:`ase.Atoms` (ASE units).

    Parameters
    ----------
    path : str or os.PathLike
        H5MD file (e.g. written by :class:`H5MDWriter`).
    frame : int, slice or str
        Frame index; negative counts from the end (default: last frame).  A slice or an ASE
        index string (``':'``, ``'::2'``, ``'-3:'``, as ``ase.io.read`` takes) gives a list.

    Returns
    -------
    ase.Atoms, or a list of them for a slice
        Positions (Å), velocities (Å per ASE time, via momenta), masses
        (amu), numbers, cell, pbc, ``arrays`` for every stored extra
        per-particle series (``id``, ``material``, ...), forces (eV/Å) and
        potential energy (eV) on a SinglePointCalculator when stored, and
        ``info['step']``, ``info['time']`` (ASE units), ``info['frame']``,
        and, from the stored material table, ``info['cd_materials']`` and
        ``info['cd_r0']`` (CD) or ``info['mca_materials']`` and
        ``info['mca_dim']`` (MCA), so a ClusterDynamics attached to the Atoms
        needs no arguments.  With ``sort_by_id`` the rows are in increasing id
        order.

    Raises
    ------
    clusterdyn.errors.InputError
        Missing or unreadable file, not H5MD, frame out of range, unknown
        unit string.
    """
    index = _index(frame)
    with H5MDReader(path) as reader:
        return reader[index]
