"""Movable Cellular Automata (MCA): calculator, state, dynamics, response functions, kernels.

docs/theory.md (MCA sections) gives the equations; docs/mca.md the choices we made.
The MCA method sits above the calculators and dynamics layers and shares them
(neighbour lists, drives); nothing below it imports it.  Its pieces that belong
to lower layers live there: the material library in :mod:`clusterdyn.materials.mca`,
the builders in :mod:`clusterdyn.build.mca` (with the tessellation in
:mod:`clusterdyn.build.tessellation`); its experiments and scenes in
:mod:`clusterdyn.scenes`, its studies in :mod:`clusterdyn.studies`.

Public API::

    from clusterdyn.mca import MCA, MCADynamics, MCAState
    from clusterdyn.mca import SegmentContact, stack_blocks     # 2D segment contact and friction
    from clusterdyn.build import mca_packing, precrack, notch
    from clusterdyn.materials.mca import mca_material
"""

import importlib

_LAZY = {
    "MCA": "calculator", "MCAState": "state", "MCADynamics": "dynamics",
    "default_timestep": "dynamics", "wave_speeds": "dynamics",
    "SegmentContact": "contact", "stack_blocks": "contact",
}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
