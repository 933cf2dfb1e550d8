"""Capture synthesis end to end: displays, synthesize(), the capture files and the synth/demo commands."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from psf import layouts
from udc_render.io.dng import read_dng_mosaic
from udc_render.metrics import psnr_db
from udc_render.optics import displays as D, gamma as G
from udc_render.pipeline import SynthConfig, SynthError, display_gamma, plan_kernels, sensor_for_scene, synthesize
from udc_render.render import render_scene
from udc_render.sensor import SensorConfig, demosaic_bilinear, mosaic_of, pack_rggb

PRESETS = [D.preset(n) for n in ("glass", "toled", "poled")]
NOISELESS = SynthConfig(sensor=SensorConfig(noise="none"))


def _scene(udc, path, image="pattern:white", bands=None, **kw):
    doc = udc.monitor_doc(image=image, bands=bands or {"range_nm": [400, 700], "step_nm": 100}, **kw)
    return udc.write_scene(path, doc)


@pytest.fixture(scope="module")
def white(udc, tmp_path_factory, render_cache):
    """A tiny monitor filling the frame with full white; 3 bands of 100 nm; margin 16 px of 24.8 µm."""
    scene = _scene(udc, tmp_path_factory.mktemp("white") / "white.toml")
    return scene, render_scene(scene, progress=False)


def _centre(a, frac=0.25):
    h, w = a.shape[-2:]
    return a[..., int(h * frac):int(h * (1 - frac)), int(w * frac):int(w * (1 - frac))]


# ---------------------------------------------------------------- displays


def test_presets_reproduce_the_papers_gammas():
    """The fitted T(λ) constants give all four γ (R, Gr, Gb, B) of the paper's, on the default rig's gains with the
    calibration square's far field (calibration.fit_gains): T-OLED 0.97 within 0.2 % (one flat T for four
    channels: measured R −0.15 %, B +0.14 %), P-OLED 0.34/0.34/0.34/0.20 within 1e-5 (three parameters fitted to
    three values: measured 3.2e-6); refitting returns the stored constants within 3e-5 (measured 4.9e-6)."""
    from psf import layouts
    from udc_render.calibration.fit_gains import FIT_EDGES_NM as edges, fit_gains
    from udc_render.sensor import rgb_to_rggb
    g = {name: fit_gains(lay) for name, lay in (("glass", None), ("toled", layouts.toled()),
                                                  ("poled", layouts.poled()))}
    w = G.white_weights(edges, "Nikon 5100 (NPL)")
    for name, tol in (("toled", 0.002), ("poled", 1e-5)):
        rggb = np.array(rgb_to_rggb(G.channel_gamma(w, D.preset(name), g[name], g["glass"], edges)))
        paper = np.array(rgb_to_rggb(D.PAPER_GAMMA[name]))
        assert np.all(np.abs(rggb / paper - 1) < tol), (name, rggb)
    assert D.fit_toled_transmission(g["toled"], g["glass"], edges) == pytest.approx(D.TOLED_T, rel=3e-5)
    fit = D.fit_poled_transmission(g["poled"], g["glass"], edges)
    assert fit == pytest.approx((D.POLED_SCALE, D.POLED_EDGE_NM, D.POLED_CATHODE_NM), rel=3e-5)
    # the far field the calibration square collects: the P-OLED's orders past the window, 0.1-2.4 % of its gain
    extra = fit_gains(layouts.poled()) / fit_gains(layouts.poled(), far_field=False) - 1
    assert 0.0005 < extra.min() and extra.max() < 0.03, extra


@pytest.mark.slow
def test_virtual_calibration_measures_the_papers_gamma_through_the_poled(tmp_path):
    """calibration.gamma's white-square protocol on the default rig (the square and region calibration.fit_gains
    assumes) gives the P-OLED's γ: truth within 0.3 % of the paper's, the noisy regression within 1.5 %."""
    from udc_render.calibration.fit_gains import FIT_REGION_PX, FIT_SQUARE_PX
    from udc_render.calibration.gamma import calibrate_gamma
    from udc_render.calibration.rig import Rig
    from udc_render.sensor import rgb_to_rggb
    r = calibrate_gamma(Rig(D.preset("poled"), out=tmp_path))
    assert (r["square_px"], r["region_px"]) == (FIT_SQUARE_PX, FIT_REGION_PX)
    paper = np.array(rgb_to_rggb(D.PAPER_GAMMA["poled"]))
    assert np.all(np.abs(r["truth"] / paper - 1) < 0.003), r["truth"]
    assert np.all(np.abs(r["gamma"] / paper - 1) < 0.015), r["gamma"]


def test_thin_cathode_transmits_less_towards_the_red():
    """Tinkham's formula: T = 1 at d = 0, falls with λ and with d, and T(λ) = 1/(1 + (π d λ/(n λp²))²)."""
    wl = np.array([450.0, 550.0, 650.0])
    assert D.thin_metal_transmission(wl, 0.0).tolist() == [1.0] * 3
    t = D.thin_metal_transmission(wl, 11.0)
    assert np.all(np.diff(t) < 0) and np.all(D.thin_metal_transmission(wl, 20.0) < t)
    x = np.pi * 11.0 * 550.0 / (D.STACK_INDEX * D.SILVER_PLASMA_WAVELENGTH_NM ** 2)
    assert t[1] == pytest.approx(1 / (1 + x ** 2), rel=1e-12)


