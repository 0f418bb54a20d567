"""Materials: cold curves and the material library."""

from .curves import ColdCurve, MurnaghanCurve, TabulatedCurve
from .library import (Hugoniot, Material, get_material, hugoniot, hugoniots, load_al_table,
                      material_names, register_material)

__all__ = ["ColdCurve", "MurnaghanCurve", "TabulatedCurve", "Material", "get_material",
           "hugoniot", "hugoniots", "Hugoniot", "load_al_table", "material_names",
           "register_material"]
from . import mca as _mca_materials  # noqa: E402,F401  (MCA library: alumina, concrete, Al6061, copper)
