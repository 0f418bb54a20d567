"""MDAnalysis Universes of clusterdyn H5MD files, with masses, ids, material and grain ids.

MDAnalysis' H5MD reader takes coordinates, velocities, forces, box and
observables from the file but no per-particle attributes: opened without a
topology a Universe has no masses and MDAnalysis warns that it cannot guess
them.  :func:`universe` is the one-call route::

    from clusterdyn.io.mda import universe
    u = universe("runs/shock/shock.h5md")
    u.atoms.masses          # amu, from the file
    u.atoms.materials       # material id of every particle (u.atoms[0].material)
    u.atoms.types           # material names from the file's material table
    u.atoms.ids             # the stable particle ids (particles/trajectory/id)

It is ``MDAnalysis.Universe(path, topology_format=H5MDTopologyParser,
format="H5MD")``; once this module is imported the parser is also known by
name, ``topology_format="CDH5MD"``.  The topology (read from the first
frame; ids, materials and grains are fixed in a clusterdyn run) holds
``ids``, ``masses``, ``types`` (material names, else material ids, else
atomic numbers), ``charges`` (zero: clusters carry no charge; MDAnalysis'
``LinearDensity`` needs the attribute), ``materials`` and ``grains`` (when
the file has them), one residue and one segment.

Periodicity.  MDAnalysis knows only "every axis periodic" (a box) or "none"
(``dimensions`` None): it reads the box from ``box/edges`` and ignores H5MD's
per-axis ``boundary``.  clusterdyn writes ``box/edges`` only when some axis is
periodic (an open box keeps its cell in ``box/cell``), so a sphere or a
free-flying sample is read without a box and without minimum images.  A box
with open and periodic axes (the shock: x open, y and z periodic) has
``box/edges``; :func:`universe` then lengthens, every frame, each open axis's
edge to its length plus twice the particles' spread along it, so that no
pair is ever imaged across the open axis while the periodic axes keep their
box (a plain ``MDAnalysis.Universe(path)`` would treat x as periodic).

Unwrapped coordinates.  Periodic axes are stored wrapped with an ``image``
series (H5MD); MDAnalysis reads the wrapped positions.  ``universe(path,
unwrap=True)`` adds the images back every frame (``position + image @ box``),
as ``EinsteinMSD`` and other displacement analyses need;
:func:`clusterdyn.io.read_h5md` always gives unwrapped positions.
"""

import numpy as np

from clusterdyn.errors import InputError
from clusterdyn.io.h5md_reader import H5MDReader

try:
    import MDAnalysis
    from MDAnalysis.core.topology import Topology
    from MDAnalysis.core.topologyattrs import (AtomAttr, Atomids, Atomtypes, Charges, Masses,
                                               Resids, Resnums, Segids)
    from MDAnalysis.lib.mdamath import triclinic_box
    from MDAnalysis.transformations.base import TransformationBase
    from MDAnalysis.topology.base import TopologyReaderBase
    HAS_MDANALYSIS = True
except ImportError:       # pragma: no cover - MDAnalysis is an optional dependency
    HAS_MDANALYSIS = False

__all__ = ["universe", "H5MDTopologyParser", "HAS_MDANALYSIS"]


def _require():
    if not HAS_MDANALYSIS:
        raise InputError("MDAnalysis", None, "an installed MDAnalysis (pip install MDAnalysis)")


def topology_arrays(path):
    """The per-particle arrays of the topology: dict of (N,) arrays from frame 0 and metadata.

    Keys ``ids``, ``masses``, ``types`` and, when stored, ``materials``, ``grains``.

    Raises
    ------
    clusterdyn.errors.InputError
        No frames, or no masses in the file.
    """
    with H5MDReader(path) as r:
        if not r.has["mass"]:
            raise InputError("path", str(path), "an H5MD file with particle masses",
                             hint="no particles/trajectory/mass")
        atoms = r.get_atoms(0)
        names = None
        if r.metadata.get("materials"):
            names = [str(m.get("name")) for m in r.metadata["materials"]]
    n = len(atoms)
    out = {"masses": atoms.get_masses(),
           "ids": np.asarray(atoms.arrays.get("id", np.arange(n)), dtype=np.int64)}
    mid = atoms.arrays.get("material")
    if mid is not None:
        out["materials"] = np.asarray(mid, dtype=np.int64)
    if "grain" in atoms.arrays:
        out["grains"] = np.asarray(atoms.arrays["grain"], dtype=np.int64)
    if mid is not None and names is not None and len(mid) and 0 <= mid.min() \
            and mid.max() < len(names):
        types = np.array([names[k] for k in mid], dtype=object)
    elif mid is not None:
        types = np.array([str(k) for k in mid], dtype=object)
    else:
        types = np.array([str(z) for z in atoms.numbers], dtype=object)
    out["types"] = types
    return out


