"""The project's files cite its own docs, never files outside the repository."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = ("physics.md", "DESIGN.md", "STYLE.md", "/work/shared", "shared/data", "seeds/")


def test_no_reference_outside_the_repository():
    bad = []
    for folder in ("clusterdyn", "docs", "tests", "examples", "benchmarks"):
        for p in (ROOT / folder).rglob("*"):
            if p.suffix not in (".py", ".md", ".csv", ".toml") or p == Path(__file__):
                continue
            text = p.read_text(errors="ignore")
            bad += [f"{p.relative_to(ROOT)}: {w}" for w in FORBIDDEN if w in text]
    readme = (ROOT / "README.md").read_text()
    bad += [f"README.md: {w}" for w in FORBIDDEN if w in readme]
    assert not bad, "\n".join(bad)
