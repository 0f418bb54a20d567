"""The reader behind ``ase.io.read(path, index)`` for H5MD (:mod:`clusterdyn.ase_plugin`).

Frames come as :func:`clusterdyn.io.read_h5md` gives them: ASE units,
unwrapped positions, masses, every stored per-particle array (``id``,
``material``, ...), energy and forces on a SinglePointCalculator, and the
material table in ``atoms.info`` (a ClusterDynamics calculator attached to
them needs no arguments).
"""

from clusterdyn.io.h5md_reader import H5MDReader

__all__ = ["read_h5md"]


def read_h5md(filename, index=-1):
    """Yield the frames ``index`` (an int or a slice, as ASE passes it) of an H5MD file."""
    with H5MDReader(filename) as r:
        got = r[index]
    yield from (got if isinstance(index, slice) else [got])
