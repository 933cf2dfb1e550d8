"""The RAW capture as a DNG (udc_render.io.dng): libraw (rawpy) reads it back as a RAW with our
pattern, levels and colour matrix; the colour matrix fits the camera; the bytes are reproducible; bad
input is one line. And the synthesis files around it (io.capture): previews optional, load_packed."""
from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from udc_render.io import capture as capture_files
from udc_render.io.dng import DngError, as_shot_neutral, checker_responses, color_matrix_fit, read_dng_mosaic, save_dng
from udc_render.sensor import SensorConfig, capture_electrons, pack_rggb

CAMERA = "Nikon 5100 (NPL)"
BLACK, WHITE = 512, 16383
# sRGB (D65) ──► XYZ, the matrix libraw uses to turn a DNG's ColorMatrix into its camera ──► sRGB matrix
XYZ_RGB = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])


def flat_mosaic(levels_rgb, size_px=64) -> np.ndarray:
    """An RGGB mosaic whose R, G and B sites hold levels_rgb (fractions of white − black)."""
    dn = np.round(BLACK + np.asarray(levels_rgb) * (WHITE - BLACK)).astype(np.uint16)
    m = np.empty((size_px, size_px), np.uint16)
    m[0::2, 0::2], m[0::2, 1::2], m[1::2, 0::2], m[1::2, 1::2] = dn[0], dn[1], dn[1], dn[2]
    return m


