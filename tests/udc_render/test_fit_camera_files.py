"""The fit through files written as cameras write them recovers what it recovers from clean files: the PSF
exposures as a 16-bit colour PNG, a 16-bit colour TIFF and a lossless-JPEG DNG with a black level per site,
row and column deltas, a LinearizationTable and an ActiveArea (tests/udc_render/camera_files.py); the white
square pair with a hot pixel and a reflection, as such DNGs. The readers hand the fit the same DN above black
as the clean files (within the table's step), so the fit is the same; the slow test runs the fit on both."""
from __future__ import annotations

from dataclasses import replace

import imageio.v3 as iio
import numpy as np
import png
import pytest
import tifffile

from psf import layouts
from tests.udc_render.camera_files import CameraDng, companding_table, encode_linear, write_camera_dng
from udc_render.fit import synthetic as S
from udc_render.fit.inputs import read_frame, read_frames
from udc_render.io.dng import save_dng
from udc_render.streams import stream

CAMERA = "Nikon 5100 (NPL)"
TOLED = dict(pitch_um=290.0, open_fraction=0.24, slit_height_fraction=0.85)
MARGIN = (3, 5, 4, 6)  # the ActiveArea's margins: top, left, bottom, right


def _colour_png(path, rgb: np.ndarray) -> None:
    h, w, _ = rgb.shape
    with open(path, "wb") as fh:
        png.Writer(w, h, greyscale=False, bitdepth=16).write(fh, rgb.reshape(h, -1))


def _camera_dng(path, mosaic: np.ndarray, black_dn: float = 64.0) -> CameraDng:
    """mosaic (RGGB, uint16 with `black_dn`) as a camera's DNG: its signal above black on four site levels, row
    and column deltas, through a square-law LinearizationTable, inside margins."""
    top, left, bottom, right = MARGIN
    h, w = mosaic.shape
    rng = stream(7, "camera-dng-deltas")
    dng = CameraDng(np.zeros((h + top + bottom, w + left + right), np.uint16), cfa=(0, 1, 1, 2),
                    black=((510.0, 515.0), (505.0, 520.0)), delta_v=np.round(rng.uniform(-2, 2, h), 3),
                    delta_h=np.round(rng.uniform(-2, 2, w), 3), table=companding_table(), white=65000,
                    active=(top, left, top + h, left + w))
    dng = replace(dng, stored=encode_linear(dng, mosaic.astype(float) - black_dn))
    write_camera_dng(path, dng)
    return dng


def _half_step(dng: CameraDng, linear: np.ndarray) -> np.ndarray:
    """Half the larger of the table's steps beside each linear value: the most a nearest code can be off."""
    table = dng.table.astype(float)
    j = np.clip(np.searchsorted(table, linear), 1, table.size - 2)
    return np.maximum(table[j] - table[j - 1], table[j + 1] - table[j]) / 2


