"""Rendering with Mitsuba: radiometry, geometry, linearity, determinism, depth, noise target, EXR
output, a user's XML scene and the LLVM → scalar fallback.

Renders are tiny (a 480 × 270 panel; sensors of 64 × 32 px at 49.6 µm or 128 × 64 px at 24.8 µm,
i.e. 32× or 16× the paper's 1.55 µm pitch so the field of view is the paper's) and use few samples;
every Monte Carlo tolerance is computed from the render's own noise. Everything here passes with
the llvm_ad_* variants and with the scalar_* ones (UDC_RENDER_VARIANT=scalar pytest …).
"""
import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from udc_render.content import spectra
from udc_render.render import band_names, render_scene, variants
from udc_render.render.job import pass_statistics
from udc_render.scene import Camera, geometry as rig, parse_scene

pytestmark = pytest.mark.usefixtures("render_cache")

SMALL = dict(sensor_px=(64, 32), pitch_um=49.6)  # 32 × 1.55 µm: the paper's field of view on 64 × 32 px
# |z| bound on Monte Carlo tests: two-sided p = 6.8e-6 per value, < 1e-3 over the ≤ 100 values a test checks
Z_MAX = 4.5


def scene_of(udc, tmp_path, **kw):
    return parse_scene(udc.monitor_doc(**kw), str(tmp_path / "scene.toml"))


def white_reference(scene) -> np.ndarray:
    """Band means of the monitor's white (all primaries at full drive): the analytic band values."""
    m = scene.content
    prim = spectra.monitor_primaries(m.primaries, m.peak_luminance_cd_m2)[0]
    return spectra.band_means(prim.sum(0), scene.bands.edges_nm)


def frame64(b) -> np.ndarray:
    """The sensor frame in float64 (a float32 mean over 10⁴ pixels would itself err by ~1e-4)."""
    return b.frame(b.bands).astype(np.float64)


def unmix(b) -> np.ndarray:
    """The drive-weighted panel RGB [3, H, W] behind band values: least squares through the band
    matrix P [3, K] (bands = Pᵀ w exactly on the rgb path)."""
    P = np.asarray(b.meta["band_matrix"])
    K, H, W = b.bands.shape
    w, *_ = np.linalg.lstsq(P.T, b.bands.reshape(K, -1).astype(np.float64), rcond=None)
    return w.reshape(3, H, W)


# ---------------------------------------------------------------- shared renders (module scope)


@pytest.fixture(scope="module")
def tmp_module(tmp_path_factory):
    return tmp_path_factory.mktemp("render")


@pytest.fixture(scope="module")
def white_spectral(udc, tmp_module):
    """pattern:white filling the frame, full spectral path: 64 × 32 px, 8 spp, 4 bands per render, no margin;
    the independent sampler (the test's z-scores take the pixels as i.i.d. estimates)."""
    s = scene_of(udc, tmp_module, framing="fill", **SMALL,
                 render={"spp": 8, "path": "spectral", "margin_um": 0, "bands_per_render": 4, "sampler": "independent"})
    return s, render_scene(s, progress=False)


@pytest.fixture(scope="module")
def astronaut(udc, tmp_module):
    """builtin:astronaut (fit), 64 × 32 px, 16 spp: the rgb path (seed 1) and the spectral path (seed 2);
    the independent sampler (the tests below use independent pixels and the 1/√N law)."""
    s = scene_of(udc, tmp_module, image="builtin:astronaut", framing="fit", **SMALL,
                 render={"spp": 16, "margin_um": 0, "bands_per_render": 4, "sampler": "independent"})
    return (s, render_scene(s.with_render(path="rgb_matrix", seed=1), progress=False),
            render_scene(s.with_render(path="spectral", seed=2), progress=False))


# ---------------------------------------------------------------- radiometry


@pytest.mark.fallback
def test_white_monitor_spectral_path_equals_the_analytic_band_integrals(white_spectral):
    s, b = white_spectral
    assert b.meta["render_path"] == "spectral" and b.meta["variant"].endswith("_spectral")
    ref = white_reference(s)
    fr = frame64(b)
    mean = fr.mean((1, 2))
    # Every pixel sees the same uniform panel, so pixels are i.i.d. estimates of the band value and
    # the standard error of the frame mean is the pixel spread / √N (N = 2048 pixels). The floor
    # 1e-5·ref covers float32 arithmetic inside Mitsuba (band sums of ~10 samples, ~1e-6).
    se = fr.std((1, 2), ddof=1) / math.sqrt(fr[0].size)
    sigma = np.hypot(se, 1e-5 * ref)
    z = (mean - ref) / sigma
    assert np.all(np.abs(z) < Z_MAX), np.round(z, 2)
    # ... and the check has teeth: the error bar is below 1.5 % in every band (measured ≤ 0.5 %)
    assert np.all(se < 0.015 * ref), se / ref
    # sum of squares over the 30 bands: χ²₃₀, P(χ² > 80) < 2e-6
    assert float(np.sum(z ** 2)) < 80


@pytest.mark.fallback
def test_white_monitor_rgb_path_is_exact(udc, tmp_path):
    """The rgb path's only approximation is pixel coverage; a panel filling the frame covers every
    pixel, so each pixel equals the analytic band value up to float32 rounding (a few ulp: 1e-6)."""
    s = scene_of(udc, tmp_path, framing="fill", **SMALL, render={"spp": 4, "path": "rgb_matrix"})
    b = render_scene(s, progress=False)
    assert b.meta["render_path"] == "rgb_matrix" and b.meta["variant"].endswith("_rgb")
    ref = white_reference(s)
    np.testing.assert_allclose(frame64(b), np.broadcast_to(ref[:, None, None], b.frame(b.bands).shape), rtol=1e-6)
    np.testing.assert_allclose(b.meta["band_matrix"], spectra.band_means(
        spectra.monitor_primaries(s.content.primaries, 300.0)[0], s.bands.edges_nm), rtol=1e-12)
    assert b.meta["noise_rel"] == 0.0  # nothing varies between passes


