"""MCA studies: the Cluster Dynamics contrast of the elasticity table, and the degrading cycle.

(Named ``test_mca_studies.py``: ``tests/studies/test_studies.py`` exists and the test folders
have no ``__init__.py``, so a second ``test_studies.py`` would not be collected beside it.)
"""

import numpy as np
import pytest

from clusterdyn import units
from clusterdyn.materials import get_material
from clusterdyn.analysis.elastic import cd_elastic_constants, cubic_stiffness, rotate_stiffness, uniaxial_moduli
from clusterdyn.scenes.mca_material_point import degrading_cycle


def test_cd_contrast_100_cauchy_poisson_ratio_and_bulk_modulus():
    r = cd_elastic_constants("Al", 5 * units.um, (1, 0, 0))
    al = get_material("Al")
    assert r["nu_xy"] == pytest.approx(1 / 3, abs=1e-3)
    assert r["nu_xz"] == pytest.approx(1 / 3, abs=1e-3)
    assert r["B"] == pytest.approx(al.rho0 * al.c0 ** 2, rel=0.01)
    assert r["C12"] == pytest.approx(r["C44"], rel=1e-3)             # Cauchy
    assert r["C11"] == pytest.approx(r["analytic"]["C11"], rel=1e-3)
    assert r["E"] == pytest.approx(r["analytic"]["E"], rel=1e-3)


def test_cd_contrast_111_poisson_ratio():
    r = cd_elastic_constants("Al", 5 * units.um, (1, 1, 1))
    assert r["nu_xy"] == pytest.approx(0.2, abs=1e-3)
    assert r["nu_xz"] == pytest.approx(0.2, abs=1e-3)
    assert r["E"] == pytest.approx(2.4 * r["analytic"]["C12"], rel=1e-3)   # E[111] = 12k/(5a)


def test_rotated_cubic_moduli():
    C = cubic_stiffness(2.0, 1.0, 1.0)
    assert uniaxial_moduli(C) == pytest.approx((4 / 3, 1 / 3, 1 / 3))
    M = np.array([[1, 1, 1], [1, -1, 0], [1, 1, -2]], float)
    M /= np.linalg.norm(M, axis=1)[:, None]
    assert uniaxial_moduli(rotate_stiffness(C, M)) == pytest.approx((2.4, 0.2, 0.2))
    assert rotate_stiffness(rotate_stiffness(C, M), M.T) == pytest.approx(C, abs=1e-12)


def test_degrading_cycle_study(tmp_path):
    r = degrading_cycle(size=(10, 4, 4), steps=2500, out=tmp_path, stream=None)
    E = r["material"].E
    assert abs(r["E_initial"] / E - 1) < 0.05
    assert r["E_unloading"] < 0.8 * r["E_initial"]
    assert r["E_reloading"] == pytest.approx(r["E_unloading"], rel=0.1)
    assert (tmp_path / "degrading_cycle.png").stat().st_size > 0
    assert len((tmp_path / "degrading_cycle.csv").read_text().splitlines()) == len(r["strain"]) + 1
