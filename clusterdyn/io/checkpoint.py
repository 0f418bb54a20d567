"""Checkpoint and restart: the full state of a run in one HDF5 file, bit for bit.

:func:`write_checkpoint` stores an :class:`ase.Atoms` (every ``atoms.arrays``
entry with its own dtype, cell, pbc, the encodable part of ``atoms.info``,
ASE constraints that have ``todict``) plus a nested ``state`` dict (pair
state, RNG state, step, time, neighbour-list reference positions, scene
parameters, ...).  :func:`read_checkpoint` gives both back; float64 arrays
and Python floats come back with identical bits.

File layout::

    /                 +format 'clusterdyn-checkpoint', +format_version 1, +creator
    /atoms            +natoms
        cell          (3, 3) float64, Angstrom
        pbc           (3,) bool
        arrays/<name> every atoms.arrays entry (positions Angstrom, numbers,
                      momenta amu*Angstrom/ASE-time, masses amu, id, material, ...)
        info/...      atoms.info, encoded like the state
        constraints   JSON text of [c.todict(), ...] (only when there are some)
    /state/...        the state dict

Every node of an encoded dict carries a ``kind`` attribute: ``dict``,
``list``, ``tuple``, ``ndarray``, ``npscalar``, ``int``, ``bigint``
(integers beyond int64, stored as decimal text: PCG64 states are 128-bit),
``float``, ``bool``, ``str``, ``bytes``, ``none``, ``list_float``,
``list_int``, ``list_str`` (homogeneous lists stored as one dataset),
``generator`` (a :class:`numpy.random.Generator`, restored with its bit
generator state) and ``randomstate``.

:func:`save_run` and :func:`load_run` put a whole run in such a file and
take it back: the Atoms, the dynamics' state, the calculator's set-up, every
constraint in order (the drives of :mod:`clusterdyn.md.drives` with their
histories, records and time state; ASE constraints through ``todict()``)
and the caller's ``extra``; the run continues bit for bit.  State layout::

    /state/run_format       2
    /state/dynamics_class   'DampedVerlet' or 'MCADynamics' (a key of RUN_KINDS)
    /state/dynamics         dyn.get_state()
    /state/calculator       {'class': 'ClusterDynamics', 'parameters': {...}}, or for MCA
                            {'class': 'MCA', 'dim', 'interfaces', 'materials' (JSON records)}
    /state/run              (MCA) the dynamics' settings: dt, damping, contact_every, ...
    /state/constraints      [{'drive': drive.get_state()} or {'ase': JSON of c.todict()}, ...]
    /state/extra            the caller's dict

The file is written to a temporary file in the destination folder, synced,
then moved over ``path`` with :func:`os.replace`, so ``path`` always holds a
complete checkpoint (the previous one or the new one).  Arrays carry a
Fletcher-32 checksum, so damaged data are detected on reading.
"""

import json
import os
import warnings

import numpy as np

from clusterdyn.errors import InputError
from clusterdyn.io._common import clusterdyn_version, open_h5_read

__all__ = ["write_checkpoint", "read_checkpoint", "save_run", "load_run", "read_run_extra", "register_run_kind",
           "FORMAT", "FORMAT_VERSION"]

FORMAT = "clusterdyn-checkpoint"
FORMAT_VERSION = 1

_ALLOWED = ("dict (str or int keys), list, tuple, str, bytes, int, float, bool, None, "
            "numpy array (numeric, bool or str), numpy scalar, numpy Generator/RandomState")
_INT64 = np.iinfo(np.int64)


class _Unencodable(InputError):
    pass


def _node_name(key, where):
    if isinstance(key, bool) or not isinstance(key, (str, int, np.integer)):
        raise _Unencodable(f"key of {where}", key, "str or int dict keys")
    name = str(int(key)) if not isinstance(key, str) else key
    if not name or "/" in name or name in (".", ".."):
        raise _Unencodable(f"key of {where}", key, "a non-empty key without '/'")
    return name, not isinstance(key, str)


