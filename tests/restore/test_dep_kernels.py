"""DeP's two kernel sources (restore.known.DEP_KERNELS): 'dep' deconvolves with the paper's computed PSF,
the recipe of `udc-render psf --method paper` at 640 / 520 / 450 nm; 'dep_exact' ("DeP (exact kernel)")
with the camera-weighted channel kernels. On one tiny T-OLED item of `udc-render dataset`."""
from __future__ import annotations

import json

import numpy as np
import pytest

from restore.data import DataError, list_pairs
from restore.evaluate import EvalSettings, evaluate
from restore.known import known_kernels_rggb
from udc_render.cli import main

TINY = ["--sensor-px", "128,64", "--pitch-um", "24.8", "--bands-nm", "400:700:100", "--quiet"]
KERNEL_PX = 9


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    out = tmp_path_factory.mktemp("dep_kernels") / "data"
    assert main(["dataset", "--builtin", "--display", "toled", "--count", "1", "--split", "0,0,1",
                 "--profile", "paper", "--out", str(out), *TINY]) == 0
    return out


def _pair(data):
    return list_pairs(data, "test", ["toled"])[0]


def test_dep_kernels_are_the_psf_commands_paper_recipe(data, tmp_path):
    """'paper': R, G, G, B of `udc-render psf --method paper --wavelengths-nm 640,520,450` for the dataset's
    lens (f = 6 mm at f/1.8: D = 3333.3 µm), at the packed planes' pitch (2 × 24.8 µm), d = 0, unit sum."""
    lens = json.loads((_pair(data).folder / "synth.json").read_text())["lens"]
    assert main(["psf", "--display", "toled", "--method", "paper", "--wavelengths-nm", "640,520,450",
                 "--pitch-um", "49.6", "--kernel-px", str(KERNEL_PX), "--distance-mm", "0",
                 "--aperture-um", repr(lens["aperture_um"]), "--focal-length-um", repr(lens["focal_length_um"]),
                 "--out", str(tmp_path / "psf")]) == 0
    k3 = np.load(tmp_path / "psf" / "psf.npz")["kernels"].astype(np.float64)
    k3 /= k3.sum(axis=(1, 2), keepdims=True)
    dep = known_kernels_rggb(_pair(data), KERNEL_PX, source="paper")
    np.testing.assert_allclose(dep, k3[[0, 1, 1, 2]], rtol=1e-5, atol=1e-7)


def test_the_two_sources_differ_and_the_default_is_the_papers(data):
    pair = _pair(data)
    paper, exact = (known_kernels_rggb(pair, KERNEL_PX, source=s) for s in ("paper", "exact"))
    np.testing.assert_array_equal(known_kernels_rggb(pair, KERNEL_PX), paper)
    np.testing.assert_allclose(exact.sum(axis=(1, 2)), 1.0, rtol=1e-5)
    assert np.abs(paper - exact).sum(axis=(1, 2)).min() > 1e-3  # the recipe's printed r: another kernel
    with pytest.raises(DataError, match="DeP kernels = 'camera': expected one of paper, exact"):
        known_kernels_rggb(pair, KERNEL_PX, source="camera")


def test_the_papers_kernels_are_for_the_diffraction_limited_lens(data, tmp_path):
    """A lens with aberrations (synth.json's zernike_waves) changes the exact kernels, not the paper's: its
    diffraction model has none (l.145–171)."""
    import shutil
    shutil.copytree(data, tmp_path / "data")
    pair, base = _pair(tmp_path / "data"), _pair(data)
    synth = json.loads((pair.folder / "synth.json").read_text())
    synth["lens"]["zernike_waves"] = [[4, 0, 1.0]]
    (pair.folder / "synth.json").write_text(json.dumps(synth))
    np.testing.assert_array_equal(known_kernels_rggb(pair, KERNEL_PX, source="paper"),
                                  known_kernels_rggb(base, KERNEL_PX, source="paper"))
    moved = np.abs(known_kernels_rggb(pair, KERNEL_PX, source="exact") - known_kernels_rggb(base, KERNEL_PX, source="exact"))
    assert moved.sum(axis=(1, 2)).min() > 1e-3


def test_dep_and_dep_exact_are_rows_of_their_own(data, tmp_path):
    """Both score, each row records its kernels, and they land in one table, DeP before DeP (exact kernel)."""
    settings = EvalSettings(previews=0, kernel_px=KERNEL_PX)
    rows = {m: evaluate(data, m, tmp_path / "eval", settings, progress=False) for m in ("dep", "dep_exact")}
    assert {m: r["kernels"] for m, r in rows.items()} == {"dep": "paper", "dep_exact": "exact"}
    for r in rows.values():
        assert np.isfinite(r["displays"]["toled"]["psnr_db_paper"])
    table = (tmp_path / "eval" / "results.md").read_text()
    assert table.index("| dep |") < table.index("| dep_exact |")