@pytest.mark.fallback
def test_rgb_matrix_and_spectral_paths_agree_on_an_image(astronaut):
    s, a, b = astronaut
    A, B = frame64(a), frame64(b)
    na, nb = a.meta["noise_rel"], b.meta["noise_rel"]
    assert 0 < na < 0.2 and 0 < nb < 0.3
    # Independent noise: E‖A − B‖² = ‖σ_A‖² + ‖σ_B‖², with ‖σ‖ = noise_rel · ‖x‖ (render.pass_statistics).
    expected = math.sqrt((na * np.linalg.norm(A)) ** 2 + (nb * np.linalg.norm(B)) ** 2)
    ratio = np.linalg.norm(A - B) / expected
    # 61 440 values (≥ 2048 independent pixels × 3 colours): ‖A − B‖ and both noise estimates are
    # good to a few %, so the ratio is 1 ± 0.1 unless the paths differ (measured 0.96–1.06, 8 seeds).
    assert 0.75 < ratio < 1.3, ratio
    # Averaging n independent pixels divides the noise norm by n (‖σ_avg‖ = ‖σ‖/n summed over the
    # averages) but keeps any real difference between the paths. 8 × 8 blocks: 960 values, ≥ 96
    # independent, measured 0.86–1.13 → < 1.4; an overall 2.6 % bias of either path reaches 1.4.
    def blocks(x, n):
        K, H, W = x.shape
        return x.reshape(K, H // n, n, W // n, n).mean((2, 4))
    ratio_b = np.linalg.norm(blocks(A, 8) - blocks(B, 8)) / (expected / 64)
    assert ratio_b < 1.4, ratio_b
    # the frame means of the 30 bands (~3 independent values: χ²₃ > 27 has p = 6e-6, so < 3;
    # measured 0.67–1.35): a 2 % bias reaches 3
    ratio_f = np.linalg.norm(A.mean((1, 2)) - B.mean((1, 2))) / (expected / A[0].size)
    assert ratio_f < 3, ratio_f


# ---------------------------------------------------------------- geometry


SQUARES = {0: (0, 0), 1: (0, -1), 2: (-1, 0)}  # channel → (row, col) corner: R top-left, G top-right, B bottom-left


def square_centres_m(scene) -> np.ndarray:
    """World centres of the orientation pattern's squares: panel in z = 0, centred, row 0 at the top (+y)."""
    cols, rows = scene.content.resolution_px
    w, h = scene.content.size_m
    side = rows // 8
    out = []
    for c in range(3):
        r, k = SQUARES[c]
        rc = side / 2 if r == 0 else rows - side / 2  # panel-pixel coordinates of the square's centre
        cc = side / 2 if k == 0 else cols - side / 2
        out.append([-w / 2 + cc * w / cols, h / 2 - rc * h / rows, 0.0])
    return np.array(out)


def centroid(img, centre, half):
    """Energy centroid (x, y) of img [H, W] in a window of ±half px around centre; pixel centres at i + 0.5."""
    x0, y0 = (int(round(v)) for v in centre)
    ys, xs = slice(max(y0 - half, 0), y0 + half), slice(max(x0 - half, 0), x0 + half)
    win = img[ys, xs]
    yy, xx = np.mgrid[ys, xs] + 0.5
    return np.array([(win * xx).sum(), (win * yy).sum()]) / win.sum()


@pytest.mark.parametrize("path, size, supersample, tol_px", [
    # rgb: partial coverage of the edge pixels of a 7.8 px square moves its centroid by at most
    # 2 · ¼ px / 7.8 ≈ 0.07 px; coverage noise ~0.01 px → 0.1 px (measured 0.03); a shift of the
    # panel by half a panel pixel (0.13 px) fails
    ("rgb_matrix", dict(sensor_px=(128, 64), pitch_um=24.8), 1, 0.1),
    ("rgb_matrix", dict(sensor_px=(128, 64), pitch_um=24.8), 2, 0.2),  # in render pixels, half the size
    # spectral: 3.9 px squares at 32 spp; the noise of the unmixed bands moves the centroids by
    # ≤ 0.12 px (measured over 10 seeds) → 0.3 px
    ("spectral", SMALL, 1, 0.3),
])
def test_orientation_pattern_lands_where_the_projection_says(udc, tmp_path, path, size, supersample, tol_px):
    s = scene_of(udc, tmp_path, image="pattern:orientation", framing="fit", **size,
                 render={"spp": 8 if path == "rgb_matrix" else 32, "path": path, "supersample": supersample},
                 bands={"range_nm": [400, 700], "step_nm": 50})
    b = render_scene(s, progress=False)
    g = rig.camera_geometry(s)
    assert b.bands.shape[1:] == (g.height_px, g.width_px) and b.margin_px == g.margin_px
    w = unmix(b)
    expect = rig.projection_px(g, square_centres_m(s))
    side_px = (s.content.resolution_px[1] // 8) / s.content.resolution_px[1] * s.sensor.height_px * supersample
    got = np.array([centroid(w[c], expect[c], int(side_px) + 2) for c in range(3)])
    np.testing.assert_allclose(got, expect, atol=tol_px, rtol=0)
    # independent of projection_px: green right of red (no mirroring), blue below red (upright, y down)
    (rx, ry), (gx, gy), (bx, by) = got
    W, H = g.width_px, g.height_px
    assert rx < W / 2 < gx and abs(ry - gy) < tol_px
    assert ry < H / 2 < by and abs(rx - bx) < tol_px
    # and nothing else is lit: outside the three squares' windows the drive is ~0
    mask = np.ones((H, W), bool)
    half = int(side_px) + 2
    for c in range(3):
        x0, y0 = (int(round(v)) for v in expect[c])
        mask[max(y0 - half, 0):y0 + half, max(x0 - half, 0):x0 + half] = False
    assert np.abs(w[:, mask]).max() < (1e-6 if path == "rgb_matrix" else 0.5)


@pytest.mark.parametrize("framing", ["fit", "fill"])
def test_framing_of_a_white_panel(udc, tmp_path, framing):
    """fit: the panel's height spans the 2:1 sensor's height exactly; fill: its width spans the
    width and the frame is fully covered. Coverage is read from the rgb path (exact per sample)."""
    s = scene_of(udc, tmp_path, framing=framing, render={"spp": 4, "path": "rgb_matrix"})
    b = render_scene(s, progress=False)
    g = rig.camera_geometry(s)
    m, W, H = g.margin_px, s.sensor.width_px, s.sensor.height_px
    assert m == 16  # ceil(396 µm / 24.8 µm): the default margin
    cover = unmix(b).mean(0)  # fraction of each pixel covered by the panel
    lit_rows = np.flatnonzero(cover.max(1) > 0.5)
    lit_cols = np.flatnonzero(cover.max(0) > 0.5)
    w_m, h_m = s.content.size_m
    (x0, y0), (x1, y1) = rig.projection_px(g, np.array([[-w_m / 2, h_m / 2, 0], [w_m / 2, -h_m / 2, 0]]))
    if framing == "fit":
        assert lit_rows[0] == m and lit_rows[-1] == m + H - 1  # exactly the frame's first and last rows
        assert m < lit_cols[0] and lit_cols[-1] < m + W - 1  # narrower than the frame
        assert np.all(cover[:m] < 1e-6) and np.all(cover[m + H:] < 1e-6)
    else:
        np.testing.assert_allclose(b.frame(cover), 1.0, rtol=0, atol=1e-6)  # every frame pixel fully covered
        assert lit_cols[0] == m and lit_cols[-1] == m + W - 1
        assert np.all(cover[:, :m] < 1e-6) and np.all(cover[:, m + W:] < 1e-6)
        assert lit_rows[0] < m and lit_rows[-1] > m + H - 1  # taller than the frame
    # the covered area equals the projected panel (clipped to the grid); the partly covered edge
    # pixels carry binomial coverage noise ≤ ½/√spp each, so 5σ = 2.5/√4 · √(edge pixels)
    area = (min(x1, g.width_px) - max(x0, 0)) * (min(y1, g.height_px) - max(y0, 0))
    edge = np.count_nonzero((cover > 1e-6) & (cover < 1 - 1e-6))
    assert abs(cover.sum() - area) <= 2.5 / 2 * math.sqrt(max(edge, 1)) + 1e-3, (cover.sum(), area, edge)


def edge_model(edge_px: float, blur_px: float, width: int) -> np.ndarray:
    """Coverage [width] of pixels (box, centres i + 0.5) by a panel to the right of a vertical edge at
    edge_px, blurred by a uniform disc of diameter blur_px, whose line spread is ∝ √(R² − x²)."""
    R = max(blur_px / 2, 1e-9)
    xs = np.linspace(-R, R, 20001)
    cdf = np.cumsum(np.sqrt(np.clip(R * R - xs * xs, 0, None)))
    cdf /= cdf[-1]
    sub = np.arange(width)[:, None] + (np.arange(256)[None, :] + 0.5) / 256  # 256 points across each pixel
    return np.interp(sub - edge_px, xs, cdf, left=0.0, right=1.0).mean(1)


@pytest.mark.parametrize("focus_m", [None, 0.2])
def test_thin_lens_blurs_the_panel_edge_by_the_geometric_circle_of_confusion(udc, tmp_path, focus_m):
    """A thin lens of aperture A focused at u_f images a point at u as a disc of angular diameter
    A·|1/u − 1/u_f|, i.e. A·|1/u − 1/u_f|·v/pitch pixels (0 when focused on the monitor, 3.5 px at
    0.2 m). The panel's left edge, averaged over 16 rows, must follow the disc-blurred, pixel-
    integrated step; binomial coverage noise ≤ ½/√(16 · 256) = 0.008 per pixel → 0.04 (5σ)."""
    doc = udc.monitor_doc(framing="fit", render={"spp": 256, "path": "rgb_matrix"})
    doc["lens"] = {"model": "thinlens", **({"focus_distance_m": focus_m} if focus_m else {})}
    s = parse_scene(doc, str(tmp_path / "lens.toml"))
    b = render_scene(s, progress=False)
    g = rig.camera_geometry(s)
    u = rig.monitor_distance_m(s)
    blur_px = s.lens.aperture_mm * 1e-3 * abs(1 / u - 1 / g.focus_distance_m) * g.image_distance_um / g.pitch_um
    assert blur_px == pytest.approx(0.0 if focus_m is None else 3.506, abs=1e-3)
    edge = rig.projection_px(g, np.array([-s.content.size_m[0] / 2, 0.0, 0.0]))[0]
    profile = unmix(b).mean(0)[g.height_px // 2 - 8:g.height_px // 2 + 8].mean(0)[:g.width_px // 2]
    model = edge_model(edge, blur_px, g.width_px // 2)
    np.testing.assert_allclose(profile, model, rtol=0, atol=0.04)
    if focus_m:  # the tolerance is well below the effect: a sharp edge differs from this one by > 0.15
        assert np.abs(edge_model(edge, 0.0, g.width_px // 2) - model).max() > 0.15


@pytest.mark.parametrize("spp", [256, pytest.param(8192, marks=pytest.mark.slow)])
def test_hdr_sky_and_sun_have_their_luminance(spp):
    """The shipped HDR room at 32 × 16 px of 99.2 µm (the paper's field of view), direct light only
    (max_depth 1). Through the window: the sky's band values (D65 at 8000 cd/m²), per band within
    4.5 standard errors of the pixel mean. The sun (0.53°, 1.6e9 cd/m², inside the frame) is
    sub-pixel: Σ Y over its pixels = Y_sun × its projected area in px² = Ω v²/(cos³θ pitch²);
    the hit count is binomial, σ_rel ≤ 1/√(spp · area) (12.5 % at 256 spp, 2.2 % at 8192)."""
    from udc_render.render.mitsuba_scene import SUN_ANGULAR_DIAMETER_DEG, SUN_SEEN_AT_M, WINDOW_M
    from udc_render.scene import Bands, Sensor, load_scene
    s = load_scene("hdr")
    s = replace(s, sensor=Sensor(32, 16, 99.2), bands=Bands((400.0, 700.0), 50.0))
    s = s.with_render(spp=spp, max_depth=1, depth=False, seed=1, sampler="independent")  # i.i.d. pixels, binomial hits
    b = render_scene(s, progress=False)
    g = rig.camera_geometry(s)
    o = np.asarray(g.origin_m)
    yweights = spectra.band_xyz(b.edges_nm)[1]
    # the sky through the window (WINDOW_M in the back wall z = −2), 1 px in
    wx0, wx1, wy0, wy1 = WINDOW_M
    (x0, y0), (x1, y1) = rig.projection_px(g, np.array([[wx0, wy1, -2.0], [wx1, wy0, -2.0]]))
    yy, xx = np.mgrid[0:g.height_px, 0:g.width_px] + 0.5
    d = np.subtract(SUN_SEEN_AT_M, o)
    d /= np.linalg.norm(d)
    sun_px = rig.projection_px(g, o + 1000 * d)
    near_sun = np.hypot(xx - sun_px[0], yy - sun_px[1]) < 2.5
    sky = (xx > x0 + 1) & (xx < x1 - 1) & (yy > y0 + 1) & (yy < y1 - 1) & ~near_sun
    assert sky.sum() > 20, sky.sum()
    sky_ref = spectra.band_means(spectra.scaled_to_luminance(spectra.illuminant("D65"), 8000.0), b.edges_nm)
    v = b.bands[:, sky].astype(np.float64)
    se = v.std(1, ddof=1) / math.sqrt(v.shape[1])
    z = (v.mean(1) - sky_ref) / np.hypot(se, 1e-5 * sky_ref)
    assert np.all(np.abs(z) < Z_MAX), np.round(z, 2)
    assert yweights @ sky_ref == pytest.approx(8000, rel=0.01)  # 50 nm bands vs the 1 nm luminance
    # the sun
    Y = np.einsum("k,khw->hw", yweights, b.bands.astype(np.float64))
    sun_Y = Y[near_sun].sum() - near_sun.sum() * np.median(Y[sky])  # minus the sky behind it
    sun_spec = spectra.scaled_to_luminance(spectra.illuminant("D55"), 1.6e9)
    half = math.radians(SUN_ANGULAR_DIAMETER_DEG / 2)
    area_px = 2 * math.pi * (1 - math.cos(half)) * g.image_distance_um ** 2 / (d @ g.forward) ** 3 / g.pitch_um ** 2
    expected = (yweights @ spectra.band_means(sun_spec, b.edges_nm)) * area_px
    sigma = 1 / math.sqrt(spp * area_px)
    assert abs(sun_Y / expected - 1) < 5 * sigma, (sun_Y / expected, sigma)
    assert Y.max() / np.median(Y[sky]) > 1e4  # high dynamic range: the sun pixel over the sky


# ---------------------------------------------------------------- linearity and determinism


@pytest.mark.parametrize("fmt, path", [("tif", "rgb_matrix"), ("png", "rgb_matrix"), ("tif", "spectral")])
def test_bands_are_linear_in_the_displayed_image(udc, tmp_path, fmt, path):
    """16-bit images A, B and M = 0.3 A + 0.7 B (linear transfer, same seed): bands(M) = 0.3 bands(A)
    + 0.7 bands(B). Codes are multiples of 10, so M's codes 3a' + 7b' are exact integers: no
    quantisation. Colour as 16-bit TIFF; grey as 16-bit PNG (imageio's Pillow reads 16-bit colour
    PNGs as 8-bit, see test_scene)."""
    import imageio.v3 as iio
    rng = np.random.default_rng(7)
    shape = (27, 48, 3) if fmt == "tif" else (27, 48)
    a, b = (rng.integers(0, 6554, shape) * 10 for _ in range(2))
    mix = 3 * a // 10 + 7 * b // 10
    assert np.array_equal(10 * mix, 3 * a + 7 * b) and mix.max() <= 65535
    for name, img in (("a", a), ("b", b), ("m", mix)):
        iio.imwrite(tmp_path / f"{name}.{fmt}", img.astype(np.uint16))
    size = SMALL if path == "rgb_matrix" else dict(sensor_px=(32, 16), pitch_um=99.2)
    out = {}
    for name in "abm":
        s = scene_of(udc, tmp_path, image=f"{name}.{fmt}", transfer="linear", framing="fit", resolution_px=(96, 54),
                     **size, render={"spp": 4, "seed": 5, "path": path}, bands={"range_nm": [400, 700], "step_nm": 20})
        out[name] = render_scene(s, progress=False).bands.astype(np.float64)
    assert out["a"].max() > 0 and not np.allclose(out["a"], out["b"])
    # float32 rounding of the bitmap, of each sample and of the pass sums: ~1e-7 of the largest
    # value (measured); 1e-5 leaves room without hiding any non-linearity of the transport
    np.testing.assert_allclose(out["m"], 0.3 * out["a"] + 0.7 * out["b"], rtol=0, atol=1e-5 * out["m"].max())


@pytest.mark.parametrize("path", ["rgb_matrix", "spectral"])
def test_same_seed_is_bit_identical_and_another_seed_differs(astronaut, path):
    s, a, b = astronaut
    first = a if path == "rgb_matrix" else b
    again = render_scene(s.with_render(path=path, seed=first.meta["seed"]), progress=False)
    np.testing.assert_array_equal(again.bands, first.bands)
    other = render_scene(s.with_render(path=path, seed=first.meta["seed"] + 100), progress=False)
    diff = np.linalg.norm(frame64(other) - frame64(first)) / np.linalg.norm(frame64(first))
    # two independent renders differ by √2 × their relative noise (±25 %)
    expected = math.sqrt(2) * first.meta["noise_rel"]
    assert 0.75 * expected < diff < 1.25 * expected, (diff, expected)


# ---------------------------------------------------------------- depth


@pytest.mark.fallback
def test_monitor_depth_is_the_axial_distance_where_the_centre_ray_hits(udc, tmp_path):
    s = scene_of(udc, tmp_path, framing="fill", render={"spp": 1, "path": "rgb_matrix", "depth": True})
    b = render_scene(s, progress=False)
    g = rig.camera_geometry(s)
    dist = rig.monitor_distance_m(s)
    assert b.depth_m is not None and b.depth_m.shape == (g.height_px, g.width_px)
    # pinhole ray through each pixel centre meets z = 0 at dist · x_sensor / v
    xs = (np.arange(g.width_px) + 0.5 - g.width_px / 2) * g.pitch_um / g.image_distance_um * dist
    ys = (g.height_px / 2 - np.arange(g.height_px) - 0.5) * g.pitch_um / g.image_distance_um * dist
    w, h = s.content.size_m
    hit = (np.abs(xs)[None, :] < w / 2) & (np.abs(ys)[:, None] < h / 2)
    assert hit.sum() > 0 and (~hit).sum() > 0 and np.all(b.frame(hit))  # fill: the whole frame is panel
    # float32 positions of a point 0.2 m away: ~1e-8 m, so 1e-5 relative is loose
    np.testing.assert_allclose(b.depth_m[hit], dist, rtol=1e-5)
    assert np.all(np.isinf(b.depth_m[~hit]))
    assert "axial distance" in b.meta["depth"]
    # the default for the monitor: no depth (a plane at a known distance)
    assert render_scene(s.with_render(depth=None), progress=False).depth_m is None


@pytest.mark.fallback
def test_room_depth_is_finite_and_hits_the_back_wall_on_the_axis(tmp_path):
    # the room at 32 × 16 px of 99.2 µm (64 × 1.55 µm: the paper's field of view), 1 spp, 3 bands
    doc = {"content": {"type": "room"}, "camera": {"origin_m": [0.0, 1.1, 3.4], "target_m": [0.0, 0.2, -2.0]},
           "sensor": {"width_px": 32, "height_px": 16, "pitch_um": 99.2}, "bands": {"step_nm": 100},
           "render": {"spp": 1, "max_depth": 2, "margin_um": 0}}
    s = parse_scene(doc, str(tmp_path / "room.toml"))
    b = render_scene(s, progress=False)
    assert b.meta["render_path"] == "spectral" and b.depth_m is not None
    d = b.depth_m
    assert np.all(np.isfinite(d)) and d.min() > 0.5 and d.max() < 7.0  # a closed 4 × 2.6 × 5.5 m room
    assert np.all(np.isfinite(b.bands)) and b.bands.min() >= 0 and b.bands.max() > 0
    # the four centre pixels look over the objects at the bare back wall (z = −2 m, below the chart):
    # intersect their centre rays with that plane and take the axial distance (float32: 1e-5)
    g = rig.camera_geometry(s)
    fwd = g.forward
    right = np.cross(fwd, g.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    for j in (7, 8):
        for i in (15, 16):
            x_um = (i + 0.5 - g.width_px / 2) * g.pitch_um
            y_um = (g.height_px / 2 - j - 0.5) * g.pitch_um
            ray = fwd * g.image_distance_um + right * x_um + up * y_um
            t = (-2.0 - g.origin_m[2]) / ray[2]
            p = np.asarray(g.origin_m) + t * ray
            assert 0.0 < p[1] < 0.43  # above the floor, below the chart (its lowest row starts at 0.43 m)
            assert d[j, i] == pytest.approx(rig.axial_depth_m(g, p), rel=1e-5)


# ---------------------------------------------------------------- noise target, metadata, files


def test_noise_target_sets_spp_from_pilot_renders(astronaut):
    s, a, _ = astronaut
    target = 0.02
    b = render_scene(s.with_render(path="rgb_matrix", spp=None, noise=target, seed=3), progress=False)
    m = b.meta
    pilot = m["pilot_noise_rel"]
    assert m["spp_from_noise_target"] == target and m["pilot_spp"] == 8
    assert pilot > target  # the target needs more than the pilot's 8 samples
    assert m["spp"] >= math.ceil(8 * (pilot / target) ** 2)  # passes round spp up
    # MC noise falls as 1/√spp; the pilot's own estimate (2 passes of 4 spp, dominated by the
    # image's edges) and spp rounding scatter the result: measured 0.95–1.14 × target over 8 seeds
    assert abs(m["noise_rel"] / target - 1) < 0.35, m["noise_rel"]


def test_pass_statistics_noise_formula():
    rng = np.random.default_rng(0)
    x = (2.0 + 0.1 * rng.standard_normal((4, 3, 50, 200))).astype(np.float32)  # 4 passes, σ = 0.1 around 2
    mean, var_sum, sq_sum = pass_statistics(x)
    np.testing.assert_allclose(mean, x.astype(np.float64).mean(0), rtol=1e-6)
    # σ of the mean of 4 passes = 0.05, relative to ‖x̄‖ ≈ 2 → 0.025 (30 000 values: ± 0.5 % sampling error)
    assert math.sqrt(var_sum / sq_sum) == pytest.approx(0.025, rel=0.02)
    # with a channel → band matrix the sums are those of the bands x_k = Σ_c M_ck w_c, computed
    # here the long way (bands of every pass, then their variance): an identity, 1e-9
    M = rng.uniform(0, 1, (3, 7))
    bands = np.einsum("ck,pchw->pkhw", M, x.astype(np.float64))
    _, v, q = pass_statistics(x, M)
    assert v == pytest.approx((bands.var(0, ddof=1) / 4).sum(), rel=1e-9)
    assert q == pytest.approx((bands.mean(0) ** 2).sum(), rel=1e-9)


def test_exr_json_and_preview_roundtrip(udc, tmp_path):
    import imageio.v3 as iio
    import OpenEXR

    from udc_render.io.band_image import load_band_image, save_band_image
    s = scene_of(udc, tmp_path, framing="fill", **SMALL,
                 render={"spp": 2, "path": "rgb_matrix", "depth": True}, bands={"range_nm": [400, 700], "step_nm": 5})
    b = render_scene(s, progress=False)
    out = tmp_path / "out"
    written = save_band_image(b, out)
    assert set(written) == {"exr", "json", "preview", "depth"} and all(Path(p).is_file() for p in written.values())
    back = load_band_image(out)
    np.testing.assert_array_equal(back.bands, b.bands)
    np.testing.assert_array_equal(back.depth_m, b.depth_m)  # inf in the margin survives
    np.testing.assert_array_equal(back.edges_nm, b.edges_nm)
    assert (back.pitch_um, back.margin_px) == (b.pitch_um, b.margin_px)
    # channel names: zero-padded centres, so alphabetical order is wavelength order
    names = band_names(b.edges_nm)
    assert names[:2] == ["band_0402p5nm", "band_0407p5nm"] and names[-1] == "band_0697p5nm"
    assert band_names(np.arange(400.0, 701.0, 10.0))[0] == "band_0405nm"
    with OpenEXR.File(str(out / "render.exr")) as f:
        chans = list(f.channels())
    assert sorted(chans) == sorted(names + ["depth_m"]) and sorted(names) == names
    meta = json.loads((out / "render.json").read_text())
    missing = set(b.meta) - set(meta)
    assert not missing, missing
    assert {"preview_white_cd_m2", "pitch_um", "margin_px", "shape_khw", "channels"} <= set(meta)
    assert meta["shape_khw"] == list(b.bands.shape) and meta["spp"] == b.meta["spp"] == 2
    # the preview's white is the luminance of the (uniform) frame: Y = band_xyz @ band values,
    # exact here (every frame pixel is the same float32 value); ≈ the 300 cd/m² peak to 0.1 %
    # (5 nm bands instead of the 1 nm table: measured 0.026 %)
    Y = spectra.band_xyz(b.edges_nm)[1] @ white_reference(s)
    assert meta["preview_white_cd_m2"] == pytest.approx(Y, rel=1e-5) and Y == pytest.approx(300, rel=1e-3)
    prev = iio.imread(out / "preview.png")
    H, W = b.frame(b.bands).shape[1:]
    assert prev.shape == (H, W, 3) and prev.dtype == np.uint8 and prev.min() > 200  # white everywhere
    dep = iio.imread(out / "depth.png")
    assert dep.shape == (H, W) and dep.dtype == np.uint8


# ---------------------------------------------------------------- a user's Mitsuba XML scene


XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0.5, 0.2, 3" target="0.5, 0.2, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
  </sensor>
  <emitter type="constant"><spectrum name="radiance" value="1.0"/></emitter>
  <shape type="rectangle">   <!-- diffuse panel, x in [-0.7, 0.3], y in [-0.3, 0.7] -->
    <transform name="to_world"><scale x="0.5" y="0.5"/><translate x="-0.2" y="0.2" z="0"/></transform>
    <bsdf type="diffuse"><spectrum name="reflectance" value="0.5"/></bsdf>
  </shape>
  <shape type="rectangle">   <!-- black emitter, x in [0.65, 1.15], y in [0.0, 0.4] -->
    <transform name="to_world"><scale x="0.25" y="0.2"/><translate x="0.9" y="0.2" z="0"/></transform>
    <bsdf type="diffuse"><spectrum name="reflectance" value="0"/></bsdf>
    <emitter type="area"><spectrum name="radiance" value="2.0"/></emitter>
  </shape>
</scene>
"""


@pytest.mark.fallback
def test_user_xml_scene_renders_spectrally_from_its_own_camera(tmp_path):
    """A constant sky of 1 W·sr⁻¹·m⁻²·nm⁻¹, a diffuse panel of albedo 0.5 (whose upper hemisphere
    sees only the sky: radiance 0.5 exactly) and a black emitter of radiance 2, in z = 0, seen from
    the XML's camera at (0.5, 0.2, 3) looking down −z. The scene file has no camera at all."""
    (tmp_path / "user.xml").write_text(XML)
    doc = {"sensor": {"width_px": 64, "height_px": 32, "pitch_um": 49.6}, "lens": {"focus_distance_m": 3.0},
           "bands": {"range_nm": [400, 700], "step_nm": 50},
           "render": {"spp": 8, "margin_um": 0, "sampler": "independent"},  # i.i.d. pixels for the z-scores
           "content": {"type": "mitsuba_xml", "file": "user.xml"}}
    s = parse_scene(doc, str(tmp_path / "user.toml"))
    assert s.camera.origin_m is None
    b = render_scene(s, progress=False)
    assert b.meta["render_path"] == "spectral" and b.meta["content"] == "mitsuba_xml"
    np.testing.assert_allclose(b.meta["camera"]["origin_m"], [0.5, 0.2, 3.0], atol=1e-6)
    g = rig.camera_geometry(replace(s, camera=Camera(origin_m=(0.5, 0.2, 3.0), target_m=(0.5, 0.2, 0.0))))
    # where each region must be, from the projection of its corners: pixel centres more than 1 px
    # inside (inset 1) or more than 1 px outside (inset −1) its edges
    yy, xx = np.mgrid[0:g.height_px, 0:g.width_px] + 0.5

    def region(x0, x1, y0, y1, inset):
        (px0, py0), (px1, py1) = rig.projection_px(g, np.array([[x0, y1, 0], [x1, y0, 0]]))
        return (xx > px0 + inset) & (xx < px1 - inset) & (yy > py0 + inset) & (yy < py1 - inset)
    PANEL, LAMP = (-0.7, 0.3, -0.3, 0.7), (0.65, 1.15, 0.0, 0.4)
    panel, lamp = region(*PANEL, 1), region(*LAMP, 1)
    sky = ~(region(*PANEL, -1) | region(*LAMP, -1))
    # ≥ 200 i.i.d. pixels each, so their means are normal enough for |z| < 4.5 (z's spread measured
    # 1.02 over 40 seeds; the per-pixel band values are discrete, so fewer pixels would not do)
    assert panel.sum() > 200 and lamp.sum() > 200 and sky.sum() > 200, (panel.sum(), lamp.sum(), sky.sum())
    assert np.argmax(panel.any(0)) < np.argmax(lamp.any(0))  # the panel (x < 0.3) on the image's left
    fr = b.bands.astype(np.float64)
    for mask, value in ((panel, 0.5), (lamp, 2.0), (sky, 1.0)):
        v = fr[:, mask]  # [K, n] i.i.d. estimates of a flat spectrum
        se = v.std(1, ddof=1) / math.sqrt(v.shape[1])
        z = (v.mean(1) - value) / np.hypot(se, 1e-5 * value)
        assert np.all(np.abs(z) < Z_MAX), (value, np.round(z, 2))
    assert b.depth_m is not None and np.isfinite(b.depth_m[panel | lamp]).all() and np.isinf(b.depth_m[sky]).all()
    np.testing.assert_allclose(b.depth_m[panel | lamp], 3.0, rtol=1e-5)  # z = 0 plane, 3 m down the axis


# ---------------------------------------------------------------- the LLVM → scalar fallback


FALLBACK_SCRIPT = r"""
import json, sys
import numpy as np
from udc_render.scene import parse_scene
from udc_render.render import render_scene
out = {}
for path in ("rgb_matrix", "spectral"):
    doc = json.loads(sys.argv[1])
    doc["render"]["path"] = path
    b = render_scene(parse_scene(doc, "fallback.toml"), progress=False)
    fr = b.frame(b.bands).astype(np.float64)
    out[path] = {"variant": b.meta["variant"], "backend": b.meta["backend"], "reason": b.meta["backend_reason"],
                 "mean": fr.mean((1, 2)).tolist(), "se": (fr.std((1, 2), ddof=1) / np.sqrt(fr[0].size)).tolist()}
print(json.dumps(out))
"""


def test_forced_scalar_variants_render_correctly(udc, tmp_path):
    """UDC_RENDER_VARIANT=scalar (what a machine without a working LLVM gets): both paths render with
    scalar_* variants (the spectral one through the Python panel texture) and the white panel still
    gives the analytic band values. A subprocess, because the variant is chosen once per process."""
    doc = udc.monitor_doc(framing="fill", sensor_px=(32, 16), pitch_um=99.2,  # independent: i.i.d. pixels (z-scores)
                          render={"spp": 8, "margin_um": 0, "sampler": "independent"},
                          bands={"range_nm": [400, 700], "step_nm": 50})
    env = dict(os.environ, UDC_RENDER_VARIANT="scalar", UDC_RENDER_CACHE=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-c", FALLBACK_SCRIPT, json.dumps(doc)], env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    ref = white_reference(parse_scene(doc, "x.toml"))
    for path, mode in (("rgb_matrix", "rgb"), ("spectral", "spectral")):
        assert res[path]["variant"] == f"scalar_{mode}" and res[path]["backend"] == "scalar"
        assert res[path]["reason"] == "UDC_RENDER_VARIANT=scalar"
    np.testing.assert_allclose(res["rgb_matrix"]["mean"], ref, rtol=1e-6)  # exact path, as with llvm
    z = (np.array(res["spectral"]["mean"]) - ref) / np.hypot(res["spectral"]["se"], 1e-5 * ref)
    assert np.all(np.abs(z) < Z_MAX), z


def test_probe_rejects_a_bad_libllvm_without_killing_the_process(tmp_path, monkeypatch):
    import glob
    bad = sorted(glob.glob("/usr/lib/*/libLLVM-15*.so*"))
    if not bad:
        pytest.skip("no libLLVM-15 on this machine (the base image's broken library)")
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path))
    assert variants.probe(bad[0]) is False  # the subprocess aborts; we are still here
    cache = json.loads((tmp_path / "llvm_probe.json").read_text())
    assert [v for k, v in cache.items() if k.startswith(os.path.realpath(bad[0]) + "|")] == [False]

    def no_subprocess(*a, **k):
        raise AssertionError("the verdict should come from the cache")
    monkeypatch.setattr(variants.subprocess, "run", no_subprocess)
    assert variants.probe(bad[0]) is False
    assert variants.probe(str(tmp_path / "no_such_libLLVM.so")) is False  # a missing file: no subprocess either


def test_no_llvm_falls_back_to_scalar_with_a_warning(monkeypatch):
    monkeypatch.setattr(variants, "_CHOSEN", None)  # restored after the test
    monkeypatch.delenv("UDC_RENDER_VARIANT", raising=False)
    monkeypatch.setattr(variants, "candidates", lambda: [])
    with pytest.warns(variants.FallbackWarning, match="no libLLVM found"):
        backend = variants.choose_backend()
    assert backend.kind == "scalar" and backend.variant("spectral") == "scalar_spectral"
    assert variants.choose_backend() is backend  # chosen once per process

    monkeypatch.setattr(variants, "_CHOSEN", None)
    monkeypatch.setattr(variants, "candidates", lambda: ["/opt/libLLVM-15.so.1"])
    monkeypatch.setattr(variants, "probe", lambda lib: False)
    with pytest.warns(variants.FallbackWarning, match=r"tried libLLVM-15\.so\.1"):
        assert variants.choose_backend().kind == "scalar"

    monkeypatch.setattr(variants, "_CHOSEN", None)
    monkeypatch.setenv("UDC_RENDER_VARIANT", "scalar")
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # forced scalar is a choice, not a fallback: no warning
        assert variants.choose_backend().reason == "UDC_RENDER_VARIANT=scalar"


def test_candidates_put_drjit_libllvm_path_first(monkeypatch, tmp_path):
    lib = tmp_path / "libLLVM-99.so"
    lib.write_bytes(b"")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(lib))
    found = variants.candidates()
    assert found[0] == str(lib) and len(found) == len(set(found))


# ---------------------------------------------------------------- the analytic path and the samplers


@pytest.fixture(scope="module")
def analytic_and_mitsuba(udc, tmp_module):
    """The astronaut (fit: black bars and the dark room in the margin), 64 × 32 px: the exact area
    integral, and Mitsuba's rgb path at 1024 spp (ldsampler, 4 passes)."""
    s = scene_of(udc, tmp_module, image="builtin:astronaut", framing="fit", **SMALL, render={"spp": 4})
    exact = render_scene(s, progress=False)
    mc = render_scene(s.with_render(path="rgb_matrix", sampler="ldsampler", spp=1024, seed=3), progress=False)
    return s, exact, mc


def rel_err(a, b) -> float:
    a, b = a.bands.astype(np.float64), b.bands.astype(np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.fallback
def test_analytic_path_is_what_mitsuba_converges_to(analytic_and_mitsuba):
    """auto picks the exact area integral for the monitor through a pinhole; Mitsuba's high-spp render
    of the same scene differs from it by no more than Mitsuba's own noise (geometry, orientation,
    panel edges and the margin agree)."""
    _, exact, mc = analytic_and_mitsuba
    assert exact.meta["render_path"] == "analytic" and exact.meta["noise_rel"] == 0.0
    assert exact.bands.shape == mc.bands.shape and exact.margin_px == mc.margin_px
    assert mc.meta["noise_rel"] < 5e-3  # 2.1e-3 measured: a 64 × 32 pixel sees ~60 panel pixels
    assert rel_err(mc, exact) <= 2.0 * mc.meta["noise_rel"]


@pytest.mark.parametrize("sampler", ["independent", "stratified", "multijitter", "orthogonal", "ldsampler"])
def test_pass_noise_estimate_is_honest_for_every_sampler(analytic_and_mitsuba, sampler):
    """Each pass is an independent randomisation of the sampler (its own seed), so the spread between
    passes estimates the error of the mean even for correlated (stratified, low-discrepancy) samples:
    the true error against the exact image stays within a factor 1.6 of the estimate. Rounded sample
    counts are recorded as rendered (ldsampler 8 → 16 per pass)."""
    s, exact, _ = analytic_and_mitsuba
    b = render_scene(s.with_render(path="rgb_matrix", sampler=sampler, spp=16, seed=5), progress=False)
    assert b.meta["sampler"] == sampler and b.meta["spp"] == b.meta["passes"] * b.meta["spp_per_pass"] >= 16
    ratio = rel_err(b, exact) / b.meta["noise_rel"]
    assert 1 / 1.6 < ratio < 1.6, ratio


def test_analytic_path_is_refused_where_it_is_not_exact(udc, tmp_path):
    from udc_render.render import RenderError
    from udc_render.scene import SceneError
    with pytest.raises(SceneError, match="analytic"):
        parse_scene({**udc.monitor_doc(render={"path": "analytic"}), "lens": {"model": "thinlens"}},
                    str(tmp_path / "t.toml"))
    s = scene_of(udc, tmp_path, **SMALL)
    with pytest.raises(RenderError, match="analytic"):
        render_scene(replace(s, lens=replace(s.lens, model="thinlens")).with_render(path="analytic"), progress=False)
