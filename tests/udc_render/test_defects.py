"""Sensor defect pixels (udc_render.sensor.defects): density, levels, a map that belongs to the sensor,
and a ground truth they never touch."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import binom

from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig, synthesize
from udc_render.render import render_scene
from udc_render.sensor import DefectConfig, DefectError, SensorConfig, SensorError, capture, defect_map, pack_rggb
from udc_render.sensor.defects import DEAD, HOT

EDGES = np.array([400.0, 500.0, 600.0, 700.0])
RIG_EXPOSURE_S = 0.03104  # the default rig's auto exposure (udc-render demo)


def _binomial_bounds(n: int, p: float, tail: float = 1e-7) -> tuple[int, int]:
    return int(binom.ppf(tail, n, p)), int(binom.isf(tail, n, p))


@pytest.mark.parametrize("dead, hot", [(1e-5, 1e-4), (3e-3, 2e-2)])
def test_density_within_binomial_bounds(dead, hot):
    """Each pixel is defective independently: on a 2048 × 2048 map the counts lie within the binomial
    1e-7 quantiles of the configured fractions (defaults, and larger ones)."""
    n_side = 2048
    m = defect_map(n_side, n_side, DefectConfig(dead_fraction=dead, hot_fraction=hot, seed=3))
    n = n_side * n_side
    for code, p in ((DEAD, dead), (HOT, hot)):
        lo, hi = _binomial_bounds(n, p)
        assert lo <= int((m == code).sum()) <= hi, (code, p, int((m == code).sum()), lo, hi)
    assert set(np.unique(m)) <= {0, DEAD, HOT}


def test_map_depends_on_its_seed_only_and_fractions_nest():
    a = defect_map(256, 512, DefectConfig(0.01, 0.02, seed=5))
    assert np.array_equal(a, defect_map(256, 512, DefectConfig(0.01, 0.02, seed=5)))
    b = defect_map(256, 512, DefectConfig(0.01, 0.02, seed=6))
    assert not np.array_equal(a != 0, b != 0) and np.mean((a != 0) & (b != 0)) < 0.003  # independent maps
    more = defect_map(256, 512, DefectConfig(0.01, 0.04, seed=5))
    assert np.all(more[a == HOT] == HOT) and np.array_equal(more == DEAD, a == DEAD)  # raising hot keeps them


def _dark_capture(gain: float, defects: DefectConfig, noise_seed: int = 0, black: int = 256):
    """A capture of zero light (read noise only) at the rig's exposure through `gain`."""
    s = SensorConfig(gain=gain, exposure_s=RIG_EXPOSURE_S, black_level_dn=black)
    return capture(np.zeros((3, 64, 64)), EDGES, s, np.random.default_rng(noise_seed), defects=defects), s


def test_dead_at_black_hot_saturates_at_gain_25_not_at_gain_1():
    """Dead pixels read the black level; a hot pixel adds g · hot_dark_e_per_s · exposure: at the rig's
    exposure with the default rate it is below white at gain 1 (black + 3935 DN, within 6 σ of read
    noise), and at the white level at the P-OLED's gain 25. Good pixels are untouched."""
    defects = DefectConfig(dead_fraction=0.02, hot_fraction=0.03, seed=11)  # default hot_dark_e_per_s
    m = defect_map(64, 64, defects)
    assert (m == DEAD).sum() > 20 and (m == HOT).sum() > 40
    for gain in (1.0, 6.0, 25.0):
        cap, s = _dark_capture(gain, defects)
        plain, _ = _dark_capture(gain, None)
        mosaic = cap.mosaic_dn
        assert np.all(mosaic[m == DEAD] == 256)
        assert np.array_equal(mosaic[m == 0], plain.mosaic_dn[m == 0])  # defects draw nothing from the noise rng
        assert np.array_equal(cap.packed_dn, pack_rggb(mosaic))  # the packed RAW carries them too
        hot = mosaic[m == HOT].astype(float)
        added = s.dn_per_electron * defects.hot_dark_e_per_s * RIG_EXPOSURE_S
        if gain == 25.0:
            assert added > 65535 and np.all(hot == 65535)
        else:
            sigma = s.dn_per_electron * s.read_noise_e
            assert np.all(hot < 65535) and np.all(np.abs(hot - (256 + added)) < 6 * sigma + 1), gain
        p = cap.params["defects"]
        assert p["dead_pixels"] == (m == DEAD).sum() and p["hot_pixels"] == (m == HOT).sum()
        assert p["hot_saturated"] == ((m == HOT).sum() if gain == 25.0 else 0)
        assert p["hot_dn_added"] == pytest.approx(added) and p["seed"] == 11
    assert 3900 < SensorConfig().dn_per_electron * DefectConfig().hot_charge_e(RIG_EXPOSURE_S) < 3970


