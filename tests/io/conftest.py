"""Fixtures of the io tests."""

import pytest

from cdio_helpers import run_md


@pytest.fixture
def md_file(tmp_path):
    path = tmp_path / "run.h5md"
    atoms, dyn, rec = run_md(path, parameters={"r0": 5.0, "material": "Cu"})
    return path, atoms, dyn, rec