def noisy_mosaic(seed=0, size_px=(64, 96)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(BLACK, WHITE + 1, size_px).astype(np.uint16)


def test_libraw_reads_the_mosaic_pattern_and_levels(tmp_path):
    rawpy = pytest.importorskip("rawpy")
    m = noisy_mosaic()
    save_dng(tmp_path / "raw.dng", m, CAMERA, BLACK, WHITE)
    with rawpy.imread(str(tmp_path / "raw.dng")) as r:
        assert np.array_equal(r.raw_image_visible, m)
        desc = r.color_desc.decode()
        assert [[desc[i] for i in row] for row in r.raw_pattern] == [["R", "G"], ["G", "B"]]
        assert list(r.black_level_per_channel) == [BLACK] * 4 and r.white_level == WHITE
        wb = np.asarray(r.camera_whitebalance[:3])
        # AsShotNeutral to 4 decimals: ≤ 5e-5 on each value, ≤ 2.5e-4 on a ratio of two (measured 7.5e-5)
        np.testing.assert_allclose(wb / wb[1], 1 / as_shot_neutral(CAMERA), rtol=3e-4)
        # libraw's camera ──► sRGB matrix is inv(rows-normalised M · XYZ_RGB): it took our ColorMatrix1
        cam_rgb = color_matrix_fit(CAMERA)[0] @ XYZ_RGB
        np.testing.assert_allclose(r.color_matrix[:, :3], np.linalg.inv(cam_rgb / cam_rgb.sum(1, keepdims=True)),
                                   atol=4e-4)  # the stored rationals' rounding through the inverse: measured 1.0e-4


def _developed_means(path, output_color) -> np.ndarray:
    import rawpy
    with rawpy.imread(str(path)) as r:
        img = r.postprocess(use_camera_wb=True, no_auto_bright=True, output_bps=16, gamma=(1, 1),
                            output_color=output_color)
    return img[4:-4, 4:-4].reshape(-1, 3).mean(0) / 65535  # away from the demosaic's border


def test_developed_grey_is_neutral_and_colours_follow_the_mosaic(tmp_path):
    """Demosaiced by libraw with the camera's white balance: a flat D65-grey mosaic (camera levels ∝
    AsShotNeutral) comes out neutral in camera RGB and in sRGB (within 1e-3: measured 2.0e-4, the mosaic's DN
    rounding); a coloured flat field keeps its channel ratios times the white-balance gains (within 5e-4:
    measured 4.6e-5; one 16-bit output level on the 0.1 channel is 1.5e-4)."""
    rawpy = pytest.importorskip("rawpy")
    neutral = as_shot_neutral(CAMERA)
    save_dng(tmp_path / "grey.dng", flat_mosaic(0.3 * neutral / neutral.max()), CAMERA, BLACK, WHITE)
    for space in (rawpy.ColorSpace.raw, rawpy.ColorSpace.sRGB):
        out = _developed_means(tmp_path / "grey.dng", space)
        np.testing.assert_allclose(out / out[1], 1, atol=1e-3)
    levels = np.array([0.1, 0.3, 0.2])
    save_dng(tmp_path / "colour.dng", flat_mosaic(levels), CAMERA, BLACK, WHITE)
    out = _developed_means(tmp_path / "colour.dng", rawpy.ColorSpace.raw)
    expected = levels / neutral  # white balance: gains 1 / AsShotNeutral
    np.testing.assert_allclose(out / out[1], expected / expected[1], rtol=5e-4)


def test_color_matrix_fits_the_checker():
    """ColorChecker under D65, Nikon 5100: relative RMS residual 0.022 and ΔE2000 mean 1.25, max 3.46
    (XYZ back from camera RGB through M⁻¹); bounds 0.03, 2 and 4. Normalised: max(M · D65 (Y = 1)) = 1."""
    import colour
    m, rel_rms = color_matrix_fit(CAMERA)
    assert rel_rms < 0.03
    cam, xyz = checker_responses(CAMERA)
    white = xyz[-1] / xyz[-1, 1]
    assert (m @ white).max() == pytest.approx(1, abs=1e-12)
    back = np.linalg.solve(m, cam.T).T  # XYZ from camera RGB, scaled so that D65 has Y = 1 (as a developer does)
    xyz_back = back[:-1] / back[-1, 1]
    wp = colour.XYZ_to_xy(white)
    de = colour.delta_E(colour.XYZ_to_Lab(xyz[:-1] / xyz[-1, 1], wp), colour.XYZ_to_Lab(xyz_back, wp),
                        method="CIE 2000")
    assert de.mean() < 2 and de.max() < 4
    assert color_matrix_fit("Sigma SDMerill (NPL)")[1] < 0.04  # 0.029


def test_bytes_are_reproducible_with_no_time_or_software(tmp_path):
    import tifffile
    m = noisy_mosaic()
    for name in ("a.dng", "b.dng"):
        save_dng(tmp_path / name, m, CAMERA, BLACK, WHITE)
    assert (tmp_path / "a.dng").read_bytes() == (tmp_path / "b.dng").read_bytes()
    with tifffile.TiffFile(tmp_path / "a.dng") as tif:
        codes = set(tif.pages[0].tags.keys())
    assert {50706, 33421, 33422, 50714, 50717, 50721, 50728, 50778, 50708} <= codes
    assert not codes & {305, 306, 36867}  # Software, DateTime, DateTimeOriginal
    raw = read_dng_mosaic(tmp_path / "a.dng")
    assert np.array_equal(raw.mosaic_dn, m) and (raw.black_level_dn, raw.white_level_dn) == (BLACK, WHITE)


@pytest.mark.parametrize("mosaic, says", [
    (np.zeros((64, 64), np.float32), "dtype float32: expected uint16"),
    (np.zeros((63, 64), np.uint16), "shape (63, 64): expected [H, W] with H and W even"),
    (np.zeros((2, 64, 64), np.uint16), "shape (2, 64, 64)"),
])
def test_bad_mosaic_is_one_line_and_leaves_no_file(tmp_path, mosaic, says):
    with pytest.raises(DngError, match=r"raw\.dng: .*" + re.escape(says)) as e:
        save_dng(tmp_path / "raw.dng", mosaic, CAMERA, BLACK, WHITE)
    assert "\n" not in str(e.value) and list(tmp_path.iterdir()) == []


def test_bad_levels_and_foreign_files_are_one_line(tmp_path):
    import tifffile
    with pytest.raises(DngError, match="black 700, white 600 DN: expected 0 ≤ black < white ≤ 65535"):
        save_dng(tmp_path / "raw.dng", noisy_mosaic(), CAMERA, 700, 600)
    tifffile.imwrite(tmp_path / "grey.tiff", noisy_mosaic(), photometric="minisblack")
    with pytest.raises(DngError, match="grey.tiff: not an RGGB CFA DNG"):
        read_dng_mosaic(tmp_path / "grey.tiff")
    (tmp_path / "text.dng").write_text("not a tiff")
    with pytest.raises(DngError, match="text.dng: not a TIFF/DNG file"):
        read_dng_mosaic(tmp_path / "text.dng")


def test_load_packed_reads_the_dng_in_white_level_units(tmp_path):
    m = noisy_mosaic()
    save_dng(tmp_path / "raw.dng", m, CAMERA, BLACK, WHITE)
    x = capture_files.load_packed(tmp_path)
    assert x.dtype == np.float32 and x.shape == (4, 32, 48)
    np.testing.assert_allclose(x, (pack_rggb(m).astype(np.float64) - BLACK) / (WHITE - BLACK), rtol=1e-6)
    with pytest.raises(capture_files.CaptureFileError, match=r"missing/raw\.dng: missing"):
        capture_files.load_packed(tmp_path / "missing")


def _result(size_px=(32, 48)):
    """A one-view synthesis result (a flat field through the sensor), as write_synthesis takes it."""
    gt = np.full((3,) + size_px, 0.25, np.float32)
    cap = capture_electrons(np.full(size_px, 3000.0), SensorConfig(form="per_channel"), np.random.default_rng(0))
    return SimpleNamespace(gt=gt, captures={"glass": cap}, display_meta={"glass": {"display": {"name": "glass"}}},
                           meta={"item": 0})


@pytest.mark.parametrize("previews", [True, False])
def test_previews_are_optional_and_the_summary_is_not(tmp_path, previews):
    summary = capture_files.write_synthesis(tmp_path, _result(), CAMERA, side_by_side=False, previews=previews)
    files = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    assert {"gt.exr", "glass/raw.dng", "glass/capture.json", "summary.json", "summary.md", "synth.json"} <= files
    assert ({"gt_preview.png", "glass/preview.png"} <= files) is previews
    assert "side_by_side.png" not in files
    assert np.isfinite(summary["views"]["glass"]["psnr_db_vs_gt_srgb"])


def test_gt_exr_is_written_uncompressed_and_read_back_bit_for_bit(tmp_path):
    """gt.exr carries the ground truth's float32 bits, and its header says the compression capture.py chose."""
    import OpenEXR

    from udc_render.io.exr import read_exr
    result = _result()
    capture_files.write_synthesis(tmp_path, result, CAMERA, side_by_side=False, previews=False)
    back = read_exr(tmp_path / "gt.exr")
    assert all(np.array_equal(back[c], result.gt[i]) for i, c in enumerate("RGB"))
    with OpenEXR.File(str(tmp_path / "gt.exr")) as f:
        assert f.header()["compression"] == OpenEXR.NO_COMPRESSION


@pytest.mark.parametrize("compression", ["zip", "zips", "piz", "rle", "none"])
def test_every_exr_compression_is_lossless(tmp_path, compression):
    from udc_render.io.exr import read_exr, save_exr
    a = np.random.default_rng(0).random((3, 37, 53), dtype=np.float32)
    save_exr(tmp_path / "a.exr", {c: a[i] for i, c in enumerate("RGB")}, compression=compression)
    back = read_exr(tmp_path / "a.exr")
    assert all(np.array_equal(back[c], a[i]) for i, c in enumerate("RGB"))


def test_an_unknown_exr_compression_is_refused_before_writing(tmp_path):
    from udc_render.io.exr import save_exr
    with pytest.raises(ValueError, match="EXR compression 'b44': expected one of zip, zips, piz, rle, none"):
        save_exr(tmp_path / "a.exr", {"Y": np.zeros((2, 2), np.float32)}, compression="b44")
    assert not any(tmp_path.iterdir())
