"""Shock analysis: profiles with the von Mises intensity, front detection, the state behind a front,
mass and momentum cross-checks, the mixture rule."""

import math

import numpy as np
import pytest
from ase import Atoms

from clusterdyn import units
from clusterdyn.analysis.shock import ShockTracker, fit_front, front_position, hugoniot_interpolant, mixture_D
from clusterdyn.analysis.slabs import binned_profile
from clusterdyn.analysis.stress import von_mises
from clusterdyn.build import fcc_packing
from clusterdyn.calculators import ClusterDynamics

R0 = 5 * units.um


def test_profile_has_intensity_and_pressure_of_uniaxial_strain():
    atoms = fcc_packing("Al", R0, size=(6, 4, 4), pbc=True)
    atoms.set_cell(atoms.cell.array * np.array([0.95, 1, 1])[:, None], scale_atoms=True)
    atoms.calc = ClusterDynamics()
    W = atoms.calc.get_property("virials", atoms)
    p = binned_profile(atoms, W, width=math.sqrt(2) * R0 * 0.95, lo=0.0, hi=atoms.cell[0, 0])
    s = atoms.get_stress()
    assert np.allclose(p["stress"], s, rtol=1e-6, atol=1e-9 * abs(s[0]))
    # uniaxial strain: sigma_yy = sigma_zz, intensity |sigma_xx - sigma_yy|
    assert np.allclose(p["von_mises"], abs(s[0] - s[1]), rtol=1e-6)
    assert np.allclose(p["pressure"], -(s[0] + s[1] + s[2]) / 3, rtol=1e-6)
    assert p["von_mises"][0] == pytest.approx(von_mises(s))


def test_front_position_ignores_single_slabs_thrown_ahead():
    x = np.arange(20.0)
    v = np.where(x < 10, 2.0, 0.0)
    assert front_position(x, v, 2.0) == pytest.approx(9.5)
    v[14] = 2.5                              # one slab of clusters ahead of the front
    assert front_position(x, v, 2.0, support=2) == pytest.approx(9.5)
    assert front_position(x, v, 2.0) == pytest.approx(14.6)
    assert math.isnan(front_position(x, np.zeros(20), 2.0))


def test_fit_front_recovers_line():
    t = np.linspace(0, 1, 12)
    D, x0, rms = fit_front(t, 3.0 + 7.5 * t)
    assert (D, x0) == pytest.approx((7.5, 3.0)) and rms < 1e-12


def synthetic_shock(D, u_behind, u_piston, times, n_planes=200, d=1.0, ny=3):
    """A steady shock written down: planes at X = k d, shocked where X < D t.

    Shocked: x = X (1 - u/D) + u t, v = u; ahead at rest; piston (X < 0) moves at u_piston.
    """
    X = np.repeat(np.arange(-4, n_planes) * d, ny * ny)
    yz = np.tile(np.array([(i, j) for i in range(ny) for j in range(ny)], float) * d, (n_planes + 4, 1))
    piston = X < 0
    m = np.ones(len(X))
    rho0 = 1.0 / d ** 3
    tracker = ShockTracker(rho0, u_piston, width=2 * d, lo=0.0, hi=(n_planes + 2) * d)
    for t in times:
        shocked = (X < D * t) & ~piston
        x = np.where(shocked, X * (1 - u_behind / D) + u_behind * t, X)
        x = np.where(piston, X + u_piston * t, x)
        v = np.zeros((len(X), 3))
        v[shocked, 0] = u_behind
        v[piston, 0] = u_piston
        a = Atoms(positions=np.c_[x, yz], cell=[(n_planes + 40) * d, ny * d, ny * d], pbc=(False, True, True),
                  masses=m)
        a.set_velocities(v)
        tracker.add(t, a, None, x[piston].max(), exclude=piston)
    return tracker


def test_state_behind_an_exact_steady_shock():
    D, u = 5.0, 1.0
    tr = synthetic_shock(D, u, u, np.linspace(0, 36, 37))
    st = tr.result()
    assert st.D_fit == pytest.approx(D, rel=0.01)
    assert st.u == pytest.approx(u, rel=1e-12)
    assert st.rho == pytest.approx(tr.rho0 / (1 - u / D), rel=1e-9)        # Lagrangian compression
    assert st.D_mass == pytest.approx(D, rel=1e-9)                           # rho0 D = rho (D - u)
    assert st.P_momentum == pytest.approx(tr.rho0 * st.D_fit * u)
    assert st.P == pytest.approx(0.0, abs=1e-12)                             # no virials, no spread
    assert st.steady and not st.steady_reasons
    assert st.fit_rms < 0.5 * tr.width
    assert abs(st.D_halves[0] / st.D_halves[1] - 1) < 0.02


