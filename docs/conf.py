"""Sphinx configuration of the activetrack manual (``make docs``).

Sphinx rather than MkDocs: autodoc documents the public names from their Google-style
docstrings (napoleon) with the library's ``:func:``/``:class:`` cross-references as written,
and MyST reads the existing Markdown pages unchanged. Built with ``-W --keep-going``
(warnings are errors). ``_ext/env_pages.py`` generates one page per registered environment,
``_ext/api_pages.py`` the API reference from the public modules' ``__all__``.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "activetrack"
author = "The activetrack developers"
copyright = "The activetrack developers"  # noqa: A001 (Sphinx's setting name)

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "env_pages",
    "api_pages",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build"]
# Headings of the Markdown pages get anchors, so links like tasks.md#the-models resolve.
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = "activetrack"
# Browsers ask for a favicon; without one each page logs a 404 in the console.
html_favicon = "_static/favicon.svg"
