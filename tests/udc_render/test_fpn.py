"""Fixed-pattern noise (udc_render.sensor.fpn): maps whose statistics are their parameters, drawn from
their own seed, the same in every capture of a run, never in the ground truth; the PRNU a flat field
shows, the dark charge's shot noise, the offsets read through the gain.

Tolerances: the sample σ of n independent normals has a standard error σ / √(2(n − 1)); a sample
variance of n Gaussian values s² has SE s² √(2 / (n − 1)). Bounds are 5 SE (a correct model fails
with probability < 1e-6 per comparison); the seeds are fixed, so the tests are deterministic.
"""
from __future__ import annotations

import math
from dataclasses import asdict, replace

import numpy as np
import pytest

from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig, SynthError, synthesize
from udc_render.profiles import PROFILES, describe, resolve_profile
from udc_render.render import render_scene
from udc_render.sensor import FpnConfig, FpnError, SensorConfig, SensorError, capture, capture_electrons, fpn_maps

BLACK = 4096


def _sigma_tol(n: int, k: float = 5.0) -> float:
    """k standard errors of a sample σ, relative to σ."""
    return k / math.sqrt(2 * (n - 1))


def flat_rgb(level: float, n: int = 512) -> np.ndarray:
    return np.full((3, n, n), level)


# ---------------------------------------------------------------- the maps


def test_map_statistics_equal_their_parameters():
    """PRNU map σ (relative gain), DSNU σ, row and column σ equal the settings within 5 SE of a sample σ:
    1024 × 1024 pixels (1.05e6 samples, 0.35 %); rows and columns from 2e5 × 8 and 8 × 2e5 maps (2e5
    samples, 0.79 %). The gain map's mean is 1 within 5 σ/√n, and the four maps are uncorrelated."""
    fpn = FpnConfig(prnu=0.012, dsnu_e=2.5, row_offset_e=0.7, column_offset_e=1.3, seed=9)
    m = fpn_maps(1024, 1024, fpn)
    n = m.gain.size
    tol = _sigma_tol(n)
    assert abs(m.gain.std(ddof=1) / fpn.prnu - 1) < tol, m.gain.std()
    assert abs(m.gain.mean() - 1) < 5 * fpn.prnu / math.sqrt(n)
    assert abs(m.dsnu_e.std(ddof=1) / fpn.dsnu_e - 1) < tol and abs(m.dsnu_e.mean()) < 5 * fpn.dsnu_e / math.sqrt(n)
    assert abs(np.corrcoef(m.gain.ravel(), m.dsnu_e.ravel())[0, 1]) < 5 / math.sqrt(n)
    tall, wide = fpn_maps(200_000, 8, fpn), fpn_maps(8, 200_000, fpn)
    tol_rc = _sigma_tol(200_000)
    assert abs(tall.row_e.std(ddof=1) / fpn.row_offset_e - 1) < tol_rc, tall.row_e.std()
    assert abs(wide.column_e.std(ddof=1) / fpn.column_offset_e - 1) < tol_rc, wide.column_e.std()
    # the offset map is their sum: its spatial variance is the sum of theirs (independent parts)
    want = fpn.dsnu_e ** 2 + fpn.row_offset_e ** 2 + fpn.column_offset_e ** 2
    got = fpn_maps(2048, 2048, fpn).offset_e.var()
    assert abs(got / want - 1) < 0.05  # rows and columns contribute 2048 samples each: ±3 % at 1 σ of theirs


def test_same_seed_same_maps_another_seed_others_and_a_parameter_scales_one_map():
    a = fpn_maps(64, 96, FpnConfig(seed=3))
    b = fpn_maps(64, 96, FpnConfig(seed=3))
    c = fpn_maps(64, 96, FpnConfig(seed=4))
    for f in ("gain", "dsnu_e", "row_e", "column_e"):
        assert np.array_equal(getattr(a, f), getattr(b, f))
        assert abs(np.corrcoef(getattr(a, f).ravel(), getattr(c, f).ravel())[0, 1]) < 0.3, f
    double = fpn_maps(64, 96, FpnConfig(prnu=2 * FpnConfig().prnu, seed=3))
    assert np.allclose(double.gain - 1, 2 * (a.gain - 1), rtol=1e-12, atol=1e-15)


