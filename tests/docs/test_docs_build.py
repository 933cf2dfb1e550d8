"""The documentation site builds with warnings as errors (docs/about.md).

    .venv/bin/sphinx-build -W --keep-going -b html docs docs/_build/html

The API pages are generated from the docstrings of psf, udc_render and restore at every build, so a
module that cannot be imported, or a page outside the table of contents, fails this test.
"""
from __future__ import annotations

import subprocess
import sys

from tests.docs.examples import ROOT


def test_docs_build_without_warnings(tmp_path):
    out = tmp_path / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), "docs", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)
    report = (proc.stdout + proc.stderr)[-6000:]
    assert proc.returncode == 0, f"sphinx-build -W failed:\n{report}"
    assert "WARNING" not in proc.stderr, report
    for page in ("index.html", "getting-started.html", "api/index.html", "studies/results.html",
                 "concepts/defaults.html", "troubleshooting.html"):
        assert (out / page).is_file(), f"{page} was not built"
    generated = list((out / "api" / "generated").glob("*.html"))
    assert any(p.name.startswith("psf.") for p in generated) and any(p.name.startswith("restore.") for p in generated)
