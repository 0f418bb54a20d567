"""The material library: records with their sources, and experimental Hugoniots."""

import csv
import dataclasses
import math
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from .. import units
from ..errors import InputError
from .curves import ColdCurve, MurnaghanCurve, TabulatedCurve


@dataclass(frozen=True)
class Material:
    """A material: density, cold curve (CD) and/or elastic constants and strengths (MCA).

    All values in ASE units (density amu/Angstrom^3, moduli and strengths
    eV/Angstrom^3).  ``hugoniot`` names a row of the experimental Hugoniot table
    (:func:`hugoniot`) used as the reference of shock scenes.
    """

    name: str
    rho0: float
    curve: ColdCurve = None
    source: str = ""
    hugoniot: str = None
    # elastic constants and strengths (MCA); None where not given
    E: float = None
    nu: float = None
    sigma_t: float = None
    sigma_c: float = None
    sigma_y: float = None
    hardening: object = None
    response: str = None
    extra: dict = field(default_factory=dict)

    @property
    def K(self):
        """Bulk modulus from (E, nu) if given, else the cold curve's K0."""
        if self.E is not None and self.nu is not None:
            return self.E / (3.0 * (1.0 - 2.0 * self.nu))
        if self.curve is not None:
            return self.curve.K0
        return None

    @property
    def G(self):
        """Shear modulus from (E, nu), or None."""
        if self.E is not None and self.nu is not None:
            return self.E / (2.0 * (1.0 + self.nu))
        return None

    @property
    def c0(self):
        """Bulk sound speed at rest of the cold curve (Angstrom/ASE time)."""
        if self.curve is None:
            raise InputError("material", self.name, "a material with a cold curve (CD)")
        return self.curve.c0

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)


def _data_path(name):
    return resources.files("clusterdyn") / "data" / name


def load_al_table():
    """Rows of the CD paper's Table 1 as a dict of numpy arrays (original units)."""
    with _data_path("al_cold_curve.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def _aluminium():
    t = load_al_table()
    rho0 = 2.71 * units.g_cm3
    delta = t["rho_g_cm3"] / 2.71          # the rho column is exact; delta is rounded to 3 digits
    curve = TabulatedCurve(delta, t["eps_x_kJ_g"] * units.kJ_g, t["P_x_GPa"] * units.GPa, rho0)
    return Material(
        name="Al", rho0=rho0, curve=curve, hugoniot="Al-1100",
        source=("Cold curve: Table 1 of Davydov et al., 'Modelling high-rate deformation by the "
                "cluster dynamics method' (VNIIEF); from Glushak, Gudarenko, Styazhkin, Zherebtsov, "
                "VANT ser. Mat. Mod. Fiz. Proc. 1991(1) 32-37"),
    )


def _murnaghan(name, rho, c0, n, hug=None):
    rho0 = rho * units.g_cm3
    return Material(
        name=name, rho0=rho0, curve=MurnaghanCurve(rho0, c0 * units.km_s, n), hugoniot=hug,
        source=(f"Tait/Murnaghan parameters rho0={rho} g/cm3, c0={c0} km/s, n={n} from Davydov et al., "
                "'Modelling high-rate deformation by the cluster dynamics method' (VNIIEF)"),
    )


_BUILDERS = {
    "Al": _aluminium,
    "Pb": lambda: _murnaghan("Pb", 11.34, 1.972, 3.0, "Pb"),
    "B4C": lambda: _murnaghan("B4C", 2.51, 9.06, 3.13),
    "h-BN": lambda: _murnaghan("h-BN", 2.29, 3.19, 10.41),
}
_CACHE = {}


def register_material(name, builder):
    """Add a material to the library; ``builder()`` returns a :class:`Material`."""
    _BUILDERS[name] = builder
    _CACHE.pop(name, None)


def material_names():
    return list(_BUILDERS)


def get_material(name):
    """Return the library material ``name`` (e.g. ``"Al"``, ``"Pb"``, ``"B4C"``, ``"h-BN"``).

    A :class:`Material` passed in is returned unchanged.
    """
    if isinstance(name, Material):
        return name
    if name not in _BUILDERS:
        raise InputError("material", name, "one of " + ", ".join(sorted(_BUILDERS)))
    if name not in _CACHE:
        _CACHE[name] = _BUILDERS[name]()
    return _CACHE[name]


@dataclass(frozen=True)
class Hugoniot:
    """Experimental Hugoniot in Steinberg's form D = c0 + s1 u + s2 u^2/D + s3 u^3/D^2.

    ``c0`` in km/s, ``rho0`` in g/cm3 (as in the table); :meth:`D` takes and returns
    ASE velocities.
    """

    name: str
    rho0_g_cm3: float
    c0_km_s: float
    s1: float
    s2: float
    s3: float
    gamma0: float
    valid_u_km_s: str
    source: str

    def D(self, u):
        """Shock speed for particle velocity u (ASE units, array ok)."""
        uk = np.asarray(u, dtype=float) / units.km_s
        d = self.c0_km_s + self.s1 * uk
        for _ in range(100):
            d_new = self.c0_km_s + self.s1 * uk + self.s2 * uk ** 2 / d + self.s3 * uk ** 3 / d ** 2
            if np.all(abs(d_new - d) < 1e-13):
                break
            d = d_new
        return d_new * units.km_s

    def pressure(self, u):
        """Longitudinal stress behind the front, rho0 D u (ASE units)."""
        return self.rho0_g_cm3 * units.g_cm3 * self.D(u) * np.asarray(u)

    def density(self, u):
        D = self.D(u)
        return self.rho0_g_cm3 * units.g_cm3 * D / (D - np.asarray(u))


def hugoniots():
    """All rows of the experimental Hugoniot table, by name."""
    with _data_path("hugoniot.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    out = {}
    for r in rows:
        out[r["material"]] = Hugoniot(r["material"], float(r["rho0_g_cm3"]), float(r["c0_km_s"]),
                                      float(r["s1"]), float(r["s2"]), float(r["s3"]),
                                      float(r["gamma0"]), r["valid_u_km_s"], r["source"])
    return out


def hugoniot(name):
    """Experimental Hugoniot by table name (``"Al-1100"``) or by material (``"Al"``)."""
    table = hugoniots()
    if name in table:
        return table[name]
    if name in _BUILDERS:
        key = get_material(name).hugoniot
        if key is not None:
            return table[key]
    raise InputError("hugoniot", name, "one of " + ", ".join(table)
                     + " or a material with a reference Hugoniot")