def test_unsteady_when_velocity_behind_front_is_off():
    tr = synthetic_shock(5.0, 0.9, 1.0, np.linspace(0, 36, 37))
    st = tr.result()
    assert not st.steady
    assert any("particle velocity behind the front" in r for r in st.steady_reasons)


def test_mass_conservation_holds_through_a_steady_ramp():
    """A steady wave whose velocity rises over 120 planes (a weak shock in a lattice): the region
    behind the front includes the ramp, yet D from mass conservation equals D."""
    D, up, L, d = 5.0, 1.0, 120.0, 1.0

    def u_of(xi):                                     # xi = X - D t; velocity ramp behind xi = 0
        return up * np.clip(-xi / L, 0.0, 1.0)

    def disp(xi):                                     # x - X, with d(x - X)/dX = -u/D at every point
        a = np.clip(-xi, 0.0, L)
        return up / D * (np.maximum(-xi - L, 0.0) + a * a / (2 * L))

    n_planes, ny = 300, 3
    X = np.repeat(np.arange(-4, n_planes) * d, ny * ny)
    yz = np.tile(np.array([(i, j) for i in range(ny) for j in range(ny)], float) * d, (n_planes + 4, 1))
    piston = X < 0
    tracker = ShockTracker(1.0 / d ** 3, up, width=2 * d, lo=0.0, hi=(n_planes + 2) * d)
    for t in np.linspace(0, 56, 57):                 # the first frame is the reference X0
        xi = X - D * t
        x = np.where(piston, X + disp(-D * t), X + disp(xi))      # the piston moves with plane 0
        v = np.zeros((len(X), 3))
        v[:, 0] = np.where(piston, u_of(-D * t), u_of(xi))
        a = Atoms(positions=np.c_[x, yz], cell=[(n_planes + 80) * d, ny * d, ny * d],
                  pbc=(False, True, True), masses=np.ones(len(X)))
        a.set_velocities(v)
        tracker.add(t, a, None, x[piston].max(), exclude=piston)
    st = tracker.result()
    assert st.D_fit == pytest.approx(D, rel=2e-3)
    assert st.u < 0.95 * up                           # the averaged region holds much of the ramp
    assert st.D_mass == pytest.approx(st.D_fit, rel=2e-3)
    # the plain mean velocity over the region would not match the fitted compression
    slope = np.mean([f["slope"] for f in tracker.frames if f["n_region"]])
    assert abs(st.u / (1 - slope) / st.D_fit - 1) > 0.02


def test_tracker_state_round_trip():
    tr = synthetic_shock(5.0, 1.0, 1.0, np.linspace(0, 20, 9), n_planes=100)
    tr2 = ShockTracker.from_state(tr.get_state())
    assert tr2.result().D_fit == tr.result().D_fit
    assert np.array_equal(tr2.X0, tr.X0)


def test_mixture_rule_closures():
    lin = lambda c, s: (lambda u: c + s * np.asarray(u))          # noqa: E731
    same = [(0.3, 2.7, lin(5.4, 1.34)), (0.7, 2.7, lin(5.4, 1.34))]
    for c in ("equal_u", "equal_p"):
        assert mixture_D(2.0, same, c) == pytest.approx(5.4 + 2 * 1.34, rel=1e-10)
    ph = [(0.72, 2.29, lin(3.2, 1.5)), (0.28, 2.51, lin(9.0, 1.0))]
    v0 = 0.72 / 2.29 + 0.28 / 2.51
    phi = np.array([0.72 / 2.29, 0.28 / 2.51]) / v0
    u = 2.0
    Du = mixture_D(u, ph, "equal_u")
    assert 1 / Du == pytest.approx(phi[0] / (3.2 + 1.5 * u) + phi[1] / (9.0 + u), rel=1e-12)
    # equal_p: the phases at the mixture's pressure, volumes adding up to the mixture's
    Dp = mixture_D(u, ph, "equal_p")
    P = Dp * u / v0
    v = 0.0
    for w, rho, f in ph:
        from scipy.optimize import brentq
        ui = brentq(lambda x: rho * f(x) * x - P, 0, 50)
        v += w / rho * (1 - ui / f(ui))
    assert v == pytest.approx(v0 * (1 - u / Dp), rel=1e-9)
    assert Dp != pytest.approx(Du, rel=1e-3)
    with pytest.raises(ValueError):
        mixture_D(u, ph, "equal_t")


def test_hugoniot_interpolant():
    f = hugoniot_interpolant([1, 2, 3], [7, 8, 9.5])
    assert [f(1), f(2), f(3)] == pytest.approx([7, 8, 9.5])
    assert f(0) == pytest.approx(6.0) and f(4) == pytest.approx(11.0)
    assert f(np.array([1.5, 2.5])).shape == (2,)
