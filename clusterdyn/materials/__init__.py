"""Materials: cold curves and the material library."""

from .curves import TAILS, ColdCurve, MurnaghanCurve, TabulatedCurve, fit_murnaghan
from .library import (Hugoniot, Material, cd_material_names, get_material, hugoniot, hugoniots, load_al_table,
                      material_names, register_material)

__all__ = ["ColdCurve", "MurnaghanCurve", "TabulatedCurve", "Material", "get_material",
           "hugoniot", "hugoniots", "Hugoniot", "load_al_table", "material_names",
           "register_material", "cd_material_names", "fit_murnaghan", "TAILS"]
from . import mca as _mca_materials  # noqa: E402,F401  (MCA library: alumina, concrete, Al6061, copper)
