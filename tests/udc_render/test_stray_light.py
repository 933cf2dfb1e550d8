"""Stray light (udc_render.optics.stray): each effect off leaves the capture bit-identical, each on adds or
moves the light its parameter says, the spreads hold their norm, bad knobs get one line, and the records
reach synth.json and capture.json."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from udc_render.content.spectra import band_means, illuminant, luminance_cd_m2, scaled_to_luminance
from udc_render.optics import displays as D
from udc_render.optics.stray import (
    ON_VALUES,
    Spread,
    StrayContext,
    StrayLight,
    StrayLightError,
    apply_view,
    convolve,
    spread as S,
    uniform_electrons,
)
from udc_render.pipeline import SynthConfig, SynthError, plan_kernels, synthesize
from udc_render.profiles import resolve_profile
from udc_render.render import render_scene
from udc_render.sensor import SensorConfig, electrons_rgb

OFF = StrayLight.off()
EDGES = np.array([400.0, 500.0, 600.0, 700.0])


@pytest.fixture(scope="module")
def rig(udc, tmp_path_factory, render_cache):
    """A tiny monitor (fit framing: the panel and a black surround), 3 bands, glass/T-OLED/P-OLED at d = 0."""
    doc = udc.monitor_doc(image="pattern:dead_leaves_colour:101", framing="fit",
                          bands={"range_nm": [400, 700], "step_nm": 100})
    scene = udc.write_scene(tmp_path_factory.mktemp("stray") / "stray.toml", doc)
    displays = [D.preset(n) for n in ("glass", "toled", "poled")]
    cfg = SynthConfig(sensor=SensorConfig(noise="none"), stray_light=OFF)
    return scene, render_scene(scene, progress=False), displays, cfg, plan_kernels(scene, displays, cfg)


def _run(rig, stray):
    scene, image, displays, cfg, kernels = rig
    return synthesize(image, scene, displays, replace(cfg, stray_light=stray), kernels=kernels)


def _ctx(shape=(64, 128), cos4=False, monitor=True, pitch_um=24.8):
    s = SensorConfig(noise="none", pitch_um=pitch_um, focal_length_um=6000.0, exposure_s=0.03, cos4_falloff=cos4)
    return StrayContext(EDGES, s, monitor, np.ones(3))


# ---------------------------------------------------------------- off: bit-identical


def test_all_off_is_the_path_without_stray_light(rig, monkeypatch):
    """StrayLight.off() returns the views' electrons untouched: the same captures, bit for bit, as a pipeline
    whose stray-light step is removed."""
    import udc_render.pipeline as P
    ref = _run(rig, OFF)
    monkeypatch.setattr(P, "synthesis_stray_light", lambda s, e, *a, **k: (e, {"settings": s.describe()}))
    bare = _run(rig, OFF)
    assert np.array_equal(ref.gt, bare.gt)
    for name in ref.captures:
        assert np.array_equal(ref.captures[name].mosaic_dn, bare.captures[name].mosaic_dn)
        assert np.array_equal(ref.captures[name].electrons, bare.captures[name].electrons)
    assert ref.meta["stray_light"]["applied"] is False


OFF_FORMS = {"room_illuminance_lux": (None, 0.0), "lens_reflectance": (0.0, 0), "lens_glare": (0.0, 0),
             "haze": (None, {}, {"poled": 0.0}), "display_luminance_cd_m2": (None, 0.0)}
RECORD_KEY = {"room_illuminance_lux": "room", "lens_reflectance": "ghost", "lens_glare": "glare", "haze": "haze",
              "display_luminance_cd_m2": "emission"}


def _same(a, b) -> bool:
    return np.array_equal(a.gt, b.gt) and all(np.array_equal(a.captures[n].electrons, b.captures[n].electrons)
                                              for n in a.captures)


@pytest.mark.parametrize("knob", sorted(OFF_FORMS))
def test_each_effect_switched_off_is_bit_identical(rig, knob):
    """dataclasses.replace(…, knob=0 or None) switches the effect off: alone, bit-identical to no stray light
    at all; beside every other effect at its on-value, each off form gives the same captures and no record."""
    none = _run(rig, OFF)
    all_on = replace(StrayLight(), **ON_VALUES)
    runs = []
    for off in OFF_FORMS[knob]:
        alone = replace(OFF, **{knob: off})
        assert alone.is_off() and _same(_run(rig, alone), none)
        runs.append(_run(rig, replace(all_on, **{knob: off})))
    assert all(_same(r, runs[0]) for r in runs[1:])
    assert not _same(runs[0], _run(rig, all_on))
    for meta in [runs[0].meta["gt_optics"]] + [runs[0].display_meta[n]["optics"] for n in ("toled", "poled")]:
        assert RECORD_KEY[knob] not in meta["stray_light"]


def test_haze_of_one_display_leaves_the_others_alone(rig):
    """The P-OLED's haze changes its capture only: glass, T-OLED and the ground truth are bit-identical."""
    a, b = _run(rig, replace(OFF, haze={"poled": 0.02})), _run(rig, OFF)
    assert np.array_equal(a.gt, b.gt)
    for name in ("glass", "toled"):
        assert np.array_equal(a.captures[name].electrons, b.captures[name].electrons)
    assert not np.array_equal(a.captures["poled"].electrons, b.captures["poled"].electrons)


