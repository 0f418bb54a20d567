import pytest

from clusterdyn.studies.mca import elastic_material


@pytest.fixture
def elastic25():
    return elastic_material(0.25)