def test_poled_transmission_is_lower_in_the_blue_and_toled_flat():
    wl = np.array([420.0, 450.0, 520.0, 640.0])
    tp, tt = D.preset("poled").transmission(wl), D.preset("toled").transmission(wl)
    assert tp[0] < tp[1] < tp[2] and tp[0] < 0.1 * tp[2]  # the polyimide's blue edge
    assert 0.8 < tp[3] / tp[2] < 1.0  # the cathode's slow fall towards the red
    assert np.all(tt == D.TOLED_T)
    assert D.preset("glass").transmission(wl).tolist() == [1.0] * 4


def test_display_file_round_trip(tmp_path):
    (tmp_path / "t.csv").write_text("wavelength_nm,t\n400,0.1\n700,0.4\n")
    (tmp_path / "d.toml").write_text(
        '[display]\nname = "mine"\ngain = 4\ndistance_mm = 0.5\n'
        '[display.layout]\ntype = "toled"\npitch_um = 50\nopen_fraction = 0.3\n'
        '[display.transmission]\ntype = "csv"\nfile = "t.csv"\n')
    d = D.load_display(str(tmp_path / "d.toml"))
    assert (d.name, d.gain, d.distance_mm, d.layout.pitch_x_um) == ("mine", 4.0, 0.5, 50.0)
    assert d.transmission([400, 550, 700]).tolist() == pytest.approx([0.1, 0.25, 0.4])
    assert d.transmission.band_means([400, 700])[0] == pytest.approx(0.25)