# ---------------------------------------------------------------- on: the light each adds


def test_room_pedestal_is_r_e_over_pi_through_every_view(rig):
    """Room light on the screen adds, in the ground truth and each capture, the electrons the sensor's
    radiometry gives a uniform radiance of luminance R E / π (× the view's band gains, with cos⁴)."""
    from udc_render.pipeline import sensor_for_scene
    from udc_render.sensor import mosaic_of
    stray = replace(OFF, room_illuminance_lux=500.0, screen_reflectance=0.05, room_illuminant="D65")
    on, off = _run(rig, stray), _run(rig, OFF)
    scene, image, displays, cfg, kernels = rig
    lum = 0.05 * 500.0 / math.pi
    spectrum = scaled_to_luminance(illuminant("D65"), lum)
    assert float(luminance_cd_m2(spectrum)) == pytest.approx(lum, rel=1e-12)
    sensor = replace(sensor_for_scene(cfg.sensor, scene), exposure_s=on.meta["exposure_s"])
    h, w = on.gt.shape[1:]
    for view, gains in (("glass", on.meta["gt_optics"]["gains"]), ("poled", on.display_meta["poled"]["optics_gains"])):
        L = np.asarray(gains)[:, None, None] * band_means(spectrum, image.edges_nm)[:, None, None] * np.ones((1, h, w))
        expected = mosaic_of(electrons_rgb(L, image.edges_nm, sensor))
        added = on.captures[view].electrons - off.captures[view].electrons
        assert np.allclose(added, expected, rtol=1e-9, atol=0), view
    assert on.meta["gt_optics"]["stray_light"]["room"]["screen_luminance_cd_m2"] == pytest.approx(lum)


def test_room_light_is_not_added_to_a_scene_without_a_monitor():
    """3D scenes render their own room: the screen's reflection applies to monitor scenes only."""
    e = np.ones((3, 8, 8))
    out, rec = apply_view(replace(OFF, room_illuminance_lux=500.0), e, "glass", True, np.ones(3), _ctx(monitor=False))
    assert np.array_equal(out, e) and rec["room"].startswith("not applied")


def test_haze_moves_its_fraction_and_leaves_a_point_its_core():
    """A point source: the haze moves exactly h of its light (the point keeps 1 − h: the tail starts beyond
    2.5°), and the share landing on the frame lies between the tail's share within the frame's inner and
    outer radius."""
    e = np.zeros((3, 256, 512))
    e[:, 128, 256] = 1000.0
    ctx = _ctx((256, 512), pitch_um=6.2)
    out, rec = apply_view(replace(OFF, haze={"poled": 0.03}), e, "poled", False, np.ones(3), ctx)
    assert out[0, 128, 256] == pytest.approx(0.97 * 1000.0, rel=1e-12)
    h = rec["haze"]
    assert h["moved_share"] == 0.03
    assert out.sum() == pytest.approx(e.sum() * (1 - 0.03 + 0.03 * h["landed_share_of_moved"]), rel=1e-9)
    tail = Spread("tail", 6000.0, inner_deg=2.5)
    assert tail.share_within(128 * 6.2) < h["landed_share_of_moved"] < tail.share_within(math.hypot(128, 256) * 6.2)


