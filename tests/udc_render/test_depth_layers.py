"""Depth and defocus in the synthesis: layer choice, the layered occlusion model, defocus of the monitor
against the thin-lens disc, the layers against the per-pixel reference, a thin-lens render counted once,
and the sun in frame at the default precision."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from udc_render.optics import displays as D
from udc_render.optics.layers import MAX_LAYERS, Compositor, DefocusGeometry, LayerError, choose_layers
from udc_render.pipeline import (
    SynthConfig,
    SynthError,
    capture_views,
    depth_layers,
    display_kernels,
    plan_kernels,
    sensor_for_scene,
    synthesize,
)
from udc_render.render import BandImage, render_scene
from udc_render.scene import Bands, load_scene
from udc_render.scene.geometry import camera_geometry, psf_lens, render_grid
from udc_render.sensor import SensorConfig
from udc_render.studies.layers_reference import edge_region, near_over_far, reference_electrons, with_focus
from udc_render.views import bright_pixels, layered_electrons

GEO = DefocusGeometry(aperture_um=3333.0, image_distance_um=6006.0, focus_m=3.0, pitch_um=1.55)
NOISELESS = SensorConfig(noise="none")


# ---------------------------------------------------------------- choose_layers


def test_a_flat_scene_is_one_layer_and_focus_is_exact():
    flat = np.full((40, 60), 3.0)
    layers = choose_layers(flat, GEO, 0.5, 101)
    assert layers.count == 1 and layers.labels is None and layers.depths_m == (3.0,)
    far = choose_layers(np.full((4, 4), 7.0), GEO, 0.5, 101)
    assert far.count == 1 and far.depths_m[0] == pytest.approx(7.0)


@pytest.mark.parametrize("tol", [0.25, 1.0, 3.0])
def test_every_pixel_is_within_the_tolerance_of_its_layer(tol):
    rng = np.random.default_rng(1)
    depth = np.concatenate([rng.uniform(0.5, 8.0, 3000), [np.inf, 3.0]]).reshape(-1, 2)
    layers = choose_layers(depth, GEO, tol, 10_001)
    beta = GEO.beta_px(depth)
    assert np.all(np.abs(beta - np.asarray(layers.beta_px)[layers.labels]) <= tol * (1 + 1e-9) + tol / 64)
    assert list(layers.beta_px) == sorted(layers.beta_px)  # far to near
    assert 0.0 in layers.beta_px and 3.0 in layers.depths_m  # the focus layer is exactly at focus
    span = beta.max() - beta.min()
    assert layers.count <= math.ceil(span / (2 * tol)) + 2  # close to the fewest intervals of width 2·tol


def test_refusals_are_one_line():
    depth = np.linspace(0.2, 50, 10_000).reshape(100, 100)
    for tol, window, words in [(0.0, 1001, "positive"), (0.01, 100_001, f"≤ {MAX_LAYERS}"), (2.0, 21, "kernel window")]:
        with pytest.raises(LayerError) as e:
            choose_layers(depth, GEO, tol, window)
        assert "\n" not in str(e.value) and words in str(e.value)
    for z in (0.0, -1.0, np.nan):
        with pytest.raises(LayerError, match="expected axial distances > 0 m") as e:
            choose_layers(np.array([[3.0, z]]), GEO, 0.5, 1001)
        assert "\n" not in str(e.value)
    huge = choose_layers(np.array([[1e30, np.inf]]), GEO, 0.5, 1001)  # beyond any lens' reach: one layer, finite
    assert huge.count == 1 and np.isfinite(huge.beta_px[0])
    with pytest.raises(SynthError, match="defocus_tolerance_px"):
        SynthConfig(defocus_tolerance_px=0.0)


# ---------------------------------------------------------------- the compositing model


def _box_blur(a, r):
    from scipy.ndimage import uniform_filter
    return uniform_filter(a, size=2 * r + 1, mode="nearest")


def test_a_uniform_surface_cut_into_two_layers_has_no_seam():
    """Uniform light through two adjacent layers with one kernel sums to itself (Ikoma's normalisation)."""
    x = np.zeros((1, 1, 41))
    near = (np.arange(41) < 20).astype(float)[None, None]
    far = 1.0 - near
    comp = Compositor()
    comp.add(_box_blur(near, 4), _box_blur(near, 4), _box_blur(near + far, 4))
    comp.add(_box_blur(far, 4), None, _box_blur(far, 4))
    np.testing.assert_allclose(comp.result(), 1.0 + x, atol=1e-12)


def test_an_in_focus_foreground_hides_a_blurred_background():
    """Background blurred behind a sharp foreground: nothing of it leaks onto the foreground."""
    near = np.zeros((1, 1, 60))
    near[..., :30] = 1.0
    far = 1.0 - near
    comp = Compositor()
    comp.add(near * 0.2, near, np.ones_like(near))  # sharp: its blur is itself
    comp.add(_box_blur(far * 1.0, 8), None, _box_blur(far, 8))
    y = comp.result()[0, 0]
    np.testing.assert_allclose(y[:30], 0.2, atol=1e-12)
    np.testing.assert_allclose(y[30:], 1.0, atol=1e-12)  # the hole behind the foreground is filled


# ---------------------------------------------------------------- defocus of the monitor


def _monitor(width=256, height=128, margin_um=80.0, image="pattern:checker"):
    s = load_scene("monitor")
    s = replace(s, sensor=replace(s.sensor, width_px=width, height_px=height),
                bands=Bands((400.0, 700.0), 100.0)).with_render(margin_um=margin_um)
    return replace(s, content=replace(s.content, image=image))


@pytest.fixture(scope="module")
def kernel_cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("kernels"))