def test_zero_settings_are_exactly_no_fpn():
    """Every FPN term vanishes exactly at zero: a capture with all-zero FPN equals one without, for the
    three noise models (the same rng draws, the same bytes)."""
    zero = FpnConfig(prnu=0.0, dsnu_e=0.0, row_offset_e=0.0, column_offset_e=0.0, dark_current_e_per_s=0.0)
    for noise in ("poisson", "gaussian", "none"):
        s = SensorConfig(form="per_channel", noise=noise, black_level_dn=BLACK, gain=6.0)
        img = np.random.default_rng(1).uniform(0, 0.3, (3, 64, 64))
        off = capture(img, None, s, np.random.default_rng(2))
        on = capture(img, None, s, np.random.default_rng(2), fpn=zero)
        assert np.array_equal(off.mosaic_dn, on.mosaic_dn) and np.array_equal(off.clean_dn, on.clean_dn), noise
        assert off.params["fpn"] is None and on.params["fpn"]["prnu"] == 0.0


# ---------------------------------------------------------------- in a capture


def test_flat_field_shows_the_prnu_without_temporal_noise():
    """Noise 'none', a flat field at half the full well, gain 1: (DN − black) / mean DN has the PRNU map's
    spatial σ (its realised value; rounding adds 1/12 DN² on 32768 DN: 9e-6 relative) and pixel by pixel
    equals the gain map to half a DN. The clean mosaic stays flat."""
    fpn = FpnConfig(prnu=0.01, dsnu_e=0.0, row_offset_e=0.0, column_offset_e=0.0, dark_current_e_per_s=0.0, seed=5)
    s = SensorConfig(form="per_channel", noise="none", black_level_dn=BLACK)
    cap = capture(flat_rgb(0.5), None, s, np.random.default_rng(0), fpn=fpn)
    signal = cap.mosaic_dn.astype(np.float64) - BLACK
    mean_dn = s.dn_per_electron * 0.5 * s.full_well_e
    gain = fpn_maps(512, 512, fpn).gain
    assert np.max(np.abs(signal - mean_dn * gain)) <= 0.5 + 1e-6
    rel = signal / mean_dn
    assert abs(rel.std(ddof=1) / gain.std(ddof=1) - 1) < 1e-4
    assert abs(rel.std(ddof=1) / fpn.prnu - 1) < _sigma_tol(rel.size)
    assert np.ptp(cap.clean_dn) == 0.0
    rec = cap.params["fpn"]
    assert rec["prnu"] == 0.01 and rec["map_std"]["prnu"] == pytest.approx(gain.std())


@pytest.mark.parametrize("noise", ["poisson", "gaussian"])
def test_two_frames_separate_prnu_from_temporal_noise(noise):
    """The EMVA 1288 two-frame method (Release 3.1 §8.1): frames A and B of one flat field with the same
    maps and other noise seeds; the spatial variance of (A + B)/2 minus a quarter of the variance of
    A − B is the PRNU's, (PRNU · μ)², within 5 SE (both variances' SE, s² √(2/(n−1)), added)."""
    fpn = FpnConfig(prnu=0.01, dsnu_e=0.0, row_offset_e=0.0, column_offset_e=0.0, dark_current_e_per_s=0.0, seed=2)
    s = SensorConfig(form="per_channel", noise=noise, lambda_source="sensor", black_level_dn=BLACK)
    a, b = (capture(flat_rgb(0.5), None, s, np.random.default_rng(k), fpn=fpn).mosaic_dn.astype(np.float64)
            for k in (10, 11))
    g = s.dn_per_electron
    mean_img, diff = (a + b) / 2 / g, (a - b) / g  # electrons
    n = a.size
    v_mean, v_diff = mean_img.var(ddof=1), diff.var(ddof=1)
    spatial = v_mean - v_diff / 4
    want = (fpn_maps(512, 512, fpn).gain.std() * 0.5 * s.full_well_e) ** 2
    se = math.sqrt(2 / (n - 1)) * math.hypot(v_mean, v_diff / 4)
    assert abs(spatial - want) < 5 * se, (spatial, want, se)
    # the temporal part is the model's: shot + read noise (+ rounding) in electrons
    temporal = 0.5 * s.full_well_e + s.read_noise_e ** 2 + 1 / 12 / g ** 2
    assert abs(v_diff / 2 - temporal) < 5 * math.sqrt(2 / (n - 1)) * temporal


