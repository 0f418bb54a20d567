"""Johnson-Cook's thermal term: adiabatic heating of each automaton from its plastic work and the
flow stress times (1 - T*^m); an exact answer for one automaton, restarts bit for bit, off costs nothing."""

import math

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.build.mca import mca_packing
from clusterdyn.build.shapes import Cylinder
from clusterdyn.errors import InputError
from clusterdyn.materials import get_material
from clusterdyn.materials.mca import mca_material
from clusterdyn.mca import MCA, MCADynamics
from clusterdyn.mca.response import plastic
from clusterdyn.mca.response.plastic import (hardening_table, heat_energy, jc_flow_stress, johnson_cook,
                                             rate_constants, thermal_constants)
from clusterdyn.md import Wall

CP = 896.0 * units.J / units.kg


def _perfectly_plastic_thermal(beta=0.9):
    """Johnson-Cook with B = 0 and C = 0 (perfectly plastic at A), m = 1: the flow stress A (1 - T*)."""
    g = units.GPa
    jc = johnson_cook(0.3 * g, 0.0, 1.0, m=1.0, T_melt=900.0, T_room=300.0, c_p=CP, beta=beta)
    return mca_material("pp-thermal", 2.7, 69.0, 0.33, sigma_y_GPa=0.3, response="elastic-plastic",
                        johnson_cook=jc)


def _return(mat, sint, epsp, T, dt):
    """One automaton (Omega = 2, three pairs along x, y, z) with a uniaxial tensor of intensity sint."""
    e, s = hardening_table(mat)
    imp, C, e0 = rate_constants(mat)
    therm = np.array([thermal_constants(mat)])
    sig = np.array([[sint, 0.0], [0.0, 0.0], [0.0, 0.0]])
    tens = np.zeros((1, 3, 3))
    tens[0, 0, 0] = sint
    M, wp = np.empty(1), np.empty(1)
    n = plastic.radial_return(tens, np.array([0, 3]), np.array([0, 1, 2]), np.zeros(3, np.int8),
                              np.zeros(1, np.int64), np.ones(1, np.int8), np.array([mat.G]), e[None, :],
                              s[None, :], np.ones(1), epsp, sig, np.zeros((3, 2, 3)), M, np.array([imp], np.int8),
                              np.array([C]), np.array([e0]), dt, np.array([2.0]), wp,
                              np.array([[1.0, 0.0]] * 3), np.full(3, 2.0), np.array([sint / 3]),
                              np.array([1 - 2 * mat.G / (3 * mat.K)]), T, therm)
    return n, M[0] * sint, wp[0]


def test_adiabatic_point_heats_from_its_plastic_work_and_softens_as_1_minus_Tstar():
    mat = _perfectly_plastic_thermal()
    jc = mat.extra["johnson_cook"]
    A, G = jc["A"], mat.G
    heat = jc["beta"] / (mat.rho0 * jc["c_p"])
    epsp, T = np.zeros(1), np.array([300.0])
    s_prev, de, dt = A, 4e-3, 1e-8 * units.s
    work, booked = 0.0, 0.0
    for _ in range(250):                        # 250 steps of total strain 4e-3, all plastic: eps_p = 1
        e0, T0 = epsp[0], T[0]
        sint = s_prev + 3 * G * de
        n, snew, wp = _return(mat, sint, epsp, T, dt)
        x = epsp[0] - e0
        assert n == 1
        # the flow stress of the step's start temperature: A (1 - T*), exactly (m = 1)
        assert snew == pytest.approx(A * (1 - (T0 - 300.0) / 600.0), rel=1e-12)
        assert T[0] - T0 == pytest.approx(heat * snew * x, rel=1e-12)
        work += snew * x
        booked += wp / 2.0                      # the ledger's plastic work per unit volume (Omega = 2)
        s_prev = snew
    # temperature from plastic work exactly: T - T_room = beta W / (rho c_p), W = sum sigma_y d eps_p
    assert T[0] - 300.0 == pytest.approx(heat * work, rel=1e-12)
    # ... a share of what the ledger books (its excess is the return's 3G x^2/2 per step)
    assert heat * work < jc["beta"] / (mat.rho0 * jc["c_p"]) * booked
    # the analytic adiabat of a perfectly plastic m = 1 solid: dT*/d eps_p = k (1 - T*)
    k = jc["beta"] * A / (mat.rho0 * jc["c_p"] * (jc["T_melt"] - jc["T_room"]))
    Ts = (T[0] - 300.0) / 600.0
    assert epsp[0] == pytest.approx(1.0, rel=2e-3)
    assert Ts == pytest.approx(1 - math.exp(-k * epsp[0]), rel=2e-3)
    assert 0.1 < Ts < 0.3                       # a real softening: 6061-T6's A, rho, c_p
    # jc_flow_stress carries the same factor
    assert jc_flow_stress(jc, 0.5, 1.0, T=T[0]) == pytest.approx(A * (1 - Ts), rel=1e-12)


