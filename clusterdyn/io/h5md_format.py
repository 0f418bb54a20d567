"""The H5MD 1.1 layout clusterdyn writes and reads (MDAnalysis reads it without a topology).

:class:`~clusterdyn.io.h5md_writer.H5MDWriter` is an observer for any ASE
``MolecularDynamics`` (``dyn.attach(writer, interval=n)``);
:class:`~clusterdyn.io.h5md_reader.H5MDReader` and
:func:`~clusterdyn.io.h5md_reader.read_h5md` bring frames back as
:class:`ase.Atoms` in ASE units.  This module holds the layout and the
constants both sides share.

File layout (``N`` particles, ``F`` frames)::

    /h5md                      +version [1, 1]
        author                 +name
        creator                +name 'clusterdyn', +version
    /particles/trajectory      (the name MDAnalysis looks up without topology)
        box                    +dimension 3, +boundary 'periodic'/'none' per axis
            edges/{step,time,value (F, 3, 3) Angstrom}     only if some axis is periodic (H5MD:
                                                            MDAnalysis then reads a box)
            cell/{step,time,value (F, 3, 3) Angstrom}      instead, when every boundary is 'none'
                                                            and the cell is not all zero: the
                                                            Atoms' cell, which readers that take
                                                            a box from edges (MDAnalysis) ignore,
                                                            so they apply no minimum image
        position/{step,time,value (F, N, 3) float64 'Angstrom'}
        velocity/{step,time,value (F, N, 3) float64 'Angstrom ps-1'}
        force/{step,time,value (F, N, 3) float64 'kJ mol-1 Angstrom-1'}  only with a calculator
        species/{step,time,value (F, N) int}            atomic numbers
        mass (N,) float64 'u'                           amu, time-independent (files written
                                                         before: mass/{step,time,value (F, N)})
        <array>/{step,time,value (F, N, ...)}            every other atoms.arrays entry
                                                         (id, material, grain, radius, ...)
                                                         and every ``per_particle`` series,
                                                         in ASE units as given
    /observables/<name>/{step,time,value (F, ...)}      dt ('ps'), kinetic_energy,
                                                         potential_energy, total_energy
                                                         ('kJ mol-1') + user ones
    /connectivity/linked_pairs                          MCA runs (``pair_state``) only
        +particles_group (reference to particles/trajectory), +values 'id'
        {step,time,value (F, P, 2) int64}               ids (i < j) of the linked pairs of
                                                         each frame, sorted, padded with -1
                                                         (P grows with the largest frame)
    /parameters                H5MD's parameters group: the run's metadata
        scene                  JSON text of ``parameters=``
        dynamics               JSON text of ``dyn.todict()`` (``set_description``)
        calculator, materials, damping, units, constraints/<k>/{description, ids}
                               the calculator with its material table, the damping J,
                               drives and walls, the unit system: see
                               :mod:`clusterdyn.io.metadata`

``step`` (int64) and ``time`` (float64, 'ps') exist once, in ``position``,
and are hard-linked into every other time-dependent group (as MDAnalysis's
own writer does), so every series has exactly the frames of ``position``.

``observables/dt`` holds, for each frame, the time since the previous frame
in ps (frame 0 gets the value of frame 1).  MDAnalysis' H5MD reader has no
other source for ``Timestep.dt`` (it would warn and assume 1 ps); it takes
``ts.data['dt']``, which this observable provides.

Positions and images
--------------------
With periodic axes (and the default ``wrap=True``) positions are written
wrapped into the box with an integer ``image`` series, as H5MD prescribes:
the unwrapped position is ``position + image @ box``.  MDAnalysis reads the
wrapped coordinates; :func:`read_h5md` gives back unwrapped positions
(ASE's integrators never wrap), so the displacement of a particle across the
whole run (fragments, ejecta, diffusion) stays available.  With
``wrap=False``, or without periodic axes, positions are written exactly as
``atoms.positions`` holds them and no ``image`` is stored.

Ordering
--------
With ``sort_by_id=True`` and an ``atoms.arrays['id']``, every per-particle
row is written in increasing id order, so row ``i`` is the same particle in
every frame even if the Atoms are re-sorted during the run (read back, the
Atoms come in id order).

Removed particles
-----------------
A run may take particles out of the Atoms (``DampedVerlet(region=...)``).
The datasets keep the size of the first frame: the rows of the particles
present are found by id, and the rows of removed particles hold fill values
(also the datasets' HDF5 fill value): NaN for floating-point series
(positions, velocities, forces, masses of the frame), -1 for signed integers
(``id``, ``species``, ``material``, ...), 0 for unsigned ones, False for
booleans.  MDAnalysis reads such a file as it is (NaN coordinates for the
removed rows); :class:`H5MDReader` and :func:`read_h5md` drop the rows whose
``id`` is -1.

Crash safety
------------
The file uses HDF5's default (oldest compatible) format, no SWMR, and is
flushed after every frame, so a process killed between frames leaves a file
that h5py and MDAnalysis open, with every frame written before the kill.
"""

import os

import numpy as np

from clusterdyn import units

__all__ = ["UNITS", "TO_ASE", "RESERVED", "STANDARD_ARRAYS", "DEFAULT_OBSERVABLES", "TRAJ", "PAIRS",
           "DEFAULT_OBSERVABLE_FUNCS", "calc_property", "chunks", "fill_value", "storage_dtype", "h5group", "is_h5md_file"]

