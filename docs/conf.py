"""Sphinx configuration for the clusterdyn documentation (built with warnings as errors)."""

import os
import re
import sys
from pathlib import Path

sys.path.insert(0, os.path.abspath(".."))

project = "clusterdyn"
author = "clusterdyn developers"
copyright = "2026, clusterdyn developers"
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "myst_parser",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False,
                           # a package documents what it defines, not what it re-exports (its
                           # __all__): those are documented in their own modules
                           "ignore-module-all": True}
autodoc_typehints = "none"
html_theme = "alabaster"
exclude_patterns = ["_build", "_templates", "_api_list.rst"]
# The API reference (api.md) is generated: _write_api_list walks the package with pkgutil and
# writes an autosummary of every public module to _api_list.rst, which api.md includes;
# autosummary then writes one page a module into _autosummary/ (neither file in git), so that
# modules added, split or renamed appear without a hand-kept list.
autosummary_generate = ["_api_list.rst"]
autosummary_generate_overwrite = True
autosummary_imported_members = False
templates_path = ["_templates"]

#: ``.. automodule::`` / ``.. autofunction::`` ... lines of the narrative pages
_AUTODOC = re.compile(r"^\s*\.\. auto(module|function|class|data|exception)::\s*(\S+)", re.M)


def _documented_elsewhere():
    """Modules and module members that a narrative page documents with autodoc.

    The generated API page of such a module documents them without a second index entry (a
    whole module: ``:no-index:``; some members: ``:exclude-members:``), so that the build has
    no duplicate object descriptions; read afresh at every build.  Returns (module -> page,
    module -> sorted member names, module -> page of its members)."""
    modules, members, pages = {}, {}, {}
    here = Path(__file__).resolve().parent
    for page in sorted(here.glob("*.md")) + sorted(here.glob("*.rst")):
        if page.stem in ("api", "index"):
            continue
        for kind, name in _AUTODOC.findall(page.read_text()):
            if kind == "module":
                modules.setdefault(name, page.stem)
            else:
                mod, _, obj = name.rpartition(".")
                members.setdefault(mod, set()).add(obj)
                pages.setdefault(mod, page.stem)
    return modules, {k: sorted(v) for k, v in members.items()}, pages


def _write_examples_page():
    """``examples.md``: every script of ``examples/`` (its docstring, then its code), written
    afresh at every build (not in git) so that a new example appears without a hand-kept list."""
    import ast
    here = Path(__file__).resolve().parent
    lines = ["# Examples", "",
             "Runnable scripts in the repository's `examples/` folder; each one runs in the test suite",
             "(`tests/examples/`). Run one with `python examples/NAME.py [OUTDIR]`.", ""]
    for script in sorted((here.parent / "examples").glob("*.py")):
        doc = ast.get_docstring(ast.parse(script.read_text())) or ""
        lines += [f"## {script.name}", "", doc.split("\n\n")[0].replace("\n", " "), "",
                  f"```{{literalinclude}} ../examples/{script.name}", ":language: python", "```", ""]
    text = "\n".join(lines)
    page = here / "examples.md"
    if not page.exists() or page.read_text() != text:
        page.write_text(text)


def _write_api_list():
    """``_api_list.rst``: an autosummary (with pages) of every public module of clusterdyn, in
    package order; a module whose dotted name has a part starting with ``_`` is internal."""
    import pkgutil

    import clusterdyn
    names = ["clusterdyn"] + [m.name for m in pkgutil.walk_packages(clusterdyn.__path__, "clusterdyn.")
                              if not any(part.startswith("_") for part in m.name.split("."))]
    text = ".. autosummary::\n   :toctree: _autosummary\n\n" + "".join(f"   {n}\n" for n in names)
    page = Path(__file__).resolve().parent / "_api_list.rst"
    if not page.exists() or page.read_text() != text:
        page.write_text(text)


_write_examples_page()
_write_api_list()
_mods, _members, _pages = _documented_elsewhere()
autosummary_context = {"cd_elsewhere_modules": _mods, "cd_elsewhere_members": _members,
                       "cd_elsewhere_pages": _pages}
nitpicky = False
# attribute names shared by several classes (rho0, r0, ...) make napoleon's field
# cross-references ambiguous; Sphinx then picks one and warns
suppress_warnings = ["ref.python"]
