"""Sorting the Atoms into the neighbour list's cell order: :class:`Sorting`, the piece of
:class:`clusterdyn.md.DampedVerlet` made by its ``sort_interval`` (as LAMMPS' ``atom_modify sort``)."""

from .pieces import Piece


class Sorting(Piece):
    """Every ``interval`` steps (at the end of a step, after a removal) put the Atoms into the
    engine's row order (:meth:`clusterdyn.md.DampedVerlet.sort_atoms`); :attr:`nsorts` counts the
    sorts done."""

    name = "sorting"
    order = 20

    def __init__(self, interval):
        self.interval = interval
        self.nsorts = 0

    def end_step(self):
        if (self.dyn.nsteps + 1) % self.interval == 0:
            self.dyn.sort_atoms()
