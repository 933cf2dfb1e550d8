"""A plain (non-editable) install works from another folder: the built-in scenes ship as package data.

Slow (builds and installs the project, then runs the main job on a small frame): `pytest -m slow`.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_plain_install_runs_the_demo_from_another_folder(tmp_path):
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                    "--target", str(target), str(ROOT)], check=True, cwd=tmp_path)
    assert (target / "udc_render" / "scenes" / "monitor.toml").is_file()
    assert not (target / "scenes").exists()
    env = dict(os.environ, PYTHONPATH=str(target), UDC_RENDER_CACHE=str(tmp_path / "cache"))
    where = subprocess.run([sys.executable, "-c", "import udc_render, udc_render.scene as s; "
                            "print(udc_render.__file__); print(s.scenes_dir())"],
                           env=env, cwd=tmp_path, capture_output=True, text=True, check=True).stdout.split()
    assert all(Path(p).resolve().is_relative_to(target.resolve()) for p in where), where
    run = subprocess.run([sys.executable, "-m", "udc_render.cli", "demo", "--sensor-px", "128,64", "--quiet",
                          "--out", str(tmp_path / "demo")], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    assert (tmp_path / "demo" / "poled" / "raw.dng").is_file() and (tmp_path / "demo" / "summary.md").is_file()


def test_every_package_folder_is_listed_in_pyproject():
    """pyproject's explicit package list names every folder with an __init__.py (an unlisted one works in the
    editable install and is missing from a wheel: udc_render.fit and udc_render.optics.stray were)."""
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for top in ("psf", "udc_render", "restore")
             for p in (ROOT / top).rglob("__init__.py")}
    assert found <= listed, sorted(found - listed)