def test_the_in_focus_monitor_is_todays_result_exactly(kernel_cache):
    s = _monitor()
    bi = render_scene(s, progress=False)
    cfg = SynthConfig(sensor=NOISELESS, kernel_cache=kernel_cache)
    layered = synthesize(bi, s, [D.preset("toled")], cfg)
    plain = synthesize(bi, s, [D.preset("toled")], replace(cfg, defocus_tolerance_px=None))
    assert layered.meta["depth_layers"]["blur_diameter_px"] == [0.0]
    np.testing.assert_array_equal(layered.gt, plain.gt)
    np.testing.assert_array_equal(layered.captures["toled"].clean_dn, plain.captures["toled"].clean_dn)


def _edge_width_px(profile):
    """10–90 % rise of a normalised edge profile, linearly interpolated (pixels)."""
    p = (profile - profile.min()) / (profile.max() - profile.min())
    i10 = np.interp(0.1, p, np.arange(p.size))
    i90 = np.interp(0.9, p, np.arange(p.size))
    return abs(i90 - i10)


def _disc_edge_width_px(diameter_px):
    """10–90 % width of the edge spread of a uniform disc (its area left of a line at x), convolved with the
    1-px pixel box, numerically."""
    r = diameter_px / 2
    x = np.linspace(-r - 2, r + 2, 40001)
    chord = 2 * np.sqrt(np.clip(r * r - x * x, 0, None))
    box = (np.abs(x[:, None] - x[None, ::200]) <= 0.5).astype(float)  # pixel box on a coarse grid
    lsf = box.T @ chord
    esf = np.cumsum(lsf) / lsf.sum()
    xs = x[::200]
    return np.interp(0.9, esf, xs) - np.interp(0.1, esf, xs)


