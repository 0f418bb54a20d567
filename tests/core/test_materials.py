"""Cold curves and the CD pair potential against the paper's Table 1 (physics.md 1.1-1.2)."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.materials import MurnaghanCurve, get_material, hugoniot, load_al_table
from clusterdyn.potentials import ClusterPotential


@pytest.fixture(scope="module")
def al():
    return ClusterPotential("Al", 5 * units.um)


def test_table1_energy_and_force_all_rows(al):
    t = load_al_table()
    r = t["r_m"] * units.m
    E = al.energy(r) / units.J
    f = al.force(r) / units.N
    assert len(r) == 12
    for k in range(12):
        if t["r_over_r0"][k] == 1.0:
            # exactly zero at r0 (the row's r in metres differs from r0 by round-off)
            assert al.energy(al.r0) == 0.0 and al.force(al.r0) == 0.0
            assert abs(E[k]) < 1e-25 and abs(f[k]) < 1e-12
        else:
            assert E[k] == pytest.approx(t["E_J"][k], rel=5e-3), f"E row {k}"
            assert f[k] == pytest.approx(t["f_N"][k], rel=5e-3), f"f row {k}"


def test_table_rows_honoured_exactly():
    c = get_material("Al").curve
    t = load_al_table()
    d = t["rho_g_cm3"] / 2.71
    np.testing.assert_allclose(c.energy(d) / units.kJ_g, t["eps_x_kJ_g"], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(c.pressure(d) / units.GPa, t["P_x_GPa"], rtol=1e-10, atol=1e-9)


def test_force_is_minus_energy_derivative(al):
    r = np.linspace(0.72, 1.35, 300) * al.r0
    h = 1e-5 * al.r0
    fd = -(al.energy(r + h) - al.energy(r - h)) / (2 * h)
    scale = np.abs(al.force(r)).max()
    assert np.abs(fd - al.force(r)).max() / scale < 1e-6


@pytest.mark.parametrize("name", ["Pb", "B4C", "h-BN"])
def test_murnaghan_energy_consistent(name):
    c = get_material(name).curve
    d = np.linspace(0.5, 2.5, 50)
    h = 1e-6
    slope = (c.energy(d + h) - c.energy(d - h)) / (2 * h)
    np.testing.assert_allclose(slope, c.pressure(d) / (c.rho0 * d ** 2), rtol=1e-6, atol=1e-12)
    assert c.energy(1.0) == 0.0


def test_tabulated_sound_speed_and_tail():
    c = get_material("Al").curve
    assert 72 < c.K0 / units.GPa < 76
    assert 5.2 < c.c0 / units.km_s < 5.3
    assert 2.0 <= c.n_tail <= 8.0
    d = np.linspace(2.37, 12, 50)
    p = c.pressure(d)
    assert np.all(np.diff(p) > 0) and p[-1] > 10 * p[0]        # repulsive, growing without bound
    assert np.all(c.dpressure(np.linspace(0.4, 12, 400)) > 0)


def test_library_and_hugoniot():
    assert get_material("Pb").c0 == pytest.approx(1.972 * units.km_s)
    assert hugoniot("Al").D(3 * units.km_s) / units.km_s == pytest.approx(5.392 + 3 * 1.341)
    with pytest.raises(InputError, match="material='Unobtainium'"):
        get_material("Unobtainium")
    with pytest.raises(InputError, match="rho0"):
        MurnaghanCurve(-1.0, 1.0, 3.0)