def _put(group, name, value, where):
    """Encode ``value`` as ``group[name]`` (dataset or group) with a ``kind`` attribute."""
    import h5py

    def ds(data, kind, **kw):
        d = group.create_dataset(name, data=data, **kw)
        d.attrs["kind"] = kind
        return d

    if value is None:
        return ds(h5py.Empty("f8"), "none")
    if isinstance(value, np.random.Generator):
        g = group.create_group(name, track_order=True)
        g.attrs["kind"] = "generator"
        _put(g, "state", value.bit_generator.state, f"{where}.bit_generator.state")
        return g
    if isinstance(value, np.random.RandomState):
        g = group.create_group(name, track_order=True)
        g.attrs["kind"] = "randomstate"
        _put(g, "state", value.get_state(legacy=False), f"{where}.get_state()")
        return g
    if isinstance(value, np.ndarray):
        kind = value.dtype.kind
        if kind in "fiubc":
            kw = {}
            if value.ndim >= 1 and value.size > 0:
                kw = {"chunks": True, "fletcher32": True}
            return ds(value, "ndarray", **kw)
        if kind == "U":
            d = ds(np.array(value.ravel().tolist(), dtype=h5py.string_dtype()), "ndarray_str")
            d.attrs["shape"] = np.array(value.shape, dtype=np.int64)
            return d
        raise _Unencodable(where, f"array of dtype {value.dtype}", _ALLOWED)
    if isinstance(value, np.generic):
        if value.dtype.kind in "fiubc":
            return ds(value, "npscalar")
        value = value.item()              # np.str_, np.bytes_ -> str, bytes
    if isinstance(value, bool):
        return ds(np.bool_(value), "bool")
    if isinstance(value, int):
        if _INT64.min <= value <= _INT64.max:
            return ds(np.int64(value), "int")
        return ds(str(value), "bigint")
    if isinstance(value, float):
        return ds(np.float64(value), "float")
    if isinstance(value, str):
        return ds(value, "str", dtype=h5py.string_dtype())
    if isinstance(value, (bytes, bytearray)):
        return ds(np.frombuffer(bytes(value), dtype=np.uint8), "bytes")
    if isinstance(value, dict):
        g = group.create_group(name, track_order=True)
        g.attrs["kind"] = "dict"
        for k, v in value.items():
            child, int_key = _node_name(k, where)
            node = _put(g, child, v, f"{where}[{k!r}]")
            if int_key:
                node.attrs["keytype"] = "int"
        return g
    if isinstance(value, (list, tuple)):
        kind = "list" if isinstance(value, list) else "tuple"
        if kind == "list" and value:
            if all(type(v) is float for v in value):
                return ds(np.array(value, dtype=np.float64), "list_float")
            if all(type(v) is int and _INT64.min <= v <= _INT64.max for v in value):
                return ds(np.array(value, dtype=np.int64), "list_int")
            if all(type(v) is str for v in value):
                return ds(np.array(value, dtype=h5py.string_dtype()), "list_str")
        g = group.create_group(name, track_order=True)
        g.attrs["kind"] = kind
        g.attrs["length"] = len(value)
        for i, v in enumerate(value):
            _put(g, str(i), v, f"{where}[{i}]")
        return g
    raise _Unencodable(where, f"{type(value).__name__} object", _ALLOWED)


def _attr_str(node, key):
    v = node.attrs[key]
    return v.decode() if isinstance(v, bytes) else str(v)


def _get(node):
    """Decode a node written by :func:`_put`."""
    kind = _attr_str(node, "kind")
    if kind == "none":
        return None
    if kind == "dict":
        out = {}
        for name in node:
            child = node[name]
            key = int(name) if child.attrs.get("keytype") in ("int", b"int") else name
            out[key] = _get(child)
        return out
    if kind in ("list", "tuple"):
        n = int(node.attrs["length"])
        items = [_get(node[str(i)]) for i in range(n)]
        return items if kind == "list" else tuple(items)
    if kind == "generator":
        state = _get(node["state"])
        bitgen = getattr(np.random, state["bit_generator"])()
        bitgen.state = state
        return np.random.Generator(bitgen)
    if kind == "randomstate":
        rs = np.random.RandomState()
        rs.set_state(_get(node["state"]))
        return rs
    if kind == "ndarray":
        return node[()] if node.shape != () else np.array(node[()])
    if kind == "ndarray_str":
        flat = node.asstr()[()]
        return np.array(list(flat), dtype=str).reshape(tuple(node.attrs["shape"]))
    if kind == "npscalar":
        return node[()]
    if kind == "bool":
        return bool(node[()])
    if kind == "int":
        return int(node[()])
    if kind == "bigint":
        return int(node.asstr()[()])
    if kind == "float":
        return float(node[()])
    if kind == "str":
        return node.asstr()[()]
    if kind == "bytes":
        return np.asarray(node[()], dtype=np.uint8).tobytes()
    if kind == "list_float":
        return [float(x) for x in node[()]]
    if kind == "list_int":
        return [int(x) for x in node[()]]
    if kind == "list_str":
        return list(node.asstr()[()])
    raise ValueError(f"unknown kind {kind!r} at {node.name}")