def test_ghost_adds_the_reflectance_product_where_its_disc_fits():
    """A uniform field: the ghost adds R_lens · R_under of it wherever its disc lies inside the frame."""
    e = np.full((3, 256, 256), 100.0)
    stray = replace(OFF, lens_reflectance=0.01, underside_reflectance={"glass": 0.08, "toled": 0.3},
                    ghost_blur_um=200.0)
    out, rec = apply_view(stray, e, "toled", False, np.ones(3), _ctx((256, 256), pitch_um=6.2))
    assert rec["ghost"]["reflectance_product"] == pytest.approx(0.003)
    assert out[:, 128, 128] == pytest.approx(100.0 * 1.003, rel=1e-9)
    out_g, rec_g = apply_view(stray, e, "poled", False, np.ones(3), _ctx((256, 256), pitch_um=6.2))
    assert rec_g["ghost"]["reflectance_product"] == pytest.approx(0.0008)  # no value of its own: the glass's


def test_glare_is_in_the_ground_truth_and_moves_its_fraction(rig):
    """The lens's veiling glare acts on every view, the ground truth too (same lens, l.235), moving v of it."""
    on, off = _run(rig, replace(OFF, lens_glare=0.02)), _run(rig, OFF)
    for rec, before, after in ((on.meta["gt_optics"], off.gt.sum(), on.gt.sum()),
                               (on.display_meta["toled"]["optics"], off.captures["toled"].electrons.sum(), None)):
        g = rec["stray_light"]["glare"]
        assert g["moved_share"] == 0.02 and 0 < g["landed_share_of_moved"] < 1
        if after is not None:
            assert after / before == pytest.approx(1 - 0.02 * (1 - g["landed_share_of_moved"]), rel=1e-6)


def test_display_light_reaches_the_displays_not_the_glass(rig):
    """A driven display adds its light (luminance L_d through the bare lens) to its own capture only."""
    on, off = _run(rig, replace(OFF, display_luminance_cd_m2=5.0)), _run(rig, OFF)
    assert np.array_equal(on.gt, off.gt)
    assert np.array_equal(on.captures["glass"].electrons, off.captures["glass"].electrons)
    rec = on.display_meta["toled"]["optics"]["stray_light"]["emission"]
    d = on.captures["toled"].electrons - off.captures["toled"].electrons
    assert d.min() > 0 and rec["luminance_cd_m2"] == 5.0
    e = np.zeros((3, 8, 8))
    ctx = _ctx((8, 8))
    out, _ = apply_view(replace(OFF, display_luminance_cd_m2=5.0), e, "toled", False, np.ones(3), ctx)
    assert np.allclose(out, uniform_electrons(5.0, "D65", np.ones(3), (8, 8), ctx))


# ---------------------------------------------------------------- the spreads


def _tail_share_closed_form(inner_deg: float, hi_rad: float) -> float:
    """∫ sinθ / θ² dθ = Ci(θ) − sinθ / θ: the share of I = c θ⁻² within θ₁ ≤ θ ≤ hi, c from θ₁ to 90°."""
    from scipy.special import sici

    def antiderivative(t: float) -> float:
        return sici(t)[1] - math.sin(t) / t
    lo = math.radians(inner_deg)
    return (antiderivative(hi_rad) - antiderivative(lo)) / (antiderivative(math.pi / 2) - antiderivative(lo))


@pytest.mark.parametrize("inner_deg", [1.0, 2.5])
def test_tail_share_is_the_sine_integrals_and_its_density_fills_the_plane(inner_deg):
    """share_within against Ci(θ) − sinθ/θ, and c against its closed form 1 / (2π [·] from θ₁ to 90°) (measured
    ≤ 9e-11 relative at 1° and 2.5°: the trapezoid's error; asserted 3e-10); the density ρ(r) per µm², integrated
    over the sensor plane in r (Gauss-Legendre in ln r, not the θ grid), holds the whole hemisphere's light
    (measured 1 − 9e-11)."""
    from scipy.special import sici
    tail = Spread("tail", 6000.0, inner_deg=inner_deg)
    lo = math.radians(inner_deg)
    norm = 2 * math.pi * (sici(math.pi / 2)[1] - 2 / math.pi - sici(lo)[1] + math.sin(lo) / lo)
    assert S.tail_constant(inner_deg) == pytest.approx(1 / norm, rel=3e-10)
    for radius_um in (300.0, 3000.0, 30000.0):
        exact = _tail_share_closed_form(inner_deg, max(lo, math.atan(radius_um / 6000.0)))
        assert tail.share_within(radius_um) == pytest.approx(exact, rel=3e-10, abs=1e-15), radius_um
    nodes, weights = np.polynomial.legendre.leggauss(48)  # on 40 unit steps of s = ln r from r₁ (e⁴⁰ r₁: θ → 90°)
    s = (math.log(tail.inner_radius_um()) + np.arange(40.0)[:, None] + (nodes[None, :] + 1) / 2).ravel()
    plane = float((np.tile(weights / 2, 40) * tail.density(np.exp(s)) * 2 * math.pi * np.exp(2 * s)).sum())
    assert plane == pytest.approx(1.0, abs=3e-10)


