"""MCA material library (docs/theory.md 2.5): alumina, concrete, aluminium 6061, copper.

Registered through :func:`clusterdyn.materials.register_material`, so
``get_material("alumina")`` works without importing :mod:`clusterdyn.mca`.
This module imports only :mod:`clusterdyn.materials.library`,
:mod:`clusterdyn.units` and :mod:`clusterdyn.errors` (no circular import).

Every value is a textbook room-temperature value (sources in ``source``);
moduli and strengths in ASE units (eV/Angstrom^3), density in amu/Angstrom^3.

MCA-specific parameters live in ``Material.extra``:

``mu``
    Coulomb friction coefficient of unlinked pairs (default 0.3)
``sigma_weld``
    compressive normal stress above which an unlinked pair welds (healing),
    eV/Angstrom^3; ``None`` = no healing
``n_weld``
    steps the pair must stay above ``sigma_weld`` (default 20)
``sigma_d``
    onset of degradation for response "degrading" (Fig. 3b)
``D_c``
    damage reached at sigma_c where the pair unlinks (default 0.8)
``eps_d``, ``eps_f``
    plastic strain at onset / end of degradation (response "plastic-degrading", Fig. 3d)
``johnson_cook``
    dict A, B (eV/Angstrom^3), n, C, eps0 (1/s): J2 flow with the Johnson-Cook curve and an
    implicit radial return (:mod:`clusterdyn.mca.response.plastic`); ``Al6061-T6``.  With
    m, T_melt, T_room (K), c_p (eV/(amu K)) and beta also Johnson-Cook's thermal term and
    adiabatic heating of each automaton; ``Al6061-T6-thermal``
"""

from .. import units
from ..errors import InputError
from .library import Material, register_material

#: names of the response functions (MCA Fig. 3)
RESPONSES = ("elastic", "elastic-brittle", "degrading", "elastic-plastic", "plastic-degrading")


def check_mca_material(mat):
    """Validate the elastic constants and strengths an MCA material needs (InputError)."""
    if mat.E is None or mat.nu is None:
        raise InputError("material", mat.name, "a material with E and nu (MCA)")
    if not mat.E > 0:
        raise InputError("E", mat.E, "a positive Young's modulus")
    if not (-1.0 < mat.nu < 0.5):
        raise InputError("nu", mat.nu, "a Poisson ratio in the open interval (-1, 0.5)")
    if not mat.rho0 > 0:
        raise InputError("rho0", mat.rho0, "a positive density")
    resp = mat.response or "elastic"
    if resp not in RESPONSES:
        raise InputError("response", resp, "one of " + ", ".join(RESPONSES))
    for name in ("sigma_t", "sigma_c", "sigma_y"):
        v = getattr(mat, name)
        if v is not None and not v > 0:
            raise InputError(name, v, "a positive strength (eV/Angstrom^3) or None")
    if resp in ("elastic-brittle", "degrading"):
        if mat.sigma_t is None or mat.sigma_c is None:
            raise InputError("sigma_t/sigma_c", (mat.sigma_t, mat.sigma_c),
                             f"both strengths for response '{resp}' (Drucker-Prager)")
    if mat.sigma_t is not None and mat.sigma_c is not None and mat.sigma_c < mat.sigma_t:
        raise InputError("sigma_c", mat.sigma_c,
                         f"sigma_c >= sigma_t = {mat.sigma_t:.6g} (Drucker-Prager beta = "
                         "sigma_c/sigma_t must be >= 1)")
    if resp in ("elastic-plastic", "plastic-degrading") and mat.sigma_y is None:
        raise InputError("sigma_y", None, f"a yield stress for response '{resp}'")
    if resp == "degrading":
        sd = mat.extra.get("sigma_d", 0.7 * mat.sigma_c)
        if not 0 < sd < mat.sigma_c:
            raise InputError("sigma_d", sd, "0 < sigma_d < sigma_c")
    return mat


def mca_material(name, rho_g_cm3, E_GPa, nu, sigma_t_GPa=None, sigma_c_GPa=None,
                 sigma_y_GPa=None, response="elastic-brittle", hardening=None, source="", **extra):
    """Build an MCA :class:`Material` from values in GPa and g/cm3."""
    g = units.GPa
    mat = Material(name=name, rho0=rho_g_cm3 * units.g_cm3, E=E_GPa * g, nu=nu,
                   sigma_t=None if sigma_t_GPa is None else sigma_t_GPa * g,
                   sigma_c=None if sigma_c_GPa is None else sigma_c_GPa * g,
                   sigma_y=None if sigma_y_GPa is None else sigma_y_GPa * g,
                   hardening=hardening, response=response, source=source, extra=dict(extra))
    return check_mca_material(mat)


