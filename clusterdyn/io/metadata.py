"""The run's metadata in an H5MD file: what analysis needs to work from the file alone.

:class:`~clusterdyn.io.h5md_writer.H5MDWriter` stores, under H5MD's ``/parameters``
group, JSON text datasets (numbers in ASE units: Angstrom, eV, amu, ASE time)::

    /parameters                +clusterdyn_metadata 1 (layout version)
        scene                  the scene's parameters (``parameters=``)
        dynamics               ``dyn.todict()``
        calculator             {"class", "module", ...}: for ClusterDynamics
                               rc (multiple of r0), skin (as given; None = default),
                               skin_effective (multiple of the smallest r0), n_table,
                               attraction; for MCA dim and interfaces; for any
                               other calculator its ``todict()``
        materials              one record per material id (index = id): id, name,
                               rho0, r0 (CD cluster size), c0 and curve (the cold
                               curve: kind and parameters), the MCA constants
                               (E, nu, sigma_t, ...) when set, source
        damping                {"J": J} of a DampedVerlet (None = no damping),
                               {"damping": fraction of critical} of MCA dynamics
        units                  the unit system of the numbers above
        constraints/<k>        one group per constraint on the Atoms (drives included),
                               in order:
            description        ``c.describe()`` when it has one, else
                               {"class", "module", "repr" (at most 300
                               characters), "attributes" (its public scalar
                               and small-array attributes)}
            ids                (M,) int64 particle ids (``arrays['id']``; rows when
                               the Atoms have no ids) it acts on, when it has an
                               ``index`` (ASE convention) or ``ids``

Cold curves are stored so that they can be rebuilt without the library:
``{"kind": "murnaghan", "rho0", "c0", "n"}`` or ``{"kind": "tabulated",
"rho0", "delta", "eps", "pressure", "n_tail", "tail"}`` (the rows; the tail exponent
is recorded for reference); any other curve as ``{"kind": class name,
"repr": ...}``, rebuilt from the library material of the same name.

:func:`read_metadata` gives the sections back (missing ones as None),
:func:`materials_from_metadata` the Material records and
:func:`calculator_from_metadata` a ClusterDynamics with the stored
parameters.
"""

import warnings

import numpy as np

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.io._common import dumps, read_json_dataset, to_jsonable

__all__ = ["METADATA_VERSION", "UNITS", "run_metadata", "write_metadata", "read_metadata",
           "describe_material", "material_from_description", "materials_from_metadata",
           "calculator_from_metadata", "require"]

#: version of the /parameters layout written here (attribute ``clusterdyn_metadata``)
METADATA_VERSION = 1

#: the unit system of every number in the metadata (the H5MD series carry their own units)
UNITS = {
    "system": "ASE",
    "length": "Angstrom",
    "energy": "eV",
    "mass": "amu",
    "time": "ASE time unit",
    "ase_time_unit_s": 1.0 / units.s,
    "velocity": "Angstrom per ASE time unit",
    "density": "amu Angstrom-3",
    "pressure": "eV Angstrom-3",
    "specific_energy": "eV amu-1",
    "note": "rc and skin are multiples of r0; the H5MD series carry their own unit attributes",
}

#: JSON sections under /parameters (besides the ``constraints`` group)
SECTIONS = ("scene", "dynamics", "calculator", "materials", "damping", "units")


# ----------------------------------------------------------------------------- materials
def describe_curve(curve):
    """A cold curve as a JSON-able dict that :func:`curve_from_description` rebuilds."""
    from clusterdyn.materials import MurnaghanCurve, TabulatedCurve
    if curve is None:
        return None
    if isinstance(curve, MurnaghanCurve):
        return {"kind": "murnaghan", "rho0": float(curve.rho0), "c0": float(curve.c0),
                "n": float(curve.n)}
    if isinstance(curve, TabulatedCurve):
        return {"kind": "tabulated", "rho0": float(curve.rho0),
                "delta": np.asarray(curve.delta_rows, float).tolist(),
                "eps": np.asarray(curve.eps_rows, float).tolist(),
                "pressure": np.asarray(curve.p_rows, float).tolist(),
                "n_tail": float(getattr(curve, "n_tail", float("nan"))),
                "tail": str(getattr(curve, "tail", "murnaghan"))}
    return {"kind": type(curve).__name__, "repr": repr(curve)}


