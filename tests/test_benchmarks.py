"""benchmarks/ stays a small suite: a few scripts, one helper module they share, no cycles."""

import ast
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _imports(path):
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module.split(".")[0])
    return names


def test_a_few_scripts_sharing_one_helper_module_without_cycles():
    scripts = sorted(BENCH.glob("*.py"))
    runnable = [p.name for p in scripts if not p.stem.startswith("_")]
    assert 2 <= len(runnable) <= 8, runnable          # at most 8 scripts, besides the helper module
    assert {p.name for p in scripts} - set(runnable) == {"_common.py"}
    local = {p.stem for p in scripts}
    assert not _imports(BENCH / "_common.py") & local
    bad = {p.name: sorted(_imports(p) & (local - {"_common"})) for p in scripts}
    assert not any(bad.values()), bad
    # their figures live in one summary, each with its command
    results = (BENCH / "RESULTS.md").read_text()
    for p in scripts:
        if not p.stem.startswith("_"):
            assert f"python benchmarks/{p.name}" in results, p.name