def test_dark_charge_has_its_shot_noise_and_the_offsets_go_through_the_gain():
    """No light: the mean charge is dark current × exposure (1000 e⁻) with Poisson variance 1000 + σ_read²
    (two frames, 5 SE); with noise 'none' each pixel reads black + g (D t + o_ij), o the offset map, to
    half a DN, at gain 6 (negative offsets stay above 0 DN on a black level of 4096)."""
    fpn = FpnConfig(prnu=0.02, dsnu_e=3.0, row_offset_e=1.0, column_offset_e=2.0, dark_current_e_per_s=2e4, seed=7)
    s = SensorConfig(form="per_channel", noise="poisson", black_level_dn=BLACK, exposure_s=0.05)
    a, b = (capture(np.zeros((3, 512, 512)), None, s, np.random.default_rng(k), fpn=replace(
        fpn, dsnu_e=0.0, row_offset_e=0.0, column_offset_e=0.0)).mosaic_dn.astype(np.float64) for k in (1, 2))
    g = s.dn_per_electron
    n = a.size
    dark = fpn.dark_current_e_per_s * s.exposure_s
    assert abs((a - BLACK).mean() / g - dark) < 5 * math.sqrt(dark + s.read_noise_e ** 2) / math.sqrt(n)
    temporal = dark + s.read_noise_e ** 2 + 1 / 12 / g ** 2
    assert abs(((a - b) / g).var(ddof=1) / 2 - temporal) < 5 * math.sqrt(2 / (n - 1)) * temporal
    s6 = replace(s, noise="none", gain=6.0)
    cap = capture(np.zeros((3, 128, 128)), None, s6, np.random.default_rng(0), fpn=fpn)
    off = fpn_maps(128, 128, fpn).offset_e
    assert np.max(np.abs(cap.mosaic_dn.astype(float) - BLACK - s6.dn_per_electron * (dark + off))) <= 0.5 + 1e-6
    assert np.all(cap.clean_dn == BLACK) and cap.params["fpn"]["dark_charge_e"] == pytest.approx(dark)


def test_full_well_caps_the_read_out_charge_as_before():
    """A saturated flat field still reads black + g · FW everywhere (the cap follows the FPN)."""
    s = SensorConfig(form="per_channel", noise="poisson", black_level_dn=0)
    cap = capture(flat_rgb(3.0, 64), None, s, np.random.default_rng(0), fpn=FpnConfig(prnu=0.05, dsnu_e=5.0))
    assert np.all(cap.mosaic_dn == s.white_level_dn)


# radiometry's float32 3e38 / (a small e⁻ unit)
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_float32_huge_zero_and_tiny_exposure_stay_finite():
    """float32 input with 0, 1e-30 and 3e38 (near float32's max), PRNU 0 and the largest allowed PRNU,
    a 1 ns exposure: every DN is finite and in [0, white], the huge pixels saturate, the zeros read
    black + g o (offsets only)."""
    img = np.zeros((3, 32, 32), np.float32)
    img[:, :8] = np.float32(3e38)  # rows 0-7
    img[:, 8:16] = np.float32(1e-30)
    for prnu in (0.0, 0.25):
        for noise in ("poisson", "gaussian", "none"):
            s = SensorConfig(form="per_channel", noise=noise, exposure_s=1e-9, black_level_dn=BLACK)
            cap = capture(img, None, s, np.random.default_rng(0), fpn=FpnConfig(prnu=prnu))
            assert cap.mosaic_dn.dtype == np.uint16 and np.all(np.isfinite(cap.clean_dn))
            assert np.all(cap.mosaic_dn[:8] == s.white_level_dn), (prnu, noise)  # rows 0-7: huge
            if noise == "none":
                off = fpn_maps(32, 32, FpnConfig(prnu=prnu)).offset_e[16:]
                assert np.max(np.abs(cap.mosaic_dn[16:].astype(float) - BLACK - s.dn_per_electron * off)) <= 0.5 + 1e-6
            assert all(math.isfinite(v) for v in cap.params["fpn"]["map_std"].values())
    e = np.full((16, 16), np.finfo(np.float64).max)
    cap = capture_electrons(e, SensorConfig(form="per_channel"), np.random.default_rng(0), fpn=FpnConfig(prnu=0.25))
    assert np.all(cap.mosaic_dn == 65535)


@pytest.mark.parametrize("kwargs, key", [
    ({"prnu": -0.01}, "prnu"), ({"prnu": 0.5}, "prnu"), ({"prnu": float("nan")}, "prnu"), ({"prnu": "0.01"}, "prnu"),
    ({"dsnu_e": -1.0}, "dsnu_e"), ({"row_offset_e": float("inf")}, "row_offset_e"),
    ({"column_offset_e": True}, "column_offset_e"), ({"dark_current_e_per_s": -5.0}, "dark_current_e_per_s"),
    ({"seed": 1.5}, "seed"), ({"seed": -1}, "seed")])
def test_bad_settings_are_one_line_naming_key_value_and_range(kwargs, key):
    with pytest.raises(FpnError) as err:
        FpnConfig(**kwargs)
    msg = str(err.value)
    assert msg.startswith(f"fpn.{key} = ") and "expected" in msg and "\n" not in msg
    assert isinstance(err.value, SensorError)
    with pytest.raises(SynthError, match="^fpn = 0.01: expected"):
        SynthConfig(fpn=0.01)


