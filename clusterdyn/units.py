"""Units: everything of :mod:`ase.units` plus the mesoscale units users think in.

Inside clusterdyn every quantity is in ASE units (length Angstrom, energy eV,
mass amu, time in ASE's unit).  Users write ``r0 = 5 * units.um`` or
``u = 2 * units.km_s`` and never convert by hand.

Also here: the conversion factors the H5MD writer uses to produce the unit
strings MDAnalysis accepts (it has no eV-based force unit).
"""

from ase.units import *  # noqa: F401,F403  (re-export: Ang, eV, fs, GPa, kg, m, s, J, mol, kJ, ...)
from ase import units as _u

#: length
m = _u.m
mm = 1e-3 * _u.m
um = 1e-6 * _u.m
nm = _u.nm
#: time
s = _u.s
ms = 1e-3 * _u.s
us = 1e-6 * _u.s
ns = 1e-9 * _u.s
ps = 1e-12 * _u.s
#: velocity
m_s = _u.m / _u.s
km_s = 1e3 * _u.m / _u.s
#: mass and density
kg = _u.kg
g = 1e-3 * _u.kg
g_cm3 = 1e-3 * _u.kg / (1e-2 * _u.m) ** 3
kg_m3 = _u.kg / _u.m ** 3
#: energy, force, pressure
J = _u.J
N = _u.J / _u.m
GPa = _u.GPa
MPa = 1e-3 * _u.GPa
Pa = 1e-9 * _u.GPa
#: specific energy
kJ_g = 1e3 * _u.J / (1e-3 * _u.kg)

# --- factors for H5MD output in MDAnalysis units (multiply ASE value by these)
PS = 1000.0 * _u.fs                      #: ASE time units per picosecond
TIME_TO_PS = 1.0 / PS                    #: ASE time -> ps
VEL_TO_A_PER_PS = PS                     #: Angstrom/ASE-time -> Angstrom ps-1
FORCE_TO_KJMOL_A = _u.mol / _u.kJ        #: eV/Angstrom -> kJ mol-1 Angstrom-1
ENERGY_TO_KJMOL = _u.mol / _u.kJ         #: eV -> kJ mol-1

#: Names accepted by the command-line parser (``u=3km/s``), value in ASE units.
NAMED = {
    "A": 1.0, "Ang": 1.0, "nm": nm, "um": um, "mm": mm, "m": m, "cm": 1e-2 * m,
    "fs": _u.fs, "ps": ps, "ns": ns, "us": us, "ms": ms, "s": s,
    "m/s": m_s, "km/s": km_s, "mm/us": km_s, "um/ns": km_s,
    "g/cm3": g_cm3, "kg/m3": kg_m3,
    "GPa": GPa, "MPa": MPa, "Pa": Pa,
    "eV": _u.eV, "J": J, "N": N, "kg": kg, "g": g, "amu": 1.0,
}

#: Unit label -> factor, used to express results (value_in_label = ase_value / factor).
LABELS = {"km/s": km_s, "m/s": m_s, "GPa": GPa, "g/cm3": g_cm3, "um": um, "mm": mm,
          "ns": ns, "us": us, "N": N, "J": J, "s": s}
