"""The material-point test (clusterdyn.scenes.material_point): the Cauchy lattice, refusals."""

import pytest

from clusterdyn import units
from clusterdyn.build import fcc_packing
from clusterdyn.build.lattice import SQRT2
from clusterdyn.calculators import ClusterDynamics
from clusterdyn.errors import InputError
from clusterdyn.scenes.material_point import material_point


@pytest.mark.parametrize("eps", [0.002, 0.004])
def test_single_crystal_is_the_cauchy_lattice(eps):
    """Uniaxial strain of a [100] crystal: -s_xx = C11 eps, -s_yy = C12 eps, s_u = (C11 - C12) eps."""
    r = material_point(sample="single", size=4.0, r0=10 * units.um, strains=(eps,), rate=1e-3, hold=2.0,
                          average=1.0, noise=0.0)
    calc = ClusterDynamics()
    calc.setup(fcc_packing("Al", 10 * units.um, size=(2, 2, 2), pbc=True))
    pot = calc.potentials[0]
    k = float(pot.stiffness(pot.r0))
    a = SQRT2 * pot.r0
    C11, C12 = 2 * k / a / units.GPa, k / a / units.GPa
    rel = r["relaxed"]
    assert rel["sigma_axial"] == pytest.approx(C11 * eps, rel=0.02)
    assert rel["sigma_lateral"] == pytest.approx(C12 * eps, rel=0.03)
    assert r["flow_stress"] == pytest.approx((C11 - C12) * eps, rel=0.03)
    assert r["curve"][0]["sigma_u"] == pytest.approx((C11 - C12) * eps, rel=0.03)
    assert r["n_clusters"] == 4 * 3 ** 3


def test_refusals_before_any_work():
    with pytest.raises(InputError, match="strains="):
        material_point(strains=(0.1, 0.05))
    with pytest.raises(InputError, match="boundaries="):
        material_point(boundaries="glued")
    with pytest.raises(InputError, match="grain_size="):
        material_point(size=8.0, grain_size=10.0)
    with pytest.raises(InputError, match="material="):
        material_point("Al-no-such")
