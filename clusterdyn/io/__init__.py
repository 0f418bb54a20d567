"""Input/output: H5MD trajectories (MDAnalysis-readable), checkpoints, file summaries.

- :class:`H5MDWriter` -- ASE dynamics observer writing H5MD 1.1
  (``particles/trajectory``; units MDAnalysis accepts).
- :class:`H5MDReader`, :func:`read_h5md` -- frames back as :class:`ase.Atoms`.
- :func:`h5md_info`, :func:`format_info` -- what ``clusterdyn info FILE`` shows.
- :mod:`clusterdyn.io.metadata` -- the run's metadata under ``/parameters`` (material
  table, r0, rc, damping, drives, units); :meth:`H5MDReader.calculator` rebuilds the
  calculator from it, so analyses work from the file alone.
- :func:`clusterdyn.io.mda.universe` -- an MDAnalysis Universe with masses, ids, material
  and grain ids (imported on demand: it imports MDAnalysis).
- :func:`write_checkpoint`, :func:`read_checkpoint` -- bit-exact restart files;
  :func:`save_run`, :func:`load_run` -- a whole run (dynamics, calculator, drives) in one.
"""

from clusterdyn.io.h5md_writer import H5MDWriter
from clusterdyn.io.h5md_reader import H5MDReader, read_h5md
from clusterdyn.io.info import h5md_info, format_info
from clusterdyn.io.checkpoint import write_checkpoint, read_checkpoint, save_run, load_run, read_run_extra
from clusterdyn.io.lammps.export import export_lammps  # noqa: F401  (LAMMPS scale-out)
from clusterdyn.io.lammps.run import run_lammps  # noqa: F401

__all__ = ["H5MDWriter", "H5MDReader", "read_h5md", "h5md_info", "format_info",
           "write_checkpoint", "read_checkpoint", "save_run", "load_run", "read_run_extra"]