def test_spread_kernel_holds_the_tails_norm():
    """The discrete tail kernel within a radius sums to the closed-form share within it (measured 4.9e-5,
    asserted 1.5e-4). The disc's cells, before the kernel rescales them to a sum of 1, hold its light to the
    sampling of its rim (measured 1 + 2.1e-4, asserted 6e-4), and a cell wholly inside holds its area / πR²."""
    tail = Spread("tail", 6000.0, inner_deg=2.5)
    k = S.kernel(tail, (300, 300), 12.4)
    y = np.arange(-299, 300) * 12.4
    r = np.hypot(y[:, None], y[None, :])
    assert k[r <= 3000].sum() == pytest.approx(_tail_share_closed_form(2.5, math.atan(3000 / 6000)), abs=1.5e-4)
    disc = Spread("disc", 6000.0, radius_um=500.0)
    assert S._cell_shares(disc, (100, 100), 24.8).sum() == pytest.approx(1.0, abs=6e-4)
    kd = S.kernel(disc, (100, 100), 24.8)
    assert kd.sum() == pytest.approx(1.0, rel=1e-12)
    assert kd[99, 99] == pytest.approx(24.8 ** 2 / (math.pi * 500.0 ** 2), rel=6e-4)


def test_coarse_grid_matches_the_full_resolution_veil(monkeypatch):
    """The veil computed on the coarse grid is within 1 % of the full-resolution one (smooth content)."""
    rng = np.random.default_rng(0)
    e = np.kron(rng.random((3, 16, 32)), np.ones((16, 16))) * 100
    tail = Spread("tail", 6000.0, inner_deg=2.5)
    coarse, landed, b = convolve(e, tail, 3.1)
    assert b > 1
    monkeypatch.setattr(S, "COARSE_PER_RADIUS", 1e9)
    fine, landed_fine, b1 = convolve(e, tail, 3.1)
    assert b1 == 1 and landed == pytest.approx(landed_fine, rel=1e-3)  # measured 3.3e-4
    assert np.abs(coarse - fine).max() < 0.01 * fine.max()


def test_finite_at_zero_and_huge_values():
    """Black frames, an enormous room, haze near 1 and a huge display luminance stay finite."""
    ctx = _ctx((32, 64))
    for e in (np.zeros((3, 32, 64)), np.full((3, 32, 64), 1e12)):
        for stray in (replace(StrayLight(), **ON_VALUES),
                      replace(OFF, room_illuminance_lux=1e15, haze={"poled": 0.999999}, lens_glare=1e-12,
                              display_luminance_cd_m2=1e15, lens_reflectance=0.999, ghost_blur_um=1e-3)):
            out, rec = apply_view(stray, e, "poled", False, np.ones(3), ctx)
            assert np.all(np.isfinite(out)) and out.min() >= 0
            json.dumps(rec)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("changes, key", [
    ({"room_illuminance_lux": -1.0}, "room_illuminance_lux"),
    ({"room_illuminance_lux": float("nan")}, "room_illuminance_lux"),
    ({"screen_reflectance": 1.5}, "screen_reflectance"), ({"lens_reflectance": 1.0}, "lens_reflectance"),
    ({"lens_glare": True}, "lens_glare"), ({"haze": {"poled": 1.0}}, "haze"), ({"haze": {"poled": -0.1}}, "haze"),
    ({"haze": {"": 0.1}}, "haze"), ({"haze": "poled"}, "haze"), ({"ghost_blur_um": 0.0}, "ghost_blur_um"),
    ({"glare_inner_deg": 90.0}, "glare_inner_deg"), ({"haze_inner_deg": 0.0}, "haze_inner_deg"),
    ({"display_luminance_cd_m2": float("inf")}, "display_luminance_cd_m2"),
    ({"underside_reflectance": {"glass": 2.0}}, "underside_reflectance"),
    ({"room_illuminance_lux": 300.0, "room_illuminant": "candle"}, "room_illuminant"),
])
def test_bad_knobs_get_one_line(changes, key):
    with pytest.raises(StrayLightError) as err:
        replace(StrayLight(), **changes)
    msg = str(err.value)
    assert "\n" not in msg and key in msg