def _alumina():
    return mca_material(
        "alumina", 3.9, 370.0, 0.22, sigma_t_GPa=0.3, sigma_c_GPa=2.5, response="elastic-brittle",
        mu=0.3,
        source=("Dense alumina (99.5% Al2O3), textbook values: M. F. Ashby, D. R. H. Jones, "
                "Engineering Materials 2, 4th ed. (2013), ch. 15-17; rho 3.9 g/cm3, E 370 GPa, "
                "nu 0.22, tensile (modulus of rupture) 0.3 GPa, compressive 2.5 GPa; "
                "values as fixed in docs/theory.md 2.5"))


def _concrete():
    return mca_material(
        "concrete", 2.4, 30.0, 0.2, sigma_t_GPa=0.003, sigma_c_GPa=0.030, response="degrading",
        mu=0.5, sigma_d=0.021 * units.GPa, D_c=0.8,
        source=("Normal-strength concrete, textbook values: A. M. Neville, Properties of Concrete, "
                "5th ed. (2011); rho 2.4 g/cm3, E 30 GPa, nu 0.2, tensile 3 MPa, compressive 30 MPa; "
                "degradation onset sigma_d = 0.7 sigma_c (our choice); docs/theory.md 2.5"))


def _al6061():
    return mca_material(
        "Al6061", 2.7, 69.0, 0.33, sigma_y_GPa=0.28, response="elastic-plastic",
        hardening=None, mu=0.3,
        source=("Aluminium alloy 6061-T6: ASM Handbook vol. 2 (1990), Properties of wrought "
                "aluminum alloys; rho 2.7 g/cm3, E 69 GPa, nu 0.33, yield 0.28 GPa "
                "(perfectly plastic unless a hardening curve is given); docs/theory.md 2.5"))


#: Johnson-Cook strength of 6061-T6 (ASE units); the thermal variant adds its thermal term
_AL6061_T6_JC = {"A": 0.324 * units.GPa, "B": 0.114 * units.GPa, "n": 0.42, "C": 0.002, "eps0": 1.0}


def _al6061_t6():
    return mca_material(
        "Al6061-T6", 2.7, 69.0, 0.33, sigma_y_GPa=0.324, response="elastic-plastic",
        hardening=None, mu=0.3, johnson_cook=dict(_AL6061_T6_JC),
        source=("Aluminium alloy 6061-T6 with Johnson-Cook strength: A 324 MPa, B 114 MPa, "
                "n 0.42, C 0.002, eps0 1/s (thermal term m 1.34, T_melt 925 K not modelled): "
                "D. R. Lesuer, G. J. Kay, M. M. LeBlanc, Modeling large-strain, high-rate "
                "deformation in metals, LLNL report UCRL-JC-134118 (2001), table of Johnson-Cook "
                "constants, the set used for 6061-T6 Taylor-test simulations; B and n as in Sandia's "
                "Payette material database (al_6061.py, 'power law hardening' 114e6 Pa, 0.42). "
                "rho 2.7 g/cm3, E 69 GPa, nu 0.33 as Al6061 (ASM Handbook vol. 2, 1990)"))


def _al6061_t6_thermal():
    jc = {**_AL6061_T6_JC, "m": 1.34, "T_melt": 925.0, "T_room": 294.0, "c_p": 896.0 * units.J / units.kg,
          "beta": 0.9}       # Taylor-Quinney (clusterdyn.mca.response.plastic.TAYLOR_QUINNEY)
    return mca_material(
        "Al6061-T6-thermal", 2.7, 69.0, 0.33, sigma_y_GPa=0.324, response="elastic-plastic",
        hardening=None, mu=0.3, johnson_cook=jc,
        source=("Al6061-T6 (same Johnson-Cook A, B, n, C, eps0 and elastic constants) with Johnson-Cook's "
                "thermal term and adiabatic heating: m 1.34, T_melt 925 K from the same Johnson-Cook set "
                "(D. R. Lesuer, G. J. Kay, M. M. LeBlanc, LLNL report UCRL-JC-134118, 2001); specific heat "
                "c_p 896 J/(kg K) from Sandia's Payette material database (al_6061.py, MatWeb values); "
                "T_room 294 K (the temperature of the Wilkins-Guinan tests); Taylor-Quinney share "
                "beta 0.9 of the plastic work heats (our choice, the common value)"))


def _copper():
    return mca_material(
        "copper", 8.96, 120.0, 0.34, sigma_y_GPa=0.07, response="elastic-plastic",
        hardening=None, mu=0.3,
        source=("Annealed OFHC copper: ASM Handbook vol. 2 (1990), Properties of pure metals; "
                "rho 8.96 g/cm3, E 120 GPa, nu 0.34, yield 0.07 GPa; docs/theory.md 2.5"))


MCA_MATERIALS = {"alumina": _alumina, "concrete": _concrete, "Al6061": _al6061,
                 "Al6061-T6": _al6061_t6, "Al6061-T6-thermal": _al6061_t6_thermal, "copper": _copper}

for _name, _builder in MCA_MATERIALS.items():
    register_material(_name, _builder)