def test_a_defocused_monitor_edge_spreads_like_the_thin_lens_disc(kernel_cache):
    s = with_focus(_monitor(image="pattern:slanted_edge:0", margin_um=110.0), 0.4)
    bi = render_scene(s, progress=False)
    res = synthesize(bi, s, [D.preset("glass")], SynthConfig(sensor=NOISELESS, kernel_cache=kernel_cache))
    lens, geom = psf_lens(s), camera_geometry(s)
    z = res.meta["depth_layers"]["depths_m"][0]
    b_px = lens.aperture_um * lens.image_distance_um * abs(1 / (z * 1e6) - 1 / (geom.focus_distance_m * 1e6)) / 1.55
    assert b_px > 25  # large defocus: the geometric disc dominates diffraction (~1.5 px)
    g = res.gt[1]
    row = g[g.shape[0] // 2]
    q = row.size // 4  # the chart's edge, not the panel's borders
    centre = q + int(np.argmax(np.abs(np.diff(row[q:-q]))))
    profile = row[centre - 30:centre + 31]
    assert _edge_width_px(profile) == pytest.approx(_disc_edge_width_px(b_px), rel=0.03)  # measured 1.0 %


# ---------------------------------------------------------------- layers against the per-pixel reference


@pytest.mark.slow
def test_layers_match_the_per_pixel_reference_at_the_edge(kernel_cache):
    s = load_scene("room")
    s = with_focus(replace(s, sensor=replace(s.sensor, width_px=64, height_px=48),
                           bands=Bands((400.0, 700.0), 100.0)).with_render(margin_um=62.0), 3.0)
    bi = near_over_far(s, 3.0, (0.8, 1.2))
    cfg = SynthConfig(sensor=NOISELESS, kernel_cache=kernel_cache)
    sensor = replace(sensor_for_scene(cfg.sensor, s), exposure_s=1e-3)
    grid, lens = render_grid(s), psf_lens(s)
    geo = DefocusGeometry(lens.aperture_um, lens.image_distance_um, 3.0, grid.pitch_um)
    cache = {}

    def kernels_at(z):
        if z not in cache:
            cache[z] = display_kernels(D.preset("glass"), s, grid, cfg, object_distance_m=z)
        return cache[z]

    ref = reference_electrons(bi, geo, kernels_at, sensor, step_px=0.05)
    ring = edge_region(bi.depth_m, 3.0, grid.margin_px, 8)
    for tol in (2.0, 0.5):
        layers = depth_layers(bi, s, grid, replace(cfg, defocus_tolerance_px=tol))

        def views(layer):
            return [_views_glass(kernels_at(layers.depths_m[layer]))]
        e = layered_electrons(bi, layers, views, sensor, cfg)["gt"][0]
        err = np.linalg.norm((e - ref)[:, ring]) / np.linalg.norm(ref[:, ring])
        assert err <= 1e-2 * tol, (tol, layers.count, err)  # stated: ≤ 1 % per pixel of tolerance (study capture)


def _views_glass(ks):
    from udc_render.views import View
    return View("gt", ks, None)


# ---------------------------------------------------------------- defocus counted once


def test_a_thin_lens_render_keeps_the_in_focus_kernels():
    s = load_scene("room")
    thin = replace(s, lens=replace(s.lens, model="thinlens"))
    bi = BandImage(np.zeros((3, 8, 8), np.float32), np.array([400.0, 500, 600, 700]), 1.55, 0,
                   np.full((8, 8), 1.0, np.float32))
    layers = depth_layers(bi, thin, render_grid(thin), SynthConfig())
    assert layers.count == 1 and layers.beta_px == (0.0,) and "thin-lens" in layers.reason
    deep = depth_layers(bi, s, replace(render_grid(s), margin_px=400), SynthConfig())
    assert deep.count == 1 and deep.beta_px[0] > 5  # the pinhole render: the wave optics add the defocus


# ---------------------------------------------------------------- the sun in frame


def _sun_room(scene, sun_ratio=1e9, seed=0):
    g = camera_geometry(scene)
    K = len(scene.bands.edges_nm) - 1
    rng = np.random.default_rng(seed)
    room = 0.02 * (0.5 + rng.random((g.height_px, g.width_px)))
    yy, xx = np.mgrid[0:g.height_px, 0:g.width_px]
    sun = (yy - g.height_px * 0.4) ** 2 + (xx - g.width_px * 0.6) ** 2 <= 3.0 ** 2
    radiance = np.where(sun, 0.02 * sun_ratio, room)
    bands = np.repeat(radiance[None], K, axis=0).astype(np.float32)
    return BandImage(bands, np.asarray(scene.bands.edges_nm, float), g.pitch_um, g.margin_px,
                     np.full(radiance.shape, g.focus_distance_m, np.float32))


def test_the_sun_in_frame_synthesises_at_the_default_precision(kernel_cache):
    s = load_scene("hdr")
    s = replace(s, sensor=replace(s.sensor, width_px=128, height_px=64),
                bands=Bands((400.0, 700.0), 100.0)).with_render(margin_um=62.0)
    bi = _sun_room(s)
    displays = [D.preset("toled"), D.preset("poled").with_distance(1.0)]
    cfg = SynthConfig(sensor=NOISELESS, kernel_cache=kernel_cache)
    res = synthesize(bi, s, displays, cfg)  # the default settings finish
    assert res.meta["bright_pixels"] > 0 and all(np.isfinite(c.clean_dn).all() for c in res.captures.values())

    sensor = replace(sensor_for_scene(cfg.sensor, s), exposure_s=res.meta["exposure_s"])
    layers = depth_layers(bi, s, render_grid(s), cfg)
    kernels = plan_kernels(s, displays, cfg)

    def electrons(c, bright):
        def views(_layer):
            return capture_views(kernels, displays, bi.edges_nm)
        return {k: v[0] for k, v in layered_electrons(bi, layers, views, sensor, c, bright).items()}

    bright = bright_pixels(bi, sensor)
    split = electrons(cfg, bright)
    exact = electrons(replace(cfg, precision="float64"), bright)
    unsplit = electrons(cfg, None)

    def error(c, name):
        """max |c − exact| / noise beyond the float32 output's own rounding: the split output is rounded twice
        (its FFT part, then its sum with the bright pixels' float64 blur), each time by at most ε32 · e / 2.
        That rounding alone can exceed a tenth of the shot noise √e above e ≈ (0.1 / ε32)² ≈ 7e11 e⁻ (the sun's
        pixels hold up to 8e12 e⁻, 5e8 full wells); whether it does shifts with the kernels' last bits (they
        change with the BLAS thread count), so the bound leaves that rounding out rather than depend on them."""
        noise = np.sqrt(sensor.read_noise_e ** 2 + exact[name])  # the pixel's own noise (read and shot), e⁻
        beyond = np.abs(c[name] - exact[name]) - np.finfo(np.float32).eps * np.abs(exact[name])
        return np.max(np.maximum(beyond, 0.0) / noise)

    for name in ("gt", "toled", "poled"):
        err = error(split, name)
        assert err < 0.1, (name, err)  # below a tenth of the noise floor (views.ROUNDOFF_TARGET)
        assert error(unsplit, name) > 10 * max(err, 0.01), name  # the split is what does it
