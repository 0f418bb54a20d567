"""Response functions of MCA (MCA Fig. 3), one small module each.

* :mod:`.brittle`   (a) linear elastic, the pair unlinks by Drucker-Prager
* :mod:`.degrading` (b) damage from sigma_d to sigma_c, unloading at the damaged modulus
* :mod:`.plastic`   (c) elastic-plastic, radial return on the automaton, hardening table
* :mod:`.plastic_degrading` (d) plastic with damage growing with plastic strain
* :mod:`.healing`   unlinked -> linked under sustained compression (micro-welding)

Each is a commit-time kernel: it receives the trial (elastic predictor)
state computed by the calculator and corrects it; the dynamics runs only
the kernels the materials of the sample need.
"""

from . import brittle, degrading, healing, plastic, plastic_degrading  # noqa: F401
