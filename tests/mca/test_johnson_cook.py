"""Johnson-Cook J2 flow: the implicit radial return lands on the rate-dependent curve."""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.errors import InputError
from clusterdyn.materials import get_material
from clusterdyn.mca.response import plastic
from clusterdyn.mca.response.plastic import hardening_table, jc_flow_stress, johnson_cook, rate_constants


def _one_automaton(mat, s_dev_int, epsp0, dt):
    """One automaton (Omega = 2) with three pairs along x, y, z (q S = Omega: sum q S n n = Omega I)
    carrying a uniaxial tensor of intensity s_dev_int."""
    e, s = hardening_table(mat)
    tab_e, tab_s = e[None, :], s[None, :]
    imp, C, e0 = rate_constants(mat)
    sig = np.array([[s_dev_int, 0.0], [0.0, 0.0], [0.0, 0.0]])    # sigma_xx = s_dev_int
    tens = np.zeros((1, 3, 3))
    tens[0, 0, 0] = s_dev_int
    first = np.array([0, 3])
    side_p = np.array([0, 1, 2])
    side_s = np.zeros(3, np.int8)
    epsp = np.array([epsp0])
    M = np.empty(1)
    wp = np.empty(1)
    tau = np.zeros((3, 2, 3))
    n = plastic.radial_return(tens, first, side_p, side_s, np.zeros(1, np.int64), np.ones(1, np.int8),
                              np.array([mat.G]), tab_e, tab_s, np.ones(1), epsp, sig, tau, M,
                              np.array([imp], np.int8), np.array([C]), np.array([e0]), dt,
                              np.array([2.0]), wp, np.array([[1.0, 0.0]] * 3), np.full(3, 2.0),
                              np.array([s_dev_int / 3]), np.array([1 - 2 * mat.G / (3 * mat.K)]),
                              np.zeros(0), np.zeros((1, 4)))
    return n, epsp[0], M[0], wp[0], sig


def test_implicit_return_on_the_johnson_cook_curve():
    mat = get_material("Al6061-T6")
    jc = mat.extra["johnson_cook"]
    dt = 1e-8 * units.s
    for sint_GPa, e0 in ((0.40, 0.0), (0.45, 0.3), (0.60, 1.5)):
        sint = sint_GPa * units.GPa
        n, e1, M, wp, sig = _one_automaton(mat, sint, e0, dt)
        assert n == 1
        x = e1 - e0
        snew = M * sint
        # consistency: the returned intensity is the flow stress at the new strain and the step's rate
        target = jc_flow_stress(jc, e1, x / dt * units.s)
        assert abs(snew / target - 1) < 1e-4          # the tabulated strain hardening
        assert abs(sint - 3 * mat.G * x - snew) < 1e-9 * sint
        # the pair forces' deviator scaled by M about the mean stress
        P = sint / 3
        assert np.allclose(sig[:, 0], P + (np.array([sint, 0, 0]) - P) * M)
        # plastic work = Omega x (sint + snew) / 2
        assert abs(wp / (2.0 * x * 0.5 * (sint + snew)) - 1) < 1e-9      # one pair a side, exact
        # the rate raises the flow stress above the static curve (1 + C ln(rate/eps0))
        assert snew > jc["A"] + jc["B"] * e1 ** jc["n"]


def test_elastic_below_A_and_bad_parameters():
    mat = get_material("Al6061-T6")
    n, e1, M, wp, _ = _one_automaton(mat, 0.3 * units.GPa, 0.0, 1e-8 * units.s)
    assert n == 0 and e1 == 0.0 and M == 1.0 and wp == 0.0
    with pytest.raises(InputError, match="johnson_cook.n"):
        johnson_cook(1.0, 1.0, 1.5)
    # the perfectly plastic Al6061 stays as it was (explicit return, no rate)
    assert rate_constants(get_material("Al6061"))[0] == 0
