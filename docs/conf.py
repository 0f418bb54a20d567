"""Sphinx configuration for the clusterdyn documentation (built with warnings as errors)."""

import os
import sys

sys.path.insert(0, os.path.abspath(".."))

project = "clusterdyn"
author = "clusterdyn developers"
copyright = "2026, clusterdyn developers"
extensions = [
    "sphinx.ext.autodoc",
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
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "none"
html_theme = "alabaster"
exclude_patterns = ["_build"]
nitpicky = False
# attribute names shared by several classes (rho0, r0, ...) make napoleon's field
# cross-references ambiguous; Sphinx then picks one and warns
suppress_warnings = ["ref.python"]
