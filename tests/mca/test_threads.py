"""The MCA kernels give the same bits on one and two threads, and the hardening table's bisection
finds the segment a scan from the start finds (issue: MCA at the speed of the CD engine)."""
import math

import numpy as np
import pytest

from clusterdyn import parallel as P
from clusterdyn import units
from clusterdyn.build import mca_packing
from clusterdyn.build.mca import precrack
from clusterdyn.errors import InputError
from clusterdyn.mca import MCA, MCADynamics
from clusterdyn.mca.response.plastic import hardening_table, yield_stress


def _run(material, threads, damping, crack=False):
    d = 1e4
    a = math.sqrt(2.0) * d
    at = mca_packing(material, d, (4 * a, 3 * a, 3 * a))
    if crack:
        precrack(at, at.get_cell().diagonal() / 2, (1, 0, 0))
    at.calc = MCA()
    x = at.positions[:, 0]
    rng = np.random.default_rng(3)
    v = np.zeros((len(at), 3))
    v[:, 0] = -300 * units.m / units.s * (x - x.mean()) / np.ptp(x)
    at.set_velocities(v + rng.normal(0, 30 * units.m / units.s, v.shape))
    at.arrays["omega"][:] = rng.normal(0, 3e-6 * units.m / units.s, (len(at), 3))
    old = (P.MIN_PARTICLES_PER_THREAD, P._MAX[0])
    try:
        P.MIN_PARTICLES_PER_THREAD = 1          # a small sample on two threads too
        P.set_max_threads(threads)
        dyn = MCADynamics(at, damping=damping, contact_every=5)
        dyn.run(60)
    finally:
        P.MIN_PARTICLES_PER_THREAD = old[0]
        P.set_max_threads(old[1])
    st = dyn.state
    return [at.positions, at.get_momenta(), at.arrays["omega"], dyn._F, st.sig_p2, st.tau_p2c, st.epsp_n,
            st.linked_p, np.array(list(dyn.ledger().values()))]


@pytest.mark.skipif(P.max_threads() < 2, reason="needs numba with two threads")
@pytest.mark.parametrize("material,damping,crack", [("Al6061-T6", 0.1, False), ("alumina", 0.0, True)])
def test_one_and_two_threads_give_the_same_bits(material, damping, crack):
    one = _run(material, 1, damping, crack)
    two = _run(material, 2, damping, crack)
    for a, b in zip(one, two):
        assert np.array_equal(a, b)
    if material == "Al6061-T6":
        assert one[6].max() > 0          # it flowed: the radial return ran
    else:
        assert (one[7] == 0).any()       # unlinked pairs: the contact law ran


def _scan(eps_p, e, s):
    """The scan from the start the bisection replaced."""
    k = len(e)
    if eps_p <= e[0]:
        return s[0], (s[1] - s[0]) / (e[1] - e[0])
    for q in range(k - 1):
        if eps_p <= e[q + 1]:
            h = (s[q + 1] - s[q]) / (e[q + 1] - e[q])
            return s[q] + h * (eps_p - e[q]), h
    return s[k - 1], 0.0


def test_hardening_bisection_finds_the_scans_segment():
    from clusterdyn.materials import get_material
    e, s = hardening_table(get_material("Al6061-T6"))
    # the second with a repeated point; the first padded as the state pads tables
    tab_e = np.array([np.concatenate([e, [e[-1] + 1.0]]), np.concatenate([e[:2], e[1:]])])
    tab_s = np.array([np.concatenate([s, [s[-1]]]), np.concatenate([s[:2], s[1:]])])
    pts = np.concatenate([e, 0.5 * (e[1:] + e[:-1]), [-1.0, 0.0, 25.0, math.nan, 0.1, 1e-7]])
    for m in range(2):
        for x in pts:
            got = yield_stress(x, tab_e, tab_s, m)
            want = _scan(x, tab_e[m], tab_s[m])
            assert got[0] == want[0] and got[1] == want[1]
    with pytest.raises(InputError, match="ascending"):
        hardening_table(type("M", (), {"extra": {}, "sigma_y": 1.0, "hardening": [[0.0, 0.2, 0.1], [1, 2, 3]]})())