def curve_from_description(d):
    """The cold curve of :func:`describe_curve`, or None if its kind cannot be rebuilt."""
    from clusterdyn.materials import MurnaghanCurve, TabulatedCurve
    if d is None:
        return None
    kind = d.get("kind")
    if kind == "murnaghan":
        return MurnaghanCurve(d["rho0"], d["c0"], d["n"])
    if kind == "tabulated":
        tail = d.get("tail", "murnaghan")          # files written before the tail was stored: the default
        c = TabulatedCurve(d["delta"], d["eps"], d["pressure"], d["rho0"],
                           tail=tail.decode() if isinstance(tail, bytes) else str(tail))
        stored = d.get("n_tail")
        if stored is not None and np.isfinite(stored) and c.n_tail != stored:
            warnings.warn(f"cold curve rebuilt from the stored rows has the tail exponent "
                          f"{c.n_tail:.6g}, the run had {stored:.6g} (another clusterdyn version)",
                          RuntimeWarning, stacklevel=3)
        return c
    return None


_MATERIAL_FIELDS = ("E", "nu", "sigma_t", "sigma_c", "sigma_y", "response")


def describe_material(material, r0=None, mid=None):
    """One record of the material table (JSON-able; ASE units).

    Parameters
    ----------
    material : Material or str
    r0 : float, optional
        CD cluster size of this material id, Angstrom.
    mid : int, optional
        Material id (``atoms.arrays['material']``).
    """
    from clusterdyn.materials import get_material
    m = get_material(material)
    d = {"id": mid, "name": m.name, "rho0": float(m.rho0), "source": m.source,
         "hugoniot": m.hugoniot}
    if r0 is not None:
        d["r0"] = float(r0)
    if m.curve is not None:
        d["c0"] = float(m.curve.c0)
        d["curve"] = describe_curve(m.curve)
    for f in _MATERIAL_FIELDS:
        v = getattr(m, f)
        if v is not None:
            d[f] = to_jsonable(v)
    if m.hardening is not None:
        d["hardening"] = to_jsonable(m.hardening)
    if m.extra:
        d["extra"] = to_jsonable(m.extra)
    return d


def _same_record(a, b):
    keys = (set(a) | set(b)) - {"id", "r0"}
    return dumps({k: a.get(k) for k in keys}) == dumps({k: b.get(k) for k in keys})


def material_from_description(d):
    """(name or Material, Material) of a stored material record.

    The first item is what ``atoms.info['cd_materials']`` holds: the library
    name when the library material of that name is the stored one (same
    density, cold curve and constants), else the Material rebuilt from the
    record (so a file stays readable when the library changes, or for
    materials that were never in it).
    """
    from clusterdyn.materials import Material, get_material, material_names
    name = d.get("name")
    lib = get_material(name) if name in material_names() else None
    if lib is not None and _same_record(describe_material(lib), d):
        return name, lib
    curve = curve_from_description(d.get("curve"))
    if curve is None and d.get("curve") is not None:
        if lib is None:
            raise InputError("materials", name, "a material whose cold curve the file can rebuild "
                             "(murnaghan or tabulated) or a library material",
                             hint=f"stored curve kind {d['curve'].get('kind')!r}")
        curve = lib.curve
    kw = {f: d[f] for f in _MATERIAL_FIELDS if f in d}
    mat = Material(name=name, rho0=d["rho0"], curve=curve, source=d.get("source", ""),
                   hugoniot=d.get("hugoniot"), hardening=(lib.hardening if lib is not None else None),
                   extra=dict(d.get("extra") or {}), **kw)
    return mat, mat


# ----------------------------------------------------------------------------- describe a run
def _calculator_section(atoms, calc):
    """(calculator dict, materials list or None) of the Atoms' calculator."""
    from clusterdyn.calculators import ClusterDynamics
    from clusterdyn.calculators.cluster import default_skin
    if calc is None:
        return None, None
    cls = type(calc)
    out = {"class": cls.__name__, "module": cls.__module__}
    if isinstance(calc, ClusterDynamics):
        calc.setup(atoms)
        p = calc.parameters
        out.update({"rc": float(p.rc), "skin": None if p.skin is None else float(p.skin),
                    "skin_effective": default_skin(p.rc) if p.skin is None else float(p.skin),
                    "n_table": int(p.n_table), "attraction": str(p.attraction)})
        mats = [describe_material(pot.material, pot.r0, k) for k, pot in enumerate(calc.potentials)]
        return out, mats
    state = getattr(calc, "state", None)
    if cls.__name__ == "MCA":        # duck-typed: io does not need the mca package for this
        out.update({"dim": getattr(state, "dim", getattr(calc, "dim", None)),
                    "interfaces": [[list(k), list(v)] for k, v in
                                   (getattr(calc, "interfaces", None) or {}).items()]})
        mats = getattr(state, "materials", None)
        if mats is None:
            mats = atoms.info.get("mca_materials", getattr(calc, "materials", None))
        if mats is not None and not isinstance(mats, (list, tuple)):
            mats = [mats]
        return out, (None if mats is None else
                     [describe_material(m, None, k) for k, m in enumerate(mats)])
    try:
        out["parameters"] = to_jsonable(calc.todict())
    except Exception:             # a calculator without ASE's todict
        out["repr"] = repr(calc)
    return out, None


