"""The material library: records with their sources, and experimental Hugoniots."""

import csv
import dataclasses
import math
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from .. import units
from ..errors import InputError, check_positive
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

    @classmethod
    def from_hugoniot(cls, name, rho0, c0, s, source, hugoniot=None):
        """A CD material from a measured Hugoniot ``D = c0 + s u`` (docs/theory.md, "Materials from shock data").

        The cold curve is the Tait/Murnaghan form with ``K0 = rho0 c0^2`` and
        ``n = 4 s - 1`` (the weak-shock slope of a Tait Hugoniot is (n + 1)/4).

        Parameters
        ----------
        name : str
            Material name.
        rho0 : float
            Density at rest, amu/Angstrom^3 (``2.703 * units.g_cm3``).
        c0 : float
            Hugoniot intercept (bulk sound speed), Angstrom/ASE time (``5.24 * units.km_s``).
        s : float
            Hugoniot slope, > 0.25 (so that n > 0).
        source : str
            Where the Hugoniot comes from (required, non-empty).
        hugoniot : str, optional
            Row of the experimental Hugoniot table (:func:`hugoniot`) to compare with.
        """
        rho0 = check_positive("rho0", rho0)
        c0 = check_positive("c0", c0)
        try:
            s = float(s)
        except (TypeError, ValueError):
            raise InputError("s", s, "a Hugoniot slope > 0.25 (n = 4 s - 1 > 0)") from None
        if not (math.isfinite(s) and s > 0.25):
            raise InputError("s", s, "a Hugoniot slope > 0.25 (n = 4 s - 1 > 0)")
        if not isinstance(source, str) or not source.strip():
            raise InputError("source", source, "a non-empty text naming the Hugoniot's source")
        return cls(name=name, rho0=rho0, curve=MurnaghanCurve(rho0, c0, 4.0 * s - 1.0), source=source,
                   hugoniot=hugoniot)


def _data_path(name):
    return resources.files("clusterdyn") / "data" / name


