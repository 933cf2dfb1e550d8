"""The documentation site builds with warnings as errors (docs/about.md).

    .venv/bin/sphinx-build -W --keep-going -b html docs docs/_build/html

The API pages are generated from the docstrings of psf, udc_render and restore at every build, so a
module that cannot be imported, or a page outside the table of contents, fails this test.

Fast suite: the `dummy` builder, which reads and resolves every page as the html builder does (MyST, autodoc
imports, the toctree, cross-references, images: Sphinx's image collector runs while reading) and writes nothing:
63 s against 247 s for html on the 2-core machine, three quarters of it the theme's navigation written into each
of ~280 pages. `-j auto` reads in parallel: 64 s against 76 s on one process (2 cores, 2026-12). The html build
itself is the slow suite's (`pytest -m slow tests/docs/test_docs_build.py`).
"""
from __future__ import annotations

import subprocess
import sys

import pytest

from tests.docs.examples import ROOT


def _build(builder: str, tmp_path):
    out = tmp_path / builder
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-j", "auto", "-b", builder,
                           "-d", str(tmp_path / "doctrees"), "docs", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)
    report = (proc.stdout + proc.stderr)[-6000:]
    assert proc.returncode == 0, f"sphinx-build -W failed:\n{report}"
    assert "WARNING" not in proc.stderr, report
    return out


def test_docs_read_without_warnings(tmp_path):
    _build("dummy", tmp_path)
    generated = list((tmp_path / "doctrees" / "api" / "generated").glob("*.doctree"))  # read in this build
    assert any(p.name.startswith("psf.") for p in generated) and any(p.name.startswith("restore.") for p in generated)


@pytest.mark.slow
def test_docs_build_without_warnings(tmp_path):
    out = _build("html", tmp_path)
    for page in ("index.html", "getting-started.html", "api/index.html", "studies/results.html",
                 "concepts/defaults.html", "troubleshooting.html"):
        assert (out / page).is_file(), f"{page} was not built"
    generated = list((out / "api" / "generated").glob("*.html"))
    assert any(p.name.startswith("psf.") for p in generated) and any(p.name.startswith("restore.") for p in generated)