def test_thermal_record_checks_and_the_6061_variant():
    with pytest.raises(InputError, match="johnson_cook.T_melt"):
        johnson_cook(1.0, 1.0, 0.5, m=1.0, T_melt=200.0, T_room=294.0, c_p=1.0)
    with pytest.raises(InputError, match="johnson_cook.c_p"):
        johnson_cook(1.0, 1.0, 0.5, m=1.0, T_melt=900.0)
    with pytest.raises(InputError, match="johnson_cook.beta"):
        johnson_cook(1.0, 1.0, 0.5, m=1.0, T_melt=900.0, c_p=1.0, beta=1.5)
    assert "m" not in johnson_cook(1.0, 1.0, 0.5)                     # the isothermal record as before
    iso, hot = get_material("Al6061-T6"), get_material("Al6061-T6-thermal")
    assert thermal_constants(iso) is None
    jh = hot.extra["johnson_cook"]
    for k, v in iso.extra["johnson_cook"].items():
        assert jh[k] == v
    assert (jh["m"], jh["T_melt"], jh["T_room"], jh["beta"]) == (1.34, 925.0, 294.0, 0.9)
    assert jh["c_p"] / (units.J / units.kg) == pytest.approx(896.0)


def _rod(mat, n=4, length=1.5):
    D0 = 6 * units.mm
    d = D0 / n
    atoms = mca_packing(mat, d, Cylinder(center=(0.5 * D0 + d, 0.5 * D0 + d, 0.0), radius=0.5 * D0,
                                         length=length * D0, axis=2), "fcc")
    atoms.calc = MCA()
    z = atoms.positions[:, 2]
    v = np.zeros((len(atoms), 3))
    v[:, 2] = -400 * units.m_s
    atoms.set_velocities(v)
    atoms.set_constraint(Wall((0, 0, z.min() - 0.51 * d), (0, 0, 1)))
    return atoms


def test_rod_heats_restarts_bit_for_bit_and_off_stores_nothing(tmp_path):
    from clusterdyn.io.checkpoint import load_run, save_run
    atoms = _rod("Al6061-T6-thermal")
    dyn = MCADynamics(atoms, damping=0.05, remesh_strain=0.1)
    dyn.run(80)
    path = tmp_path / "ck.h5"
    save_run(path, dyn)
    dyn.run(80)
    st = dyn.state
    assert dyn.remesh_count >= 1
    assert st.T_n.max() > 310.0 and st.T_n.min() == 294.0          # the face heats, the rear does not
    q = heat_energy(st, atoms)
    assert 0 < q < 0.9 * dyn.plastic_work                          # a share of the booked plastic work
    a2, d2, _ = load_run(path)
    d2.run(80)
    assert np.array_equal(atoms.positions, a2.positions)
    assert np.array_equal(atoms.get_momenta(), a2.get_momenta())
    for k in ("sig_p2", "tau_p2c", "epsp_n", "T_n"):
        assert np.array_equal(getattr(st, k), getattr(d2.state, k)), k
    # the isothermal material: no temperatures, none checkpointed; the hot rod is softer (shorter)
    cold = _rod("Al6061-T6")
    dc = MCADynamics(cold, damping=0.05, remesh_strain=0.1)
    dc.run(160)
    assert dc.state.T_n.size == 0 and "T_n" not in dc.state.get_state() and heat_energy(dc.state, cold) == 0.0
    assert np.ptp(atoms.positions[:, 2]) < np.ptp(cold.positions[:, 2])
