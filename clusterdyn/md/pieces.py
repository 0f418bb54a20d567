"""The attach point of :class:`clusterdyn.md.DampedVerlet`: pieces that act at fixed points of a step.

A step of the dynamics is (docs/architecture.md)::

    drives.begin_step; constraints.adjust_momenta
    first half kick + drift          (the engine's fused pass, or the separate passes)
    drives.end_drift
    piece.before_forces(...)         each piece reads the state before the pass (half-step momenta)
    forces: the pair pass (with the second half kick inside it)
            -> piece.add_forces(...)  each piece adds its forces and kicks its rows
            -> constraints.adjust_forces; drives.kick_extra
    constraints.adjust_momenta
    piece.end_step()                 removal, sorting (they renumber the particles)

A piece is attached with ``dyn.attach_piece(piece)``; :class:`clusterdyn.md.region.Removal` and
:class:`clusterdyn.md.sorting.Sorting` are pieces (made by DampedVerlet's ``region=`` and
``sort_interval=``), and an extra force term (a list of bonded pairs with a history, say) is one
too: it overrides :meth:`Piece.add_forces` and :meth:`Piece.energy`, and follows the particles
through :meth:`Piece.reindexed` and :meth:`Piece.compacted`.  Its state goes into checkpoints
through :meth:`Piece.get_state` / :meth:`Piece.set_state` under its :attr:`Piece.name`.
"""


#: the piece classes by name, for restoring a checkpoint's pieces that are not attached yet
PIECE_KINDS = {}


class Piece:
    """Base of the pieces attached to a :class:`~clusterdyn.md.DampedVerlet` (every hook a no-op).

    :attr:`adds_forces` tells the dynamics that :meth:`add_forces` adds forces (a removal then
    recomputes the forces rather than subtracting the removed pairs from the step's)."""

    #: key of the piece's state in checkpoints (``get_state()["pieces"][name]``)
    name = "piece"
    #: True when :meth:`add_forces` adds forces
    adds_forces = False
    #: energy this piece has dissipated since the start (eV), booked in the energy ledger
    dissipated = 0.0

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        PIECE_KINDS[cls.__name__] = cls

    @classmethod
    def from_state(cls, state):
        """A piece made from :meth:`get_state`'s dict alone (a checkpoint loaded without its scene);
        pieces that cannot be rebuilt so refuse."""
        raise NotImplementedError(f"{cls.__name__} is rebuilt by its scene, not from its state")

    def bind(self, dyn):
        """Called by ``dyn.attach_piece``; the piece may keep ``dyn``."""
        self.dyn = dyn

    def before_forces(self, atoms, kick):
        """Before the pair pass of a force evaluation: with ``kick`` (a step's pass) the momenta
        are still the half-step ones; ``kick`` is None for a pass outside a step."""

    def add_forces(self, atoms, forces, kick):
        """After the pair pass, before the constraints: add this term's forces to ``forces``
        ((N, 3), eV/Angstrom, in place) and, when ``kick`` (a float h) is given, add ``h`` times
        them to ``atoms.arrays['momenta']`` (the second half kick, which the pair pass has
        already given its own forces)."""

    def energy(self, atoms):
        """The potential energy this term adds (eV): part of ``dyn.potential_energy`` and of
        the energy ledger."""
        return 0.0

    def end_step(self):
        """At the end of a step, after the constraints' momenta (removal, sorting)."""

    def reindexed(self, order):
        """The particles were reordered: new particle k is old particle ``order[k]``."""

    def compacted(self, keep):
        """Particles were removed: ``keep`` (ascending) are the old indices kept, in order."""

    def get_state(self):
        """The piece's state for a checkpoint (a dict of numbers and arrays; a ``kind`` key naming
        the class lets a checkpoint loaded alone rebuild it with :meth:`from_state`)."""
        return {}

    def set_state(self, state):
        """Restore :meth:`get_state`'s dict."""
