"""The ``slow`` list of tests/conftest.py names tests that exist, once each."""

import importlib.util
import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("tests_root_conftest", TESTS / "conftest.py")
_conftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_conftest)
SLOW = _conftest.SLOW


def test_every_slow_entry_names_a_test_function():
    missing = []
    for fname, name in SLOW:
        func = name.split("[")[0]
        files = [p for p in TESTS.rglob(fname) if re.search(rf"^def {func}\(", p.read_text(), re.M)]
        if len(files) != 1:
            missing.append((fname, name, [str(p) for p in files]))
    assert not missing, missing
