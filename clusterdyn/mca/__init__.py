"""Movable Cellular Automata (MCA): calculator, dynamics, builders, response functions, scenes.

physics.md section 2 gives the equations; docs/mca.md the choices we made.
"""

from . import materials  # noqa: F401  (registers the MCA material library)
