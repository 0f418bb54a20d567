"""Every example runs (so they never rot), on the tiny settings CLUSTERDYN_EXAMPLES_TINY=1 picks."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parents[2] / "examples").glob("*.py"))


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path):
    env = dict(os.environ, CLUSTERDYN_EXAMPLES_TINY="1")
    r = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True, text=True,
                       timeout=600, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stdout + r.stderr


def test_there_are_examples():
    assert len(EXAMPLES) >= 4