def load_al_table():
    """Rows of the CD paper's Table 1 as a dict of numpy arrays (original units)."""
    with _data_path("al_cold_curve.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def _aluminium(tail="murnaghan"):
    t = load_al_table()
    rho0 = 2.71 * units.g_cm3
    delta = t["rho_g_cm3"] / 2.71          # the rho column is exact; delta is rounded to 3 digits
    curve = TabulatedCurve(delta, t["eps_x_kJ_g"] * units.kJ_g, t["P_x_GPa"] * units.GPa, rho0, tail=tail)
    rule = ("the table's own Murnaghan form P = A (delta^n - 1), fitted to the rows with delta >= 0.751, "
            "scaled to the densest row's value" if tail == "murnaghan" else
            "a Tait form slope-matched at the densest row, with the exponent n of the table's own Murnaghan fit")
    return Material(
        name="Al" if tail == "murnaghan" else "Al-" + tail, rho0=rho0, curve=curve, hugoniot="Al-1100",
        source=("Cold curve: Table 1 of Davydov et al., 'Modelling high-rate deformation by the "
                "cluster dynamics method' (VNIIEF); from Glushak, Gudarenko, Styazhkin, Zherebtsov, "
                f"VANT ser. Mat. Mod. Fiz. Proc. 1991(1) 32-37. Beyond delta = 2.37: {rule}"),
    )


def _murnaghan(name, rho, c0, n, hug=None):
    rho0 = rho * units.g_cm3
    return Material(
        name=name, rho0=rho0, curve=MurnaghanCurve(rho0, c0 * units.km_s, n), hugoniot=hug,
        source=(f"Tait/Murnaghan parameters rho0={rho} g/cm3, c0={c0} km/s, n={n} from Davydov et al., "
                "'Modelling high-rate deformation by the cluster dynamics method' (VNIIEF)"),
    )


#: materials from shock data (Material.from_hugoniot): name -> (row of data/hugoniot.csv, source text).
#: The row gives rho0, c0 and s; data/SOURCES.md says where each row comes from.
_FROM_HUGONIOT = {
    "Al-6061-T6": ("Al-6061-T6", "Hugoniot of aluminium 6061-T6, Steinberg UCRL-MA-106439 (1996)"),
    "Al-2024": ("Al-2024", "Hugoniot of aluminium 2024, Marsh (ed.) LASL Shock Hugoniot Data (1980); the "
                "nearest documented alloy to the 2017-T4 of the Piekutowski sphere tests (both Al-Cu-Mg, "
                "2.79 g/cm3): no sourced 2017 Hugoniot was found"),
    "steel": ("steel-4340", "Hugoniot of 4340 steel (RC 38), Steinberg UCRL-MA-106439 (1996); stands in for "
              "the striker and plate steels of the multilayer target"),
    "textolite": ("textolite-est", "ESTIMATE, no sourced Hugoniot of textolite (phenolic cotton-fabric "
                  "laminate) was found: density 1.35 g/cm3 (middle of the usual 1.3-1.4 g/cm3 of textolite, "
                  "not a sourced value) with the line of a cured thermoset resin, epoxy Epon 828 (c0 = 2.678 km/s, s = 1.52; "
                  "Kinslow (ed.) High-Velocity Impact Phenomena (1970), appendix)"),
    "paraffin": ("paraffin-est", "ESTIMATE: the only sourced paraffin fit found (0.900 g/cm3, c0 = 2.960 km/s, "
                 "s = 2.531; Kinslow (ed.) High-Velocity Impact Phenomena (1970), appendix) has a slope far "
                 "above every (CH2)n polymer's (perhaps a low-pressure fit or a misprint; not checked against "
                 "the book); used instead: paraffin's density 0.900 g/cm3 with the line of polyethylene, the "
                 "same (CH2)n chain (c0 = 2.901 km/s, s = 1.481; low-density polyethylene, Kinslow (ed.) "
                 "High-Velocity Impact Phenomena (1970), appendix)"),
}


def _from_hugoniot_row(name):
    key, source = _FROM_HUGONIOT[name]
    h = hugoniots()[key]
    if h.s2 != 0 or h.s3 != 0:
        raise InputError("hugoniot", key, "a linear Hugoniot row (s2 = s3 = 0) for Material.from_hugoniot")
    return Material.from_hugoniot(name, h.rho0_g_cm3 * units.g_cm3, h.c0_km_s * units.km_s, h.s1,
                                  source, hugoniot=key)


_BUILDERS = {
    "Al": _aluminium,
    "Al-tait": lambda: _aluminium("tait"),
    "Pb": lambda: _murnaghan("Pb", 11.34, 1.972, 3.0, "Pb"),
    "B4C": lambda: _murnaghan("B4C", 2.51, 9.06, 3.13),
    "h-BN": lambda: _murnaghan("h-BN", 2.29, 3.19, 10.41),
}
for _name in _FROM_HUGONIOT:
    _BUILDERS[_name] = (lambda n: (lambda: _from_hugoniot_row(n)))(_name)
_CACHE = {}


def register_material(name, builder):
    """Add a material to the library; ``builder()`` returns a :class:`Material`."""
    _BUILDERS[name] = builder
    _CACHE.pop(name, None)


def material_names():
    return list(_BUILDERS)


def cd_material_names():
    """Names of the library materials with a cold curve (usable by Cluster Dynamics)."""
    return [n for n in _BUILDERS if get_material(n).curve is not None]


def get_material(name):
    """Return the library material ``name`` (e.g. ``"Al"``, ``"Pb"``, ``"B4C"``, ``"h-BN"``).

    ``"Al-tait"`` is aluminium with the slope-matched Tait tail beyond the cold
    table's densest row instead of the default scaled Murnaghan tail
    (:class:`~clusterdyn.materials.TabulatedCurve`), to see the tail's effect.
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

    @property
    def u_max(self):
        """Top of the measured particle-velocity range (ASE units; inf when the table gives none).
        Above it :meth:`D` extrapolates the fit."""
        hi = self.valid_u_km_s.split("-")[-1].strip() if self.valid_u_km_s else ""
        return float(hi) * units.km_s if hi else np.inf

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
