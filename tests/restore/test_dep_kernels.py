"""DeP's two kernel sources (restore.known.DEP_KERNELS): 'dep' deconvolves with the paper's computed PSF,
the recipe of `udc-render psf --method paper` at 640 / 520 / 450 nm; 'dep_exact' ("DeP (exact kernel)")
with the camera-weighted channel kernels. On one tiny T-OLED item of `udc-render dataset`."""
from __future__ import annotations

import json

import numpy as np
import pytest

from restore.data import DataError, list_pairs
from restore.evaluate import EvalSettings, evaluate
from restore.known import known_kernels_rggb, packed_from_sensor
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
    moved = np.abs(known_kernels_rggb(pair, KERNEL_PX, source="exact")
                   - known_kernels_rggb(base, KERNEL_PX, source="exact"))
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


def test_packed_from_sensor_integrates_over_the_packed_pixel_about_the_centre():
    """A sensor-pitch delta at the centre is a packed delta at the centre; a shift of 2 px is one of 1 packed px,
    a shift of 1 px splits in halves; a Gaussian of variance σ² becomes (σ² + ½) / 4 (the 2-px box adds ½ px²)."""
    for size in (129, 131):
        c = size // 2
        k = np.zeros((3, size, size))
        k[:, c, c] = 1
        packed = packed_from_sensor(k)
        h = packed.shape[-1] // 2
        assert packed.shape == (4, 65, 65) and packed[:, h, h].tolist() == [1.0] * 4
        k = np.zeros((3, size, size))
        k[:, c + 2, c + 1] = 1  # 2 px down, 1 px right
        packed = packed_from_sensor(k)[0]
        assert packed[h + 1, h] == packed[h + 1, h + 1] == 0.5 and packed.sum() == 1.0
    y, x = np.mgrid[-64:65, -64:65]
    sigma = np.array([3.0, 4.0, 5.0])
    k = np.exp(-(x ** 2 + y ** 2)[None] / (2 * sigma[:, None, None] ** 2))
    packed = packed_from_sensor(k / k.sum(axis=(1, 2), keepdims=True)).astype(np.float64)
    u = np.arange(-32, 33)
    variance = (packed.sum(axis=1) * u ** 2).sum(axis=1)  # along x, R Gr Gb B
    np.testing.assert_allclose(variance, (np.array([9.0, 16, 16, 25]) + 0.5) / 4, rtol=1e-6)
    np.testing.assert_allclose(packed.sum(axis=(1, 2)), 1.0, rtol=1e-6)


def test_packed_from_sensor_refuses_a_kernel_of_even_size_in_one_line():
    with pytest.raises(DataError, match=r"kernels: shape \(3, 64, 64\): expected \[3, S, S\] \(R, G, B\) with S odd"):
        packed_from_sensor(np.ones((3, 64, 64)))