def _write_atoms(group, atoms):
    group.attrs["natoms"] = len(atoms)
    group.create_dataset("cell", data=np.asarray(atoms.cell[:], dtype=np.float64))
    group.create_dataset("pbc", data=np.asarray(atoms.pbc, dtype=bool))
    arrays = group.create_group("arrays", track_order=True)
    for name, a in atoms.arrays.items():
        _put(arrays, _node_name(name, "atoms.arrays")[0], np.asarray(a), f"atoms.arrays[{name!r}]")
    info = group.create_group("info", track_order=True)
    info.attrs["kind"] = "dict"
    for key, value in atoms.info.items():
        try:
            child, int_key = _node_name(key, "atoms.info")
            node = _put(info, child, value, f"atoms.info[{key!r}]")
            if int_key:
                node.attrs["keytype"] = "int"
        except _Unencodable as exc:
            if isinstance(key, str) and key in info:
                del info[key]
            warnings.warn(f"write_checkpoint: atoms.info[{key!r}] not stored ({exc})",
                          RuntimeWarning, stacklevel=3)
    dicts = []
    for c in atoms.constraints:
        try:
            dicts.append(c.todict())
        except Exception:
            warnings.warn(f"write_checkpoint: constraint {type(c).__name__} has no todict(); "
                          "not stored (restore it from the state)", RuntimeWarning, stacklevel=3)
    if dicts:
        from clusterdyn.io._common import to_jsonable
        group.create_dataset("constraints", data=json.dumps(to_jsonable(dicts)))


def _read_atoms(group):
    from ase import Atoms

    arrays = {name: _get(group["arrays"][name]) for name in group["arrays"]}
    n = int(group.attrs["natoms"])
    for name, a in arrays.items():
        if len(a) != n:
            raise ValueError(f"atoms.arrays[{name!r}] has {len(a)} rows, expected {n}")
    atoms = Atoms(numbers=arrays.pop("numbers"), positions=arrays.pop("positions"),
                  cell=group["cell"][()], pbc=group["pbc"][()])
    for name, a in arrays.items():
        atoms.arrays[name] = a
    atoms.info = _get(group["info"])
    if "constraints" in group:
        from ase.constraints import dict2constraint
        raw = group["constraints"][()]
        for d in json.loads(raw.decode() if isinstance(raw, bytes) else raw):
            try:
                atoms.constraints = list(atoms.constraints) + [dict2constraint(d)]
            except Exception as exc:
                warnings.warn(f"read_checkpoint: constraint {d.get('name')} not restored ({exc})",
                              RuntimeWarning, stacklevel=3)
    return atoms


def _new_temp(folder, name):
    """A new empty file beside the destination, created with mode 0666 less the umask (the mode
    every other output gets; ``tempfile.mkstemp`` would give 0600)."""
    for _ in range(100):
        tmp = os.path.join(folder, f".{name}.{os.getpid()}.{os.urandom(4).hex()}.tmp")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return tmp
        except FileExistsError:  # pragma: no cover - a name taken: try another
            continue
    raise FileExistsError(f"no free temporary name in {folder}")  # pragma: no cover


