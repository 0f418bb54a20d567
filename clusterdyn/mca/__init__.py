"""Movable Cellular Automata (MCA): calculator, dynamics, builders, response functions, scenes.

physics.md section 2 gives the equations; docs/mca.md the choices we made.

Public API (also re-exported where ASE users look for them)::

    from clusterdyn.calculators import MCA          # clusterdyn.mca.calculator.MCA
    from clusterdyn.md import MCADynamics           # clusterdyn.mca.dynamics.MCADynamics
    from clusterdyn.build import mca_packing, precrack

Importing this package registers the MCA material library (alumina,
concrete, Al6061, copper); :mod:`clusterdyn.materials` does so too.
The heavier modules load on first attribute access (no import cycles with
:mod:`clusterdyn.materials`).
"""

import importlib

from . import materials  # noqa: F401  (registers the MCA material library)

_LAZY = {
    "MCA": "calculator", "MCAState": "state", "MCADynamics": "dynamics", "Grip": "dynamics",
    "default_timestep": "dynamics", "wave_speeds": "dynamics", "mca_packing": "builders",
    "precrack": "builders", "notch": "builders", "mca_material": "materials",
}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