if HAS_MDANALYSIS:
    class Materials(AtomAttr):
        """Material id of each particle (``atoms.arrays['material']``)."""

        attrname = "materials"
        singular = "material"
        dtype = int

        @staticmethod
        def _gen_initial_values(na, nr, ns):
            return np.zeros(na, dtype=int)

    class Grains(AtomAttr):
        """Grain id of each particle (``atoms.arrays['grain']``)."""

        attrname = "grains"
        singular = "grain"
        dtype = int

        @staticmethod
        def _gen_initial_values(na, nr, ns):
            return np.zeros(na, dtype=int)

    class H5MDTopologyParser(TopologyReaderBase):
        """MDAnalysis topology parser of clusterdyn H5MD files (format ``"CDH5MD"``).

        Pass it as ``topology_format`` together with ``format="H5MD"``.
        """

        format = "CDH5MD"

        def parse(self, **kwargs):
            a = topology_arrays(self.filename)
            n = len(a["masses"])
            attrs = [Atomids(a["ids"]), Atomtypes(a["types"]), Masses(a["masses"]),
                     Charges(np.zeros(n)),
                     Resids(np.array([1])), Resnums(np.array([1])),
                     Segids(np.array(["SYSTEM"], dtype=object))]
            if "materials" in a:
                attrs.append(Materials(a["materials"]))
            if "grains" in a:
                attrs.append(Grains(a["grains"]))
            return Topology(n, 1, 1, attrs=attrs, atom_resindex=np.zeros(n, dtype=int),
                            residue_segindex=np.zeros(1, dtype=int))
    class _FileBox(TransformationBase):
        """Per frame: unwrapped positions (``unwrap``: position + image @ box, box and images from
        the file) and the box MDAnalysis should use: None when no axis is periodic, else the
        file's box with every open axis lengthened past twice the particles' spread along it."""

        def __init__(self, path, unwrap):
            super().__init__(max_threads=1, parallelizable=True)
            import h5py
            self._f = h5py.File(path, "r")
            traj = self._f["particles/trajectory"]
            b = np.atleast_1d(traj["box"].attrs.get("boundary", ["none"] * 3))
            self.periodic = np.array([(x.decode() if isinstance(x, bytes) else str(x)) == "periodic"
                                      for x in b], dtype=bool)
            self._edges = traj["box/edges/value"] if "edges" in traj["box"] else None
            self._image = traj["image/value"] if unwrap and "image" in traj else None

        def _cell(self, frame):
            e = np.asarray(self._edges[frame], dtype=np.float64)
            return np.diag(e) if e.shape == (3,) else e

        def _transform(self, ts):
            if self._edges is None or not self.periodic.any():
                ts.dimensions = None
                return ts
            cell = self._cell(ts.frame)
            if self._image is not None:
                ts.positions = ts.positions + (self._image[ts.frame].astype(np.float64) @ cell
                                               ).astype(ts.positions.dtype)
            if not self.periodic.all():
                pos = ts.positions.astype(np.float64)
                for d in np.flatnonzero(~self.periodic):
                    length = np.linalg.norm(cell[d])
                    spread = float(np.nanmax(pos[:, d]) - np.nanmin(pos[:, d])) if len(pos) else 0.0
                    cell[d] *= (length + 2.0 * spread + 1.0) / length if length > 0 else 1.0
                ts.dimensions = triclinic_box(*cell)
            return ts

        def close(self):
            self._f.close()
else:                     # pragma: no cover
    H5MDTopologyParser = None


def universe(path, unwrap=False, **kwargs):
    """An MDAnalysis Universe of a clusterdyn H5MD file, with masses and ids.

    Parameters
    ----------
    path : str or os.PathLike
        H5MD file written by :class:`clusterdyn.io.H5MDWriter`.
    unwrap : bool, default False
        Unwrapped positions (the file's ``image`` series added back), for
        ``EinsteinMSD`` and other displacements across periodic boundaries.
    **kwargs
        Passed to :class:`MDAnalysis.Universe` (e.g. ``in_memory=True``).

    Returns
    -------
    MDAnalysis.Universe
        Masses (amu), ``ids``, ``types`` (material names), ``charges`` (0),
        ``materials`` and ``grains`` (when stored); MDAnalysis units
        (Angstrom, ps, kJ/mol).  No box when no axis is periodic; open axes
        of a partly periodic box are never imaged (module docstring).
        Loading emits no warning.

    Raises
    ------
    clusterdyn.errors.InputError
        MDAnalysis missing, the file missing or unreadable, no frames, no masses.
    """
    _require()
    topology_arrays(path)          # the file's problems as one-line InputErrors first
    u = MDAnalysis.Universe(str(path), topology_format=H5MDTopologyParser, format="H5MD", **kwargs)
    box = _FileBox(str(path), bool(unwrap))
    if box._edges is not None or box._image is not None:
        u.trajectory.add_transformations(box)
    else:
        box.close()
    return u