def _row_ids(atoms, rows):
    rows = np.asarray(rows)
    if rows.dtype == bool:
        rows = np.flatnonzero(rows)
    rows = rows.astype(np.int64).ravel()
    if "id" in atoms.arrays:
        return np.asarray(atoms.arrays["id"], np.int64)[rows], "id"
    return rows, "row"


_REPR_MAX = 300


def _fallback_description(c):
    """Class, repr (at most _REPR_MAX characters) and the small public attributes."""
    text = repr(c)
    if len(text) > _REPR_MAX:
        text = text[:_REPR_MAX] + "...(cut; the particles are in 'ids')"
    attrs = {}
    for k, v in sorted(getattr(c, "__dict__", {}).items()):
        if k.startswith("_") or k in ("index", "ids"):
            continue
        if callable(v):
            attrs[k] = f"callable {getattr(v, '__qualname__', type(v).__name__)}"
        elif v is None or isinstance(v, (bool, int, float, str, np.generic)):
            attrs[k] = to_jsonable(v)
        elif isinstance(v, (np.ndarray, list, tuple)) and np.size(v) <= 16:
            attrs[k] = to_jsonable(v)
    return {"class": type(c).__name__, "module": type(c).__module__, "repr": text,
            "attributes": attrs}


def _describe_drive(c, atoms):
    """(description dict, ids or None) of a constraint or drive."""
    desc = None
    if hasattr(c, "describe"):
        try:
            desc = to_jsonable(c.describe())
        except Exception as exc:          # a describe() that fails must not stop the run
            desc = {**_fallback_description(c), "describe_error": repr(exc)}
    if not isinstance(desc, dict):
        desc = _fallback_description(c)
    desc.setdefault("class", type(c).__name__)
    ids = None
    index = getattr(c, "index", None)
    if index is not None and not callable(index):
        ids, kind = _row_ids(atoms, index)
        desc["particles"] = kind
    elif getattr(c, "ids", None) is not None and not callable(c.ids):
        ids = np.asarray(c.ids)
        if ids.dtype == bool:
            ids, kind = _row_ids(atoms, ids)
        else:
            ids, kind = ids.astype(np.int64).ravel(), "id"
        desc["particles"] = kind
    return desc, ids


def damping_of(dyn):
    """The dynamics' damping as a dict (J of a DampedVerlet, MCA's critical fraction), or None."""
    if dyn is None or not hasattr(dyn, "todict"):
        return None
    try:
        d = dyn.todict()
    except Exception:
        return None
    out = {}
    if "J" in d:
        out["J"] = d["J"]
        out["law"] = "Gamma = c0/(J r0); J None = no damping term"
    if "damping" in d:
        out["damping"] = d["damping"]
        out["law"] = "fraction of the critical damping of the relative pair velocity"
    return to_jsonable(out) if out else None


def run_metadata(atoms, dyn=None):
    """The metadata sections of a run (see the module docstring), JSON-able but for the ids.

    Returns
    -------
    dict
        ``calculator``, ``materials``, ``damping``, ``units`` (each None when
        unknown) and ``constraints``: a list of ``(description, ids or None)``.
    """
    calc, mats = _calculator_section(atoms, atoms.calc)
    drives = [_describe_drive(c, atoms) for c in atoms.constraints]
    return {"calculator": calc, "materials": mats, "damping": damping_of(dyn),
            "units": UNITS, "constraints": drives}


def _put_json(group, name, obj):
    if name in group:
        del group[name]
    group.create_dataset(name, data=dumps(obj))


