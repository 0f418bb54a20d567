"""Helpers shared by the H5MD and checkpoint modules (not public API)."""

import json
import os

import numpy as np

from clusterdyn.errors import InputError


def clusterdyn_version():
    """The installed clusterdyn version string, or ``'unknown'``."""
    try:
        from importlib.metadata import version
        return version("clusterdyn")
    except Exception:  # pragma: no cover - not installed as a distribution
        import clusterdyn
        return getattr(clusterdyn, "__version__", "unknown")


def to_jsonable(obj):
    """Convert ``obj`` into something :func:`json.dumps` accepts.

    numpy arrays become (nested) lists, numpy scalars Python scalars, tuples
    lists, dict keys strings; anything else unknown becomes its ``repr``.
    """
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    return repr(obj)


def dumps(obj):
    """JSON text of ``obj`` after :func:`to_jsonable`."""
    return json.dumps(to_jsonable(obj), sort_keys=True)


def check_file_exists(path, what):
    """Raise :class:`InputError` unless ``path`` is an existing file."""
    if not os.path.exists(path):
        raise InputError("path", str(path), what, hint="file not found")
    if not os.path.isfile(path):
        raise InputError("path", str(path), what, hint="not a regular file")


def open_h5_read(path, what):
    """Open ``path`` read-only with h5py, turning failures into InputError.

    File locking is switched off so that a file still being written by a
    running simulation can be inspected.
    """
    import h5py
    check_file_exists(path, what)
    try:
        try:
            return h5py.File(path, "r", locking=False)
        except (TypeError, OSError):
            # h5py without the keyword, or the file is already open in this
            # process with locking on (HDF5 then refuses other locking flags)
            return h5py.File(path, "r")
    except OSError as exc:
        raise InputError("path", str(path), what,
                         hint=f"not a readable HDF5 file (truncated or corrupt?): {exc}") from None


def read_json_dataset(group, name):
    """Parse a scalar string dataset written with :func:`dumps`, or None."""
    if group is None or name not in group:
        return None
    raw = group[name][()]
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8")
    return json.loads(raw)
