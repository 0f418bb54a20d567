"""clusterdyn: mesoscale particle simulation of deformation, shock and fracture of solids.

Two methods, in the ASE ecosystem: Cluster Dynamics (CD) and Movable Cellular
Automata (MCA).  Force models are ASE calculators on numba kernels, samples
are ASE Atoms, dynamics are ASE MolecularDynamics subclasses, output is H5MD.
"""

__version__ = "0.1.0"

from . import units  # noqa: F401
from .errors import InputError, InstabilityError  # noqa: F401