def test_no_defects_records_none():
    cap, _ = _dark_capture(1.0, None)
    assert cap.params["defects"] is None


@pytest.mark.parametrize("kwargs, key", [
    ({"dead_fraction": -1e-5}, "dead_fraction"), ({"dead_fraction": float("nan")}, "dead_fraction"),
    ({"dead_fraction": 0.6, "hot_fraction": 0.5}, "hot_fraction"), ({"hot_fraction": "1e-4"}, "hot_fraction"),
    ({"hot_dark_e_per_s": -1.0}, "hot_dark_e_per_s"), ({"seed": 1.5}, "seed"), ({"seed": True}, "seed"),
    ({"seed": -1}, "seed")])
def test_bad_settings_are_one_line_naming_key_value_and_range(kwargs, key):
    with pytest.raises(DefectError) as err:
        DefectConfig(**kwargs)
    msg = str(err.value)
    assert msg.startswith(f"defects.{key} = ") and "expected" in msg and "\n" not in msg
    assert isinstance(err.value, SensorError)


def test_old_sensor_defect_keys_are_refused_with_where_they_went():
    with pytest.raises(SensorError) as err:
        SensorConfig.from_dict({"dead_fraction": 0.01})
    assert "sensor.dead_fraction = 0.01" in str(err.value) and "--profile" in str(err.value)


# ---------------------------------------------------------------- in the synthesis


@pytest.fixture(scope="module")
def white(udc, tmp_path_factory, render_cache):
    """A tiny monitor filling the frame with white; 3 bands; 9-px kernels."""
    doc = udc.monitor_doc(sensor_px=(64, 32), pitch_um=49.6, render={"spp": 2, "margin_um": 150},
                          bands={"range_nm": [400, 700], "step_nm": 100})
    scene = udc.write_scene(tmp_path_factory.mktemp("white") / "white.toml", doc)
    return scene, render_scene(scene, progress=False)


def _defect_positions(cap) -> np.ndarray:
    """Where the noise-free mosaic departs from its clean mean by more than rounding (noise 'none')."""
    return np.abs(cap.clean_dn.astype(np.float64) - cap.mosaic_dn) > 1.0


def test_same_map_in_every_capture_of_a_run_and_ground_truth_untouched(white):
    """Noise off, a white field, glass + T-OLED + P-OLED, items 0 and 1: defects sit at the same pixels
    in every capture (the sensor's map), move with another defect seed, and neither the ground truth
    nor the clean mosaic changes; without defects the mosaic is the rounded clean mean."""
    scene, bi = white
    views = [D.preset(n) for n in ("glass", "toled", "poled")]
    base = SynthConfig(sensor=SensorConfig(noise="none"))
    defects = DefectConfig(dead_fraction=0.02, hot_fraction=0.03, hot_dark_e_per_s=1e7, seed=4)  # ~0.03 ms exposure
    expected = defect_map(32, 64, defects) != 0
    clean = synthesize(bi, scene, views, base)
    assert not any(_defect_positions(c).any() for c in clean.captures.values())
    for item in (0, 1):
        res = synthesize(bi, scene, views, SynthConfig(sensor=SensorConfig(noise="none"), defects=defects), item)
        assert np.array_equal(res.gt, clean.gt)
        assert res.meta["defects"]["seed"] == 4 and clean.meta["defects"] is None
        for name, cap in res.captures.items():
            assert np.array_equal(_defect_positions(cap), expected), (item, name)
            assert np.array_equal(cap.clean_dn, clean.captures[name].clean_dn)
            assert np.array_equal(cap.packed_dn, pack_rggb(cap.mosaic_dn))
    other = synthesize(bi, scene, views[:1], SynthConfig(sensor=SensorConfig(noise="none"),
                                                         defects=replace(defects, seed=5)))
    assert not np.array_equal(_defect_positions(other.captures["glass"]), expected)


def test_the_defect_map_is_made_once_per_shape_and_read_only():
    """defect_map is a function of (shape, config): made once per process, read-only."""
    d = DefectConfig(dead_fraction=0.01, hot_fraction=0.01, seed=2)
    kind = defect_map(8, 6, d)
    assert defect_map(8, 6, d) is kind
    with pytest.raises(ValueError, match="read-only"):
        kind[0, 0] = 0