#: unit strings written (all accepted by MDAnalysis' H5MD reader)
UNITS = {
    "time": "ps",
    "length": "Angstrom",
    "velocity": "Angstrom ps-1",
    "force": "kJ mol-1 Angstrom-1",
    "energy": "kJ mol-1",
    "mass": "u",
}

#: unit string -> factor to multiply a stored value by to get ASE units
TO_ASE = {
    "length": {"Angstrom": 1.0, "angstrom": 1.0, "A": 1.0, "nm": 10.0, "pm": 0.01},
    "time": {"ps": units.PS, "fs": units.fs, "ns": 1e3 * units.PS,
             "s": units.s, "second": units.s, "sec": units.s},
    "velocity": {"Angstrom ps-1": 1.0 / units.PS, "A ps-1": 1.0 / units.PS,
                 "Angstrom fs-1": 1.0 / units.fs, "A fs-1": 1.0 / units.fs,
                 "nm ps-1": 10.0 / units.PS, "nm ns-1": 10.0 / (1e3 * units.PS),
                 "pm ps-1": 0.01 / units.PS, "m s-1": units.m / units.s},
    "force": {"kJ mol-1 Angstrom-1": units.kJ / units.mol,
              "kJ mol-1 nm-1": 0.1 * units.kJ / units.mol,
              "kcal mol-1 Angstrom-1": units.kcal / units.mol,
              "kcal mol-1 A-1": units.kcal / units.mol,
              "N": units.N, "Newton": units.N, "J m-1": units.N},
    "energy": {"kJ mol-1": units.kJ / units.mol, "kcal mol-1": units.kcal / units.mol,
               "eV": 1.0, "J": units.J},
    "mass": {"u": 1.0, "amu": 1.0, "Da": 1.0},
}

#: names under particles/trajectory that ``per_particle`` may not use
RESERVED = ("box", "position", "velocity", "force", "species", "mass", "image")
#: atoms.arrays entries written through dedicated groups (never as extras)
STANDARD_ARRAYS = ("positions", "numbers", "momenta", "masses")
#: the default observables (``dt`` is the frame spacing in ps, read by MDAnalysis as Timestep.dt)
DEFAULT_OBSERVABLES = ("dt", "kinetic_energy", "potential_energy", "total_energy")

TRAJ = "particles/trajectory"
PAIRS = "connectivity/linked_pairs"
MAX_CHUNK_BYTES = 1 << 20


def calc_property(atoms, name):
    """A calculator property, from its result cache when valid, else computed.

    Returns None when ``atoms`` has no calculator.
    """
    calc = atoms.calc
    if calc is None:
        return None
    try:
        value = calc.get_property(name, atoms, allow_calculation=False)
    except (TypeError, AttributeError):  # calculator without the ASE cache API
        value = None
    if value is None:
        if name == "forces":
            value = atoms.get_forces(apply_constraint=False)
        elif name == "energy":
            value = atoms.get_potential_energy(apply_constraint=False)
        else:
            value = calc.get_property(name, atoms)
    return value


def _kinetic_energy(atoms):
    return atoms.get_kinetic_energy() * units.ENERGY_TO_KJMOL


def _potential_energy(atoms):
    return float(calc_property(atoms, "energy")) * units.ENERGY_TO_KJMOL


def _total_energy(atoms):
    return (float(calc_property(atoms, "energy")) + atoms.get_kinetic_energy()) \
        * units.ENERGY_TO_KJMOL


DEFAULT_OBSERVABLE_FUNCS = {
    "kinetic_energy": (_kinetic_energy, UNITS["energy"]),
    "potential_energy": (_potential_energy, UNITS["energy"]),
    "total_energy": (_total_energy, UNITS["energy"]),
}


def chunks(shape, itemsize):
    """Chunk shape: one frame, at most ~1 MiB, for a dataset of shape ``(0, *shape)``."""
    if not shape:
        return (1024,)
    per_row = itemsize * int(np.prod(shape[1:], dtype=np.int64)) if len(shape) > 1 else itemsize
    rows = max(1, min(shape[0], MAX_CHUNK_BYTES // max(per_row, 1)))
    return (1, rows) + tuple(shape[1:])


def fill_value(dtype):
    """The value of a removed particle's rows: NaN (float, complex), -1 (signed int), 0
    (unsigned), False (bool); also the datasets' HDF5 fill value."""
    dtype = np.dtype(dtype)
    if dtype.kind in "fc":
        return dtype.type(np.nan)
    if dtype.kind == "i":
        return dtype.type(-1)
    return dtype.type(0)


def storage_dtype(a):
    a = np.asarray(a)
    if a.dtype.kind == "f":
        return np.dtype(np.float64)
    if a.dtype.kind in "iub":
        return a.dtype
    if a.dtype.kind == "c":
        return np.dtype(np.complex128)
    raise TypeError(f"cannot store values of dtype {a.dtype} in H5MD")


def h5group():
    import h5py
    return h5py.Group


def is_h5md_file(path):
    import h5py
    if not os.path.isfile(path):
        return False
    try:
        with h5py.File(path, "r") as f:
            return TRAJ in f
    except OSError:
        return False