# ---------------------------------------------------------------- in the synthesis


@pytest.fixture(scope="module")
def white(udc, tmp_path_factory, render_cache):
    """A tiny monitor filling the frame with white; 3 bands; 9-px kernels."""
    doc = udc.monitor_doc(sensor_px=(64, 32), pitch_um=49.6, render={"spp": 2, "margin_um": 150},
                          bands={"range_nm": [400, 700], "step_nm": 100})
    scene = udc.write_scene(tmp_path_factory.mktemp("white") / "white.toml", doc)
    return scene, render_scene(scene, progress=False)


@pytest.mark.parametrize("form", ["spectral", "per_channel"])
def test_same_maps_in_glass_and_display_captures_none_in_the_ground_truth(white, form):
    """Noise off, a white field, glass + T-OLED + P-OLED, items 0 and 1, both forms: in every capture each
    pixel reads black + g · (e · gain_ij + D t + o_ij) to half a DN, with the one set of maps of the
    seed (e from the clean mosaic, which, like the ground truth, equals the FPN-free run's)."""
    scene, bi = white
    views = [D.preset(n) for n in ("glass", "toled", "poled")]
    sensor = SensorConfig(noise="none", black_level_dn=BLACK)
    fpn = FpnConfig(prnu=0.03, dsnu_e=2.0, row_offset_e=1.0, column_offset_e=1.5, dark_current_e_per_s=100.0, seed=6)
    base = synthesize(bi, scene, views, SynthConfig(form=form, sensor=sensor))
    maps = fpn_maps(32, 64, fpn)
    for item in (0, 1):
        res = synthesize(bi, scene, views, SynthConfig(form=form, sensor=sensor, fpn=fpn), item)
        assert np.array_equal(res.gt, base.gt) and res.meta["fpn"] == asdict(fpn) and base.meta["fpn"] is None
        for name, cap in res.captures.items():
            assert np.array_equal(cap.clean_dn, base.captures[name].clean_dn), name
            g = cap.params["dn_per_electron"]
            e = (cap.clean_dn.astype(np.float64) - BLACK) / g
            assert e.max() < 0.9 * cap.params["sensor"]["full_well_e"]  # unsaturated: the formula holds
            dark = cap.params["fpn"]["dark_charge_e"]
            want = BLACK + g * (e * maps.gain + dark + maps.offset_e)
            ok = want < cap.params["sensor"]["white_level_dn"] - 1  # below white: not clipped
            assert ok.mean() > 0.5, (name, ok.mean())
            # clean_dn is float32: its rounding (≤ 2^-24 of 65535 DN) adds to the half DN of quantisation
            assert np.max(np.abs(cap.mosaic_dn - want)[ok]) <= 0.5 + 4e-3 * (1 + maps.gain.max()), (item, name)
            assert np.all(cap.mosaic_dn[~ok] >= cap.params["sensor"]["white_level_dn"] - 1)
            assert cap.params["fpn"]["seed"] == 6
    other = synthesize(bi, scene, views[:1], SynthConfig(form=form, sensor=sensor, fpn=replace(fpn, seed=7)))
    assert not np.array_equal(other.captures["glass"].mosaic_dn, res.captures["glass"].mosaic_dn)


def test_profiles_physical_has_fpn_paper_none():
    assert PROFILES["physical"].fpn == FpnConfig() and PROFILES["paper"].fpn is None
    cfg, _ = resolve_profile("physical", SynthConfig(), [D.preset("toled")])
    assert cfg.fpn == FpnConfig() and cfg.profile["applied"]["fpn"] == asdict(FpnConfig())
    assert "fixed-pattern noise: PRNU 0.007, DSNU 1 e-" in describe(cfg.profile)
    cfg, _ = resolve_profile("paper", SynthConfig(), [D.preset("toled")])
    assert cfg.fpn is None and cfg.form == "per_channel" and "fixed-pattern noise: none" in describe(cfg.profile)
    assert SynthConfig().fpn is None


def test_the_maps_are_made_once_per_shape_and_read_only():
    """fpn_maps is a function of (shape, config): a process makes it once and hands out read-only arrays (a capture
    that wrote into them would change every later capture)."""
    fpn = FpnConfig(prnu=0.01, dsnu_e=1.0, seed=3)
    a = fpn_maps(8, 6, fpn)
    assert fpn_maps(8, 6, fpn) is a and fpn_maps(8, 8, fpn) is not a
    with pytest.raises(ValueError, match="read-only"):
        a.gain[0, 0] = 2.0
