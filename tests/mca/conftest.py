import pytest

from clusterdyn.mca.studies import elastic_material


@pytest.fixture
def elastic25():
    return elastic_material(0.25)