def write_checkpoint(path, atoms, state=None):
    """Write ``atoms`` and ``state`` to the checkpoint file ``path``, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder must exist.  An existing file is replaced
        only once the new one is complete.
    atoms : ase.Atoms
        Every ``atoms.arrays`` entry is stored with its dtype and bits
        (positions in Angstrom, momenta in amu*Angstrom/ASE-time, masses in
        amu if set, numbers, id, material, ...), plus cell, pbc, the
        encodable entries of ``atoms.info`` (others are skipped with a
        warning) and constraints that have ``todict()``.  The calculator is
        not stored.
    state : dict, optional
        Nested dict (str or int keys) of numpy arrays, numpy scalars,
        Python scalars (ints of any size), str, bytes, None, lists, tuples,
        dicts and numpy Generators; e.g. ``{'step': 1200, 'time': t,
        'pairs': {'i': i_p, 'j': j_p, 'linked': s_p}, 'rng':
        rng.bit_generator.state, 'nl_reference_positions': r_nc}``.

    Raises
    ------
    clusterdyn.errors.InputError
        ``state`` is not a dict or holds a value of another type (the
        message names where), or the folder of ``path`` does not exist.
    clusterdyn.errors.OutputError
        The file could not be written (full disk, no permission); ``path``
        still holds the previous checkpoint, if there was one.

    The file gets mode 0666 less the umask, as every other output does.
    """
    import h5py

    if state is None:
        state = {}
    if not isinstance(state, dict):
        raise InputError("state", type(state).__name__, "a dict")
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError("path", path, "a file in an existing folder",
                         hint=f"folder {folder} does not exist")
    tmp = _new_temp(folder, os.path.basename(path))
    try:
        with h5py.File(tmp, "w", track_order=True) as f:
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["creator"] = f"clusterdyn {clusterdyn_version()}"
            _write_atoms(f.create_group("atoms", track_order=True), atoms)
            st = f.create_group("state", track_order=True)
            st.attrs["kind"] = "dict"
            for key, value in state.items():
                child, int_key = _node_name(key, "state")
                node = _put(st, child, value, f"state[{key!r}]")
                if int_key:
                    node.attrs["keytype"] = "int"
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, (OSError, RuntimeError)) and not isinstance(exc, InputError):
            from clusterdyn.errors import OutputError
            raise OutputError(path, exc, "the previous checkpoint, if any, unchanged") from None
        raise
    try:                                  # make the rename itself durable
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:  # pragma: no cover - platforms without directory fsync
        pass


def read_checkpoint(path):
    """Read a checkpoint written by :func:`write_checkpoint`.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    atoms : ase.Atoms
        With every stored array, cell, pbc, info and constraints (no calculator).
    state : dict
        The state as written (numpy Generators restored as Generators that
        continue the same random stream).

    Raises
    ------
    clusterdyn.errors.InputError
        The file is missing, not HDF5, truncated or corrupt, not a
        clusterdyn checkpoint (e.g. an H5MD trajectory), or from a newer
        format version; the message names the path and the problem.
    """
    path = os.fspath(path)
    what = "a clusterdyn checkpoint file"
    f = open_h5_read(path, what)
    try:
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode()
        if fmt != FORMAT:
            hint = "not a clusterdyn checkpoint"
            if "h5md" in f or "particles" in f:
                hint += " (it is an H5MD trajectory; read it with clusterdyn.io.read_h5md)"
            else:
                hint += f" (format attribute {fmt!r})"
            raise InputError("path", path, what, hint=hint)
        version = int(f.attrs.get("format_version", -1))
        if not 1 <= version <= FORMAT_VERSION:
            raise InputError("path", path, what,
                             hint=f"format_version {version}; this clusterdyn reads 1 to "
                                  f"{FORMAT_VERSION}")
        try:
            atoms = _read_atoms(f["atoms"])
            state = _get(f["state"])
        except InputError:
            raise
        except Exception as exc:
            raise InputError("path", path, what,
                             hint=f"corrupt or incomplete checkpoint: {type(exc).__name__}: "
                                  f"{exc}") from None
    finally:
        f.close()
    return atoms, state


# -- whole runs: dynamics + calculator + constraints ---------------------------------------------

#: version of the run layout under /state (1: DampedVerlet.checkpoint of earlier releases)
RUN_FORMAT = 2

#: dynamics class name -> ``(save, load)``: ``save(dyn)`` gives a dict of 'dynamics' and 'calculator'
#: states, ``load(atoms, state, **kwargs)`` the dynamics; see :func:`register_run_kind`
RUN_KINDS = {}


def register_run_kind(name, save, load):
    """Teach :func:`save_run` / :func:`load_run` another dynamics class.

    ``save(dyn)`` returns a dict with at least ``'dynamics'`` (the dynamics'
    own state, e.g. ``dyn.get_state()``) and ``'calculator'`` (what rebuilds
    the calculator), encodable by :func:`write_checkpoint`.  ``load(atoms,
    state, **kwargs)`` gets the Atoms with their constraints restored and the
    whole stored state dict, attaches the calculator and returns the
    dynamics, restored.  ``name`` is ``type(dyn).__name__``.  The constraints
    and ``extra`` are handled by save_run/load_run for every kind.

    ``save`` may also return ``'info'``: ``{key: encodable value}`` written in
    place of ``atoms.info[key]`` (e.g. material names for Material objects);
    ``load`` then gets the Atoms with those values and restores the entries.
    """
    RUN_KINDS[name] = (save, load)


