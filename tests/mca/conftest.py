import pytest

from clusterdyn.analysis.mca_elastic import elastic_material


@pytest.fixture
def elastic25():
    return elastic_material(0.25)