def test_synth_config_refuses_a_non_stray_light():
    with pytest.raises(SynthError, match="stray_light"):
        SynthConfig(stray_light={"haze": 0.1})


# ---------------------------------------------------------------- records and profiles


def test_profiles_and_records(rig, tmp_path):
    """The paper profile has no stray light, the physical one the defaults (the P-OLED's haze); what ran is
    in synth.json (settings) and each capture.json (per effect: fraction and share of light)."""
    from udc_render.io.capture import write_synthesis
    scene, image, displays, cfg, kernels = rig
    paper, _ = resolve_profile("paper", SynthConfig(), displays)
    physical, _ = resolve_profile("physical", SynthConfig(), displays)
    assert paper.stray_light.is_off() and physical.stray_light == StrayLight() == SynthConfig().stray_light
    assert physical.profile["applied"]["stray_light"]["haze"] == {"poled": 0.015}
    result = _run(rig, StrayLight())
    write_synthesis(tmp_path, result, cfg.sensor.camera, side_by_side=False, previews=False)
    synth = json.loads((tmp_path / "synth.json").read_text())
    assert synth["stray_light"]["settings"] == StrayLight().describe() and synth["stray_light"]["applied"]
    cap = json.loads((tmp_path / "poled" / "capture.json").read_text())
    assert cap["optics"]["stray_light"]["haze"]["moved_share"] == 0.015
    assert json.loads((tmp_path / "toled" / "capture.json").read_text())["optics"]["stray_light"] == {}
    per_channel = synthesize(image, scene, displays, replace(cfg, form="per_channel", stray_light=StrayLight()))
    assert not per_channel.meta["stray_light"]["applied"] and "per-channel" in per_channel.meta["stray_light"]["note"]


def test_stray_light_option_wins_over_the_profile():
    """--stray-light off / default (resolve_profile's stray_light) replaces the profile's, and is recorded as
    an option."""
    from udc_render.cli import build_parser
    from udc_render.cli.args import capture_setup
    from udc_render.profiles import describe
    cfg, _ = capture_setup(build_parser().parse_args(["synth", "monitor", "--display", "poled",
                                                      "--stray-light", "off"]))
    assert cfg.stray_light.is_off() and cfg.profile["options"]["stray_light"] == "off"
    assert "stray light: none (option)" in describe(cfg.profile)
    cfg, _ = capture_setup(build_parser().parse_args(["synth", "monitor", "--profile", "paper", "--stray-light",
                                                      "default"]))
    assert cfg.stray_light == StrayLight() and "stray light: haze poled 0.015 (option)" in describe(cfg.profile)
    cfg, _ = capture_setup(build_parser().parse_args(["synth", "monitor"]))
    assert cfg.stray_light == StrayLight() and "stray_light" not in cfg.profile["options"]


def test_spread_back_interpolates_linearly_and_keeps_the_total():
    """Coarse cells of a plane's densities a + b·y + c·x come back as that plane at every pixel centre between the
    outer cell centres (bilinear interpolation is exact on a plane), clamped beyond them; the total is the cells'."""
    from udc_render.optics.stray.spread import spread_back
    b, h, w = 4, 5, 7
    yc, xc = np.arange(h)[:, None], np.arange(w)[None, :]  # cell centres in cell units
    cells = ((2.0 + 0.3 * yc + 0.1 * xc) * b * b)[None]  # cell sums of the plane's density
    fine = spread_back(cells, b)[0]
    t_y = np.clip((np.arange(h * b) + 0.5) / b - 0.5, 0, h - 1)[:, None]
    t_x = np.clip((np.arange(w * b) + 0.5) / b - 0.5, 0, w - 1)[None, :]
    plane = 2.0 + 0.3 * t_y + 0.1 * t_x
    scale = cells.sum() / plane.sum()  # the clamped border's share, put back uniformly
    np.testing.assert_allclose(fine, plane * scale, rtol=1e-13)
    assert fine.sum() == pytest.approx(cells.sum(), rel=1e-13)
