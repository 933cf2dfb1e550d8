"""Sphinx configuration of the udc-render documentation site (docs/).

Build: .venv/bin/sphinx-build -W -b html docs docs/_build/html
The test suite builds it with -W --keep-going (tests/docs/test_docs_build.py).
"""
from __future__ import annotations

import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

project = "udc-render"
author = "the udc-render authors"
copyright = "2026, the udc-render authors"
try:
    from importlib.metadata import version as _version
    release = _version("udc-render")
except Exception:  # not installed: the docs still build from the source tree
    release = "0.1.0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store",
                    # a table without a title of its own: included by studies/restore.md
                    "figures/restore_studies/dep_misfit.md",
                    # the gap study's own report (its answer and tables are in studies/gap.md)
                    "figures/gap/study_gap.md",
                    # bench_field_knobs.py's table beside its PNG (the guide's synth.md and concepts/defaults.md
                    # quote it)
                    "figures/field_knobs.md",
                    # the layout and design-knob studies' own reports (guides/design.md quotes their tables)
                    "figures/design/**/study_layout.md", "figures/design/**/study_design.md",
                    "figures/design/**/layout_crop.md", "figures/design/**/study_layout_compare.md",
                    "figures/design/**/study_layout_trained.md", "figures/design/**/study_layout_dipole.md",
                    "figures/design/**/study_held_out.md", "figures/design/**/study_channel_step.md",
                    "figures/design/**/study_design_bands.md"]
templates_path = ["_templates"]

# MyST: the project's Markdown is included as is (docs/*.md, RESULTS.md, scenes/README.md,
# benchmarks/README.md). Headings get anchors so pages can link to sections.
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
myst_heading_anchors = 3
# The as-is pages skip heading levels in places (a "###" right under a "#"); that is style, not an error.
suppress_warnings = ["myst.header"]

html_theme = "furo"
html_title = f"udc-render {release}"
html_static_path = ["_static"]
html_css_files = ["docstrings.css"]  # a smaller font for the docstrings' literal blocks

# ---------------------------------------------------------------- API reference
# docs/api/index.md lists the three packages under `autosummary :recursive:`, so every module,
# including modules added or renamed later, gets its page (written to docs/api/generated/, ignored by git).
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True,
                           "ignore-module-all": True}  # a package page documents what it defines, not its re-exports
autodoc_member_order = "bysource"
autodoc_typehints = "none"   # signatures stay as written; no cross-reference warnings from types

# `python -m udc_render.cli` runs the command line on import (udc_render/cli/__main__.py), and
# autosummary imports every submodule it finds: stand a placeholder in for it, marked as a mock
# so that autosummary skips it.
_main = types.ModuleType("udc_render.cli.__main__")
_main.__sphinx_mock__ = True
sys.modules.setdefault("udc_render.cli.__main__", _main)


def _escaped(line: str) -> str:
    """One line as plain reStructuredText text: every character that could be markup backslash-escaped."""
    return "".join("\\" + c if not (c.isalnum() or c.isspace()) else c for c in line)


def _literal_docstring(app, what, name, obj, options, lines):
    """Render a docstring as its summary paragraph (escaped prose, which autosummary's tables show)
    followed by the rest as a literal block.

    The docstrings are free-form text written for the terminal (`help()`), with formulas such as
    `|x|`, `*`, `_` and indented continuation lines, which reStructuredText reads as markup
    (substitution references, emphasis, definition lists) and warns about. Shown verbatim they read
    as their authors wrote them, and the build stays free of warnings under -W.
    """
    text = [line.rstrip() for line in lines]
    while text and not text[-1]:
        text.pop()
    if not text:
        return
    cut = text.index("") if "" in text else len(text)
    summary, rest = text[:cut], text[cut + 1:]
    out = [_escaped(line.strip()) for line in summary] + [""]
    if rest:
        out += [".. code-block:: text", ""] + ["    " + line if line else "" for line in rest] + [""]
    lines[:] = out


def setup(app):
    app.connect("autodoc-process-docstring", _literal_docstring)