def _damped_save(dyn):
    from clusterdyn.calculators.cluster import ClusterDynamics
    if not isinstance(dyn.calc, ClusterDynamics):
        raise InputError("dyn.calc", type(dyn.calc).__name__,
                         "a ClusterDynamics calculator (save_run rebuilds it from its parameters)")
    par = {k: v for k, v in dyn.calc.parameters.items() if v is not None}
    if "materials" in par:
        par["materials"] = [m if isinstance(m, str) else getattr(m, "name", m) for m in par["materials"]]
    return {"dynamics": dyn.get_state(copy=False), "calculator": {"class": "ClusterDynamics", "parameters": par}}


def _damped_load(atoms, state, **kwargs):
    from clusterdyn.calculators.cluster import ClusterDynamics
    from clusterdyn.md.damped import DampedVerlet
    cal = state.get("calculator", {})
    cpar = dict(cal.get("parameters", cal) if isinstance(cal, dict) else {})
    cpar.pop("class", None)
    if "materials" in cpar:
        cpar["materials"] = [str(m) for m in np.atleast_1d(cpar["materials"])]
    if "r0" in cpar:
        cpar["r0"] = [float(r) for r in np.atleast_1d(cpar["r0"])]
    atoms.calc = ClusterDynamics(**cpar)
    dst = state["dynamics"]
    J = float(dst["J"])
    dyn = DampedVerlet(atoms, timestep=float(dst["dt"]), J=None if J < 0 else J, **kwargs)
    dyn.set_state(dst)
    return dyn


register_run_kind("DampedVerlet", _damped_save, _damped_load)


def _mca_save(dyn):
    from clusterdyn.io._common import to_jsonable
    from clusterdyn.io.metadata import describe_material
    st = dyn.state
    mats = [describe_material(m, None, k) for k, m in enumerate(st.materials)]
    cal = {"class": "MCA", "dim": int(st.dim), "materials": json.dumps(to_jsonable(mats)),
           "interfaces": [[float(a), float(b), float(t), float(c)] for (a, b), (t, c) in st.interfaces.items()]}
    run = {"dt": float(dyn.dt), "damping": float(dyn.damping), "contact_every": int(dyn.contact_every),
           "check_timestep": bool(dyn.check_timestep), "hold_layer_rotation": bool(dyn.hold_layer_rotation)}
    if getattr(dyn, "contact", None) is not None:      # the segment contact's parameters (its history: dynamics)
        run["contact"] = dyn.contact.params()
    out = {"dynamics": dyn.get_state(), "calculator": cal, "run": run}
    if "mca_materials" in dyn.atoms.info:          # Material objects: stored as records in 'calculator'
        out["info"] = {"mca_materials": [m.name for m in st.materials]}
    return out


def _mca_load(atoms, state, **kwargs):
    from clusterdyn.io.metadata import material_from_description
    from clusterdyn.mca.calculator import MCA
    from clusterdyn.mca.dynamics import MCADynamics
    cal = state["calculator"]
    mats = []
    for d in json.loads(cal["materials"]):
        m = material_from_description(d)[1]
        if m.hardening is None and isinstance(d.get("hardening"), list):
            m = m.replace(hardening=d["hardening"])
        mats.append(m)
    if "mca_materials" in atoms.info:
        atoms.info["mca_materials"] = list(mats)
    interfaces = {(int(a), int(b)): (float(t), float(c)) for a, b, t, c in cal.get("interfaces") or []}
    atoms.calc = MCA(materials=mats, interfaces=interfaces or None, dim=int(cal["dim"]))
    r = state["run"]
    contact = None
    if "contact" in r:
        from clusterdyn.mca.contact import SegmentContact
        contact = SegmentContact(**r["contact"])
    return MCADynamics(atoms, timestep=float(r["dt"]), damping=float(r["damping"]),
                       contact_every=int(r["contact_every"]), check_timestep=bool(r["check_timestep"]),
                       hold_layer_rotation=bool(r["hold_layer_rotation"]), state=state["dynamics"],
                       contact=contact, **kwargs)