@pytest.mark.parametrize("body, needle", [
    ('[display]\nlayout = {type = "hex"}\n', "display.layout.type = 'hex'"),
    ('[display]\nlayout = {type = "toled", pitch = 3}\n', "display.layout.pitch = 3"),
    ('[display]\nlayout = {type = "toled"}\ngain = -1\n', "display.gain = -1"),
    ('[display]\nlayout = {type = "toled", open_fraction = 0.95}\n', "open_fraction"),
    ('[display]\nlayout = {type = "toled"}\ntransmission = {type = "flat", value = 2}\n',
     "display.transmission.value = 2"),
    ('[display]\nlayout = {type = "toled"}\ntransmission = {type = "csv", file = "nope.csv"}\n', "nope.csv"),
    ('[display]\nlayout = {type = "micrograph", file = "nope.png"}\n', "display.layout.file = 'nope.png'"),
    ('[screen]\n', "screen"),
])
def test_bad_display_files_give_one_line_naming_file_and_key(tmp_path, capsys, body, needle):
    from udc_render.cli import main
    f = tmp_path / "bad.toml"
    f.write_text(body)
    assert main(["synth", "monitor", "--display", str(f), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(f) in err and needle in err, err


# ---------------------------------------------------------------- synthesize()


def test_levels_follow_gamma_and_glass_is_the_ground_truth(white):
    """Noise off, a white field: the glass capture equals the ground truth's mosaic (same optics, same
    exposure) and, without the far field, each display's level is γ × glass, γ from the display's kernels
    (their window) and T(λ); the far field adds its veil on top, at most its share of the power over the
    window's (optics.far_field)."""
    scene, bi = white
    off = replace(NOISELESS, far_field_threshold=None)
    res, res_on = synthesize(bi, scene, PRESETS, off), synthesize(bi, scene, PRESETS, NOISELESS)
    glass = res.captures["glass"].clean_dn / 65535
    assert np.allclose(glass, np.clip(mosaic_of(res.gt), 0, 1), rtol=2e-5, atol=2e-5)
    gl = pack_rggb(_centre(res.captures["glass"].clean_dn))
    for name in ("toled", "poled"):
        d = D.preset(name)
        as_file = D.Display(name, d.layout, d.transmission, d.gain, source="file")  # analytic γ, not the paper's
        kernels = plan_kernels(scene, [as_file], NOISELESS)
        gamma, _ = display_gamma(as_file, bi, kernels, sensor_for_scene(NOISELESS.sensor, scene))
        lv = pack_rggb(_centre(res.captures[name].clean_dn))
        ratio = lv.reshape(4, -1).mean(1) / gl.reshape(4, -1).mean(1)
        assert ratio[[0, 1, 3]] == pytest.approx(np.array(gamma), rel=0.01), name
        veil = pack_rggb(_centre(res_on.captures[name].clean_dn)).reshape(4, -1).mean(1) / lv.reshape(4, -1).mean(1)
        far = kernels.far[name]
        assert np.all(veil > 1) and np.all(veil - 1 <= (far.added / (1 - far.lost)).max()), (name, veil)


def test_per_channel_form_uses_the_papers_gamma(white):
    scene, bi = white
    cfg = SynthConfig(form="per_channel", sensor=SensorConfig(noise="none"))
    res = synthesize(bi, scene, PRESETS, cfg)
    gl = pack_rggb(_centre(res.captures["glass"].clean_dn)).reshape(4, -1).mean(1)
    for name in ("toled", "poled"):
        lv = pack_rggb(_centre(res.captures[name].clean_dn)).reshape(4, -1).mean(1)
        g = D.PAPER_GAMMA[name]
        assert lv / gl == pytest.approx([g[0], g[1], g[1], g[2]], rel=2e-6), name  # measured 2.2e-7 (float32)
        assert res.display_meta[name]["gamma_rgb"] == list(g)


def test_zero_light_is_black_and_finite(udc, tmp_path, render_cache):
    scene = _scene(udc, tmp_path / "black.toml", image="pattern:orientation")
    bi = render_scene(scene, progress=False)
    dark = type(bi)(np.zeros_like(bi.bands), bi.edges_nm, bi.pitch_um, bi.margin_px, None, bi.meta)
    res = synthesize(dark, scene, PRESETS, SynthConfig(sensor=SensorConfig(noise="poisson", read_noise_e=0)))
    for cap in res.captures.values():
        assert cap.mosaic_dn.max() == 0
    assert np.all(res.gt == 0)


def test_saturation_and_huge_gain_clip_at_the_white_level(white):
    scene, bi = white
    cfg = SynthConfig(exposure_s=10.0)  # ~300× the auto exposure
    res = synthesize(bi, scene, [D.preset("glass"), D.Display("hot", D.layouts.toled(), gain=1e6)], cfg)
    for cap in res.captures.values():
        assert np.all(_centre(cap.mosaic_dn) == 65535)
    assert np.all(np.isfinite(res.gt)) and res.gt.max() > 100  # the ground truth is not clipped


def test_nan_band_image_is_rejected(white):
    from udc_render.optics import OpticsError
    scene, bi = white
    bands = bi.bands.copy()
    bands[1, 5, 7] = np.nan
    bad = type(bi)(bands, bi.edges_nm, bi.pitch_um, bi.margin_px, None, bi.meta)
    with pytest.raises(OpticsError, match="NaN"):
        synthesize(bad, scene, PRESETS[:2], NOISELESS)


def test_kernel_larger_than_the_frame(udc, tmp_path, render_cache):
    """A 16 × 8 px frame with a 33-px kernel: still exact linear convolution (no wrap)."""
    scene = _scene(udc, tmp_path / "small.toml", sensor_px=(16, 8))
    res = synthesize(render_scene(scene, progress=False), scene, PRESETS, NOISELESS)
    assert res.meta["kernel_size_px"] > 16
    assert all(np.all(np.isfinite(c.clean_dn)) for c in res.captures.values())


def test_duplicate_display_names_rejected(white):
    scene, bi = white
    with pytest.raises(SynthError, match="distinct"):
        synthesize(bi, scene, [D.preset("toled"), D.preset("toled")], NOISELESS)


def test_banding_period_in_the_capture(udc, tmp_path, render_cache):
    """A flat field through a 60 µm T-OLED at d = 2 mm: the noise-free capture's column profile (G sites
    of both rows, so every column) has its spectral peaks at harmonics of d / (z_i p) (period
    z_i · p / d); at d = 0 the profile is flat to round-off above half the banding frequency (below it lies
    the far field's veil, optics.far_field: smooth over the frame, brighter where more panel surrounds a pixel)."""
    scene = _scene(udc, tmp_path / "band.toml", sensor_px=(512, 16), resolution_px=(1920, 1080))
    bi = render_scene(scene, progress=False)
    from udc_render.scene.geometry import psf_lens
    period_px = psf_lens(scene).image_distance_um * 60.0 / 2000.0 / bi.pitch_um
    spectra = {}
    for d_mm in (0.0, 2.0):
        fine = replace(D.preset("toled"), layout=layouts.toled(pitch_um=60.0))  # ~4 periods in the frame
        res = synthesize(bi, scene, [fine.with_distance(d_mm)], NOISELESS)
        m = res.captures["toled"].clean_dn.astype(np.float64)
        g = np.where(np.arange(m.shape[1]) % 2 == 1, m[0::2].mean(0), m[1::2].mean(0))  # Gr odd, Gb even columns
        prof = g[40:-40] / g[40:-40].mean() - 1  # away from the monitor's edges
        spectra[d_mm] = np.abs(np.fft.rfft(prof * np.hanning(prof.size)))
    f = np.fft.rfftfreq(prof.size)
    fast = f > 0.5 / period_px  # above the veil
    spec = np.where(fast, spectra[2.0], 0.0)
    top = np.argsort(spec)[-2:]  # the two strongest lines
    for i in top:
        harmonic = f[i] * period_px
        assert abs(harmonic - round(harmonic)) * (1 / period_px) < 2 / prof.size and round(harmonic) in (1, 2), f[i]
    assert spectra[0.0][fast].max() < 0.02 * spec.max()


# ---------------------------------------------------------------- files and commands


@pytest.mark.fallback
def test_synth_files_round_trip_and_are_byte_identical(udc, tmp_path, render_cache):
    import OpenEXR

    from udc_render.cli import main
    scene_file = tmp_path / "img.toml"
    _scene(udc, scene_file, image="builtin:camera", framing="fit")
    outs = [tmp_path / "a", tmp_path / "b"]
    for o in outs:
        # the default profile (d > 0, defect pixels); 2 field phases per axis keep the kernels cheap
        assert main(["synth", str(scene_file), "--display", "toled,poled", "--field-phases", "2", "--out", str(o),
                     "--quiet"]) == 0
    a, b = outs
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert {"gt.exr", "gt_preview.png", "toled/raw.dng", "poled/capture.json", "glass/preview.png",
            "side_by_side.png", "summary.md", "synth.json"} <= {str(p) for p in files}
    assert not {"toled/raw.png", "toled/packed.tiff"} & {str(p) for p in files}
    for p in files:
        if p.name != "side_by_side.png":  # matplotlib embeds its version; the other writers do not
            assert (a / p).read_bytes() == (b / p).read_bytes(), p
    raw = read_dng_mosaic(a / "toled/raw.dng")
    assert raw.mosaic_dn.dtype == np.uint16 and raw.mosaic_dn.shape == (64, 128)
    assert (raw.black_level_dn, raw.white_level_dn) == (0, 65535)
    meta = json.loads((a / "toled/capture.json").read_text())
    assert meta["display"]["name"] == "toled" and meta["sensor"]["gain"] == 6.0 and "rng_state_before" in meta
    with OpenEXR.File(str(a / "gt.exr")) as f:
        assert f.channels()["RGB"].pixels.shape == (64, 128, 3)  # R, G, B channels (grouped by OpenEXR)
    summary = json.loads((a / "summary.json").read_text())
    assert summary["views"]["glass"]["psnr_db_vs_gt"] > summary["views"]["toled"]["psnr_db_vs_gt"] \
        > summary["views"]["poled"]["psnr_db_vs_gt"]


@pytest.mark.slow
def test_demo_runs_and_reports(tmp_path, capsys, render_cache):
    """The built-in demo end to end (slow: under the default physical profile, d > 0, the field-dependent
    511-px kernels of the default rig take about 8 min on a cold cache; tests/udc_render/test_profiles.py
    runs the demo command on a tiny scene)."""
    from udc_render.cli import main
    assert main(["demo", "--out", str(tmp_path), "--sensor-px", "64,32", "--quiet"]) == 0
    out = capsys.readouterr().out
    for name in ("glass", "toled", "poled"):
        assert name in out and (tmp_path / name / "raw.dng").is_file()
    assert (tmp_path / "side_by_side.png").stat().st_size > 1000


def test_demosaic_bilinear_is_exact_on_a_linear_ramp():
    y, x = np.mgrid[0:16, 0:20].astype(float)
    rgb = np.stack([x + y, 2 * x, 3 * y + 1])
    out = demosaic_bilinear(mosaic_of(rgb))
    assert np.allclose(out[:, 2:-2, 2:-2], rgb[:, 2:-2, 2:-2])
    assert psnr_db(rgb, rgb) == math.inf


@pytest.mark.slow
def test_study_capture_quick_writes_table_and_errors_order(tmp_path):
    """`udc-render study capture --quick` (minutes: it computes every kernel with the cache off)."""
    from udc_render.studies.capture_knobs import run_study
    rows = run_study(tmp_path, quick=True, progress=False)
    assert {"study_capture.csv", "study_capture.md", "study_capture.png"} <= {p.name for p in tmp_path.iterdir()}
    by = {(r["study"], r["setting"]): r["rel_error"] for r in rows}
    assert by[("precision", "float64")] == 0.0 and by[("precision", "float32")] < 1e-5
    assert all(np.isfinite(r["rel_error"]) and r["kernel_s"] >= 0 for r in rows)
    layers = [r["rel_error"] for r in rows if r["study"] == "layers"]  # tolerances falling, then defocus off
    assert layers[0] > layers[1] and layers[-1] > 10 * layers[1]
    bright = {(r["display"], r["setting"]): r["rel_error"] for r in rows if r["study"] == "bright"}
    assert all(v < 0.1 for (_, setting), v in bright.items() if "sun apart" in setting)


def test_the_scene_is_the_one_source_of_the_optics(tmp_path):
    """A scene at f/2.8 with a 4 mm lens gets f/2.8 kernels (aperture f/N), f/2.8 irradiance (electrons
    ∝ 1/N²) and its own focal length in the cos⁴ fall-off; a sensor file may not set them."""
    from dataclasses import replace

    from udc_render.scene import load_scene
    from udc_render.scene.geometry import psf_lens
    from udc_render.sensor import SensorError, band_electron_weights
    base = load_scene("monitor")
    scene = replace(base, lens=replace(base.lens, f_number=2.8, focal_length_mm=4.0))
    lens = psf_lens(scene)
    assert lens.focal_length_um == 4000.0 and lens.aperture_um == pytest.approx(4000.0 / 2.8)
    s28, s18 = sensor_for_scene(SensorConfig(), scene), sensor_for_scene(SensorConfig(), base)
    assert (s28.f_number, s28.focal_length_um, s28.pitch_um) == (2.8, 4000.0, base.sensor.pitch_um)
    edges = np.array([500.0, 510.0])
    ratio = band_electron_weights(edges, s18) / band_electron_weights(edges, s28)
    np.testing.assert_allclose(ratio, (2.8 / 1.8) ** 2, rtol=1e-12)
    cfg = tmp_path / "sensor.toml"
    cfg.write_text("f_number = 2.8\n")
    with pytest.raises(SensorError, match="comes from the scene file"):
        SensorConfig.from_toml(cfg)


def test_deps_known_gamma_is_the_gamma_that_made_the_capture(udc, tmp_path, render_cache):
    """One γ (optics.gamma): restore.known reads it back from a synth folder, and it equals the level
    ratio display / glass of a noise-free white field (spectral form), and the recorded paper γ
    (per-channel form). At d = 0 (DeP's kernels and γ assume the display at the lens), without the far field
    (its veil over a white field comes on top of γ: test_levels_follow_gamma_and_glass_is_the_ground_truth) and
    without stray light (the P-OLED's default haze moves 1.5 % of its light, about 1 % off a white field's centre)."""
    from restore.data import Pair
    from restore.known import known_gamma_rggb
    from udc_render.cli import main
    scene = tmp_path / "white.toml"
    _scene(udc, scene)
    for form in ("spectral", "per_channel"):
        out = tmp_path / form
        assert main(["synth", str(scene), "--display", "toled,poled", "--noise-model", "none", "--form", form,
                     "--distance-mm", "0", "--far-field-threshold", "off", "--stray-light", "off", "--quiet",
                     "--out", str(out)]) == 0
        mosaic = read_dng_mosaic(out / "glass" / "raw.dng").mosaic_dn.astype(float)
        glass = pack_rggb(_centre(mosaic)).reshape(4, -1).mean(1)
        for name in ("toled", "poled"):
            mosaic = read_dng_mosaic(out / name / "raw.dng").mosaic_dn.astype(float)
            level = pack_rggb(_centre(mosaic)).reshape(4, -1).mean(1)
            known = known_gamma_rggb(Pair(0, "test", out, name, "white"))
            assert level / glass == pytest.approx(known, rel=3e-3), (form, name)  # measured ≤ 0.14 %
            if form == "per_channel":
                g = D.PAPER_GAMMA[name]
                assert list(known) == [g[0], g[1], g[1], g[2]]
