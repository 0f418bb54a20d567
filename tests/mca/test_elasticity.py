"""Elastic constants independent of the packing, with any Poisson ratio (fast subset of the table).

The full 20-case table: ``python -m clusterdyn.mca.studies elasticity`` (docs/mca.md).
"""

import pytest

from clusterdyn.analysis.mca_elastic import elastic_case, relative_errors

CASES = [("fcc", 0.25), ("hcp", 0.45), ("sc", 0.0), ("random", 0.35), ("fcc", 0.45), ("sc", 0.15)]


@pytest.mark.parametrize("packing,nu", CASES)
def test_elastic_constants(packing, nu):
    row = elastic_case(nu, packing)
    err = relative_errors(row)
    tol = 0.10 if packing == "random" else 0.05
    if nu == 0.0:
        assert abs(err["nu"]) < 0.02, row
    else:
        assert abs(err["nu"]) < tol, row
    assert abs(err["E"]) < tol, row
    assert abs(err["K"]) < 0.02, row
    assert abs(err["G"]) < 0.05, row