register_run_kind("MCADynamics", _mca_save, _mca_load)


def save_run(path, dyn, extra=None):
    """Write a whole run to the checkpoint ``path``, atomically; returns ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        Destination (its folder must exist); replaced only once complete.
    dyn : ase.md.md.MolecularDynamics
        A dynamics of a registered kind (:class:`~clusterdyn.md.DampedVerlet`,
        :class:`~clusterdyn.mca.MCADynamics` with its pair state; others
        through :func:`register_run_kind`).  Its Atoms (every array),
        its state, its calculator's set-up and the Atoms' constraints in order
        are stored: drives (:mod:`clusterdyn.md.drives`) with their state,
        ASE constraints through ``todict()``.
    extra : dict, optional
        Anything the caller needs back (scene parameters, analysis state, RNG
        states), encodable by :func:`write_checkpoint`.

    Raises
    ------
    clusterdyn.errors.InputError
        Before anything is written: a dynamics or calculator of an unknown
        kind, a constraint that is neither a drive nor has ``todict()``, a
        drive with a callable history (pass a Table), or an unencodable
        ``extra``.
    """
    from clusterdyn.md.drives import Drive
    from clusterdyn.io._common import to_jsonable
    kind = type(dyn).__name__
    if kind not in RUN_KINDS:
        raise InputError("dyn", kind, "a dynamics save_run knows: " + ", ".join(RUN_KINDS))
    atoms = dyn.atoms
    cons = []
    for c in atoms.constraints:
        if isinstance(c, Drive):
            cons.append({"drive": c.get_state()})
        elif hasattr(c, "todict"):
            cons.append({"ase": json.dumps(to_jsonable(c.todict()))})
        else:
            raise InputError("atoms.constraints", type(c).__name__,
                             "drives of clusterdyn.md.drives or ASE constraints with todict()")
    state = {"run_format": RUN_FORMAT, "dynamics_class": kind}
    saved = dict(RUN_KINDS[kind][0](dyn))
    info = saved.pop("info", None) or {}
    state.update(saved)
    state["constraints"] = cons
    state["extra"] = extra if extra is not None else {}
    kept, kept_info = list(atoms.constraints), atoms.info
    atoms.set_constraint()
    if info:
        atoms.info = {**kept_info, **info}
    try:
        write_checkpoint(path, atoms, state)
    finally:
        atoms.set_constraint(kept)
        atoms.info = kept_info
    return path


def _constraints(state, path):
    from ase.constraints import dict2constraint
    from clusterdyn.md.drives import from_state
    items = state.get("constraints")
    if items is None:                             # run_format 1: drives inside the dynamics' state
        return [from_state(c) for c in state["dynamics"].get("constraints", [])]
    out = []
    for c in items:
        if "drive" in c:
            out.append(from_state(c["drive"]))
        else:
            out.append(dict2constraint(json.loads(c["ase"])))
    return out


def load_run(path, **kwargs):
    """Rebuild ``(atoms, dyn, extra)`` from :func:`save_run`'s file.

    ``kwargs`` go to the dynamics' constructor (e.g. ``logfile``).  N steps +
    save_run + load_run + N steps equals 2N steps bit for bit: positions,
    momenta, forces, every drive's records and time state.

    Raises
    ------
    clusterdyn.errors.InputError
        The file is not a checkpoint (see :func:`read_checkpoint`) or not one
        written by save_run (e.g. a bare write_checkpoint file).
    """
    atoms, state = read_checkpoint(path)
    kind = state.get("dynamics_class", "DampedVerlet") if isinstance(state, dict) else None
    if not isinstance(state, dict) or "dynamics" not in state or kind not in RUN_KINDS:
        raise InputError("path", os.fspath(path), "a run checkpoint written by save_run",
                         hint=f"dynamics class {kind!r}" if kind not in RUN_KINDS else None)
    atoms.set_constraint(_constraints(state, path))
    dyn = RUN_KINDS[kind][1](atoms, state, **kwargs)
    return atoms, dyn, state.get("extra", {})


def read_run_extra(path):
    """The ``extra`` dict of :func:`save_run`'s file, without rebuilding the run."""
    _, state = read_checkpoint(path)
    if not isinstance(state, dict) or "dynamics" not in state:
        raise InputError("path", os.fspath(path), "a run checkpoint written by save_run")
    return state.get("extra", {})