def test_psf_exposures_read_alike_from_every_file_kind(tmp_path):
    """A grey 16-bit PNG (clean), a 16-bit colour PNG and TIFF (the spot in R): the same DN above black; RGGB
    mosaics as an uncompressed DNG with one black level (clean) and as a camera's LJ92 DNG: the same, below the
    white level, within half the table's step (0.5 DN where the table is the identity, below 2048 DN: the
    codes are integers, the black levels and deltas are not)."""
    grey = S.psf_measurement(layouts.toled(**TOLED), shape_hw=(96, 128), peaks_fw=(0.8, 8.0), seed=3, window_px=95)
    for i, g in enumerate(grey):
        iio.imwrite(tmp_path / f"g{i}.png", g)
        rgb = np.stack([g, (g - 64) // 10 + 64, (g - 64) // 50 + 64], axis=-1).astype(np.uint16)
        _colour_png(tmp_path / f"c{i}.png", rgb)
        tifffile.imwrite(tmp_path / f"c{i}.tif", rgb, photometric="rgb")
    clean = read_frames([tmp_path / f"g{i}.png" for i in range(2)], 64)
    for suffix in (".png", ".tif"):
        frames = read_frames([tmp_path / f"c{i}{suffix}" for i in range(2)], 64)
        for f, c in zip(frames, clean):
            assert f.kind == "rgb" and np.array_equal(f.above_black()[..., 0], c.above_black())
    cfa = S.psf_measurement(layouts.toled(**TOLED), shape_hw=(96, 128), peaks_fw=(0.8, 8.0), seed=3, window_px=95,
                            cfa=True)
    save_dng(tmp_path / "clean.dng", cfa[1], CAMERA, 64, 65535)
    dng = _camera_dng(tmp_path / "camera.dng", cfa[1])
    c, f = read_frame(tmp_path / "clean.dng"), read_frame(tmp_path / "camera.dng")
    assert f.sites.tolist() == c.sites.tolist() == [[0, 1], [1, 2]] and f.black_map is not None
    below = c.dn < 65534.5
    diff = np.abs(f.above_black() - c.above_black())[below]
    assert np.all(diff <= _half_step(dng, f.dn[below]) + 1e-9) and np.all(diff[f.dn[below] < 2048] <= 0.5 + 1e-9)


def test_the_white_square_through_camera_dngs(tmp_path):
    """The white pair with a hot pixel and a reflection in the glass capture, as camera DNGs: γ within 1 % and
    3 σ of the truth, and within 0.2 % of what the clean DNGs give (the table's steps: 20–40 DN at the square's
    24 000–46 000 DN)."""
    from udc_render.fit.white import measure_gamma
    truth = np.array([0.42, 0.5, 0.5, 0.61])
    glass, disp = S.white_pair(truth, display_gain=6.0, seed=3)
    g = glass.astype(float)
    g[10, 240] = 65535.0
    g[200:220, 10:40] += 0.8 * float(np.median(glass[100:150, 100:150]) - 64)
    glass = np.clip(g, 0, 65535).astype(np.uint16)
    for name, mosaic in (("g", glass), ("d", disp)):
        save_dng(tmp_path / f"{name}_clean.dng", mosaic, CAMERA, 64, 65535)
        _camera_dng(tmp_path / f"{name}_camera.dng", mosaic)
    clean = measure_gamma(read_frame(tmp_path / "g_clean.dng"), read_frame(tmp_path / "d_clean.dng"))
    cam = measure_gamma(read_frame(tmp_path / "g_camera.dng"), read_frame(tmp_path / "d_camera.dng"))
    assert cam.square_xy_px == clean.square_xy_px == (128, 128)
    assert np.all(np.abs(cam.gamma / truth - 1) < 0.01) and np.all(np.abs(cam.gamma - truth) < 3 * cam.sigma)
    assert np.all(np.abs(cam.gamma / clean.gamma - 1) < 0.002)


@pytest.mark.slow
def test_the_psf_fit_through_a_camera_dng_recovers_the_clean_fit(tmp_path):
    """Two RGGB exposures of the guide's T-OLED (the brighter saturated) as camera LJ92 DNGs and as clean DNGs:
    the pitch within 1 % and the open fraction within 10 % of the clean files' fit (~3 min: two fits)."""
    from udc_render.fit import FitSpec
    from udc_render.fit.hdr import merge_psf
    from udc_render.fit.psf_fit import fit_psf
    frames = S.psf_measurement(layouts.toled(**TOLED), shape_hw=(320, 384), offset_px=(6.3, -4.1), rotation_deg=2.5,
                               peaks_fw=(0.8, 8.0), seed=11, window_px=255, cfa=True)
    fits = {}
    for kind in ("clean", "camera"):
        paths = [tmp_path / f"{kind}{i}.dng" for i in range(len(frames))]
        for p, f in zip(paths, frames):
            save_dng(p, f, CAMERA, 64, 65535) if kind == "clean" else _camera_dng(p, f)
        plane = merge_psf(read_frames(paths), 650.0, CAMERA)
        fits[kind] = fit_psf(plane, FitSpec(psf=tuple(map(str, paths))).optics(), "toled", None, 255).chosen
    c, k = fits["clean"], fits["camera"]
    for (pc, _), (pk, _) in zip(c.pitch_um, k.pitch_um):
        assert abs(pk / pc - 1) < 0.01 and abs(pc / 290.0 - 1) < 0.01
    ofc, ofk = c.fit.params[0] * c.fit.params[1], k.fit.params[0] * k.fit.params[1]
    assert abs(ofk / ofc - 1) < 0.10 and abs(ofc / 0.24 - 1) < 0.10
