"""The documentation builds with Sphinx, warnings as errors, with an API page for every public
module and each page listed once in the index."""

import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import clusterdyn

DOCS = Path(__file__).parents[2] / "docs"


def test_docs_build_without_warnings(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    html = tmp_path / "html"
    r = subprocess.run([sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b", "html",
                        str(DOCS), str(html)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (html / "index.html").exists()
    assert (html / "api.html").stat().st_size > 10_000
    # every public module has its page, among them those the reference once left out
    public = [m.name for m in pkgutil.walk_packages(clusterdyn.__path__, "clusterdyn.")
              if not any(p.startswith("_") for p in m.name.split("."))]
    for name in ("clusterdyn.mca", "clusterdyn.io.lammps", "clusterdyn.build.polycrystal",
                 "clusterdyn.analysis.stress"):
        assert name in public
    missing = [n for n in public if not (html / "_autosummary" / f"{n}.html").exists()]
    assert not missing, missing
    # the index lists each page once (the guide, theory and API were listed twice)
    index = (html / "index.html").read_text()
    body = index[index.index('<div class="body"'):index.index('<div class="sphinxsidebar"')]
    entries = re.findall(r'toctree-l1"><a class="reference internal" href="([^"#]+)"', body)
    assert entries and len(entries) == len(set(entries)), entries
    for page in ("guide.html", "theory.html", "api.html", "examples.html", "performance.html"):
        assert page in entries
