"""ASE's ``ase.ioformats`` entry point: ``ase.io.read('run.h5md', ':')`` reads clusterdyn H5MD files.

Registered in pyproject.toml (``[project.entry-points."ase.ioformats"]``); ASE
loads this object when ``ase.io`` is imported, so the module imports nothing
of clusterdyn: the reader, :mod:`clusterdyn.io.ase_h5md`, is imported when a
file is read.  Format name ``h5md``, extension ``.h5md`` (other names:
``format="h5md"``).
"""

from ase.utils.plugins import ExternalIOFormat

#: read-only, many frames ("+"), needs the file name ("S": h5py opens the file itself)
h5md_format = ExternalIOFormat(desc="H5MD trajectory (clusterdyn)", code="+S",
                               module="clusterdyn.io.ase_h5md", ext="h5md")