def write_metadata(h5file, meta):
    """Write :func:`run_metadata` output under ``/parameters`` of an open h5py file."""
    g = h5file.require_group("parameters")
    g.attrs["clusterdyn_metadata"] = METADATA_VERSION
    for name in ("calculator", "materials", "damping", "units"):
        if meta.get(name) is not None:
            _put_json(g, name, meta[name])
        elif name in g:
            del g[name]
    if "constraints" in g:
        del g["constraints"]
    cg = g.create_group("constraints", track_order=True)
    for k, (desc, ids) in enumerate(meta["constraints"]):
        sub = cg.create_group(str(k))
        _put_json(sub, "description", desc)
        if ids is not None:
            sub.create_dataset("ids", data=np.asarray(ids, np.int64))


# ----------------------------------------------------------------------------- read back
_json = read_json_dataset



def read_metadata(h5file):
    """The metadata of an open h5py file as a dict; missing sections are None.

    Keys: ``version`` (layout version or None for files written before it),
    ``scene``, ``dynamics``, ``calculator``, ``materials``, ``damping`` (and
    ``J``: the DampedVerlet damping, None when off or unknown), ``units``,
    ``constraints`` (list of dicts: the description plus ``ids`` (M,) int64
    when stored), ``creator``.
    """
    g = h5file.get("parameters")
    out = {"version": None if g is None else
           (int(g.attrs["clusterdyn_metadata"]) if "clusterdyn_metadata" in g.attrs else None)}
    for name in SECTIONS:
        out[name] = _json(g, name)
    out["J"] = (out["damping"] or {}).get("J")
    cons = None
    if g is not None and "constraints" in g:
        cons = []
        for k in sorted(g["constraints"], key=int):
            sub = g["constraints"][k]
            d = dict(_json(sub, "description") or {})
            if "ids" in sub:
                d["ids"] = np.asarray(sub["ids"][()], np.int64)
            cons.append(d)
    out["constraints"] = cons
    h = h5file.get("h5md")
    creator = None
    if h is not None and "creator" in h:
        creator = {k: (v.decode() if isinstance(v, bytes) else str(v))
                   for k, v in h["creator"].attrs.items()}
    out["creator"] = creator
    return out


def require(meta, names, path, purpose):
    """Raise a one-line InputError naming the metadata sections ``names`` missing from a file."""
    missing = [n for n in names if meta.get(n) is None]
    if missing:
        raise InputError("path", str(path), f"an H5MD file with /parameters/{', /parameters/'.join(names)}",
                         hint=f"missing /parameters/{', /parameters/'.join(missing)}, needed for "
                              f"{purpose}; the file was written without the run's metadata")


def materials_from_metadata(meta, path="file"):
    """``(info_materials, materials, r0)`` from stored metadata.

    ``info_materials`` holds library names where the stored record is the
    library's, else Material objects (what ``atoms.info['cd_materials']`` /
    ``['mca_materials']`` hold); ``r0`` is the list of cluster sizes
    (Angstrom) or None when the records have none (MCA).
    """
    require(meta, ("materials",), path, "the material table")
    pairs = [material_from_description(d) for d in meta["materials"]]
    r0 = [d.get("r0") for d in meta["materials"]]
    return ([p[0] for p in pairs], [p[1] for p in pairs],
            None if any(r is None for r in r0) else [float(r) for r in r0])


def calculator_from_metadata(meta, path="file"):
    """A ClusterDynamics calculator with the stored parameters and material table.

    Raises
    ------
    clusterdyn.errors.InputError
        The file has no calculator or material metadata, or its calculator
        is not a ClusterDynamics (MCA forces need the full pair state of a
        checkpoint, not the linked pairs an H5MD file holds).
    """
    from clusterdyn.calculators import ClusterDynamics
    require(meta, ("calculator", "materials"), path, "rebuilding the calculator")
    c = meta["calculator"]
    if c.get("class") != "ClusterDynamics":
        raise InputError("calculator", c.get("class"), "ClusterDynamics (rebuilt from the file)",
                         hint=f"{path}: forces of other calculators are not rebuilt from H5MD "
                              "metadata; MCA needs the pair history of a checkpoint")
    _, mats, r0 = materials_from_metadata(meta, path)
    if r0 is None:
        raise InputError("path", str(path), "a material table with r0 per material",
                         hint="/parameters/materials has no r0")
    return ClusterDynamics(rc=c["rc"], materials=mats, r0=r0, skin=c.get("skin"),
                           n_table=int(c["n_table"]), attraction=c.get("attraction", "all"))
