"""The averaged ground truth (SynthConfig.gt_frames, sensor.frames): the mean of N glass frames at gain 1."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from udc_render.optics import displays as D
from udc_render.pipeline import SynthConfig, SynthError, synthesize
from udc_render.profiles import PAPER_GT_FRAMES, resolve_profile
from udc_render.render import render_scene
from udc_render.sensor import SensorConfig, SensorError, mosaic_of
from udc_render.sensor.frames import (
    _frame_after_frame,
    _frame_by_frame,
    _thinned_counts,
    burst_sensor,
    mean_of_frames,
)

FLAT_PX = (256, 256)  # 65 536 pixels: a σ estimate within 0.3 % (1/√(2M)); tolerances about 4 of those


def _frame_sigma_dn(s: SensorConfig, e: float) -> float:
    """One poisson frame's σ in DN with the rounding: √(g² (e + σ_read²) + 1/12)."""
    g = s.dn_per_electron
    return math.sqrt(g * g * (e + s.read_noise_e ** 2) + 1 / 12)


@pytest.mark.parametrize("e0", [300.0, 5000.0, 12000.0])
def test_flat_field_noise_falls_as_one_over_root_n(e0):
    """On a flat field the mean of 16 frames has the single frame's σ / 4 (within sampling error), both equal
    to the model's σ (shot, read, rounding), and the mean level is unbiased."""
    s = SensorConfig()
    rng = np.random.default_rng(3)
    e = np.full(FLAT_PX, e0)
    one, _ = mean_of_frames(e, s, 1, rng)
    sixteen, drawn = mean_of_frames(e, s, PAPER_GT_FRAMES, rng)
    sigma = _frame_sigma_dn(s, e0)
    assert drawn == 0  # no frame clips: the one-draw sum
    # a σ measured over FLAT_PX = 65 536 values errs by 1 / √(2 · 65 536) = 0.28 % (1σ): asserted ~4σ (measured
    # 0.36 %, 0.17 % and 0.19 % on the ratio)
    assert one.std() == pytest.approx(sigma, rel=0.012)
    assert sixteen.std() == pytest.approx(sigma / 4, rel=0.012)
    assert one.std() / sixteen.std() == pytest.approx(4.0, rel=0.016)
    assert abs(sixteen.mean() - s.dn_per_electron * e0) < 5 * sigma / 4 / math.sqrt(e.size)


def test_the_one_draw_sum_matches_frames_drawn_one_by_one():
    """The exact-sum path (Poisson(N e) + N(0, N σ²) + rounding) and N frames of expose agree in mean and σ."""
    s = SensorConfig()
    rng = np.random.default_rng(4)
    e = np.full(FLAT_PX, 2000.0)
    fast, _ = mean_of_frames(e, s, 16, rng)
    slow = _frame_by_frame(e.ravel(), s, 16, rng)
    assert fast.std() == pytest.approx(slow.std(), rel=0.016)  # two σ estimates: 0.4 % (1σ); measured 0.54 %
    assert abs(fast.mean() - slow.mean()) < 5 * slow.std() / math.sqrt(e.size)


def test_dark_pixels_clip_at_black_frame_by_frame():
    """At black level 0 a dark pixel's frames are clipped at 0 DN one by one: the mean of e = 0 is
    E[max(g·N(0, σ_read²), 0)] = g σ_read / √(2π), not 0, and never negative."""
    s = SensorConfig()
    out, drawn = mean_of_frames(np.zeros(FLAT_PX), s, 16, np.random.default_rng(5))
    expected = s.dn_per_electron * s.read_noise_e / math.sqrt(2 * math.pi)
    assert drawn == out.size and out.min() >= 0
    assert out.mean() == pytest.approx(expected, rel=0.01)


def test_saturation_and_the_gaussian_model():
    """Above the full well every frame reads the white level; the Gaussian model's mean of 16 has its
    σ √((λ_read + λ_shot w)/16) (in units of the range)."""
    s = SensorConfig()
    sat, _ = mean_of_frames(np.full((4, 4), 3 * s.full_well_e), s, 16, np.random.default_rng(6))
    assert np.all(sat == s.white_level_dn)
    g = burst_sensor(replace(s, noise="gaussian", lambda_source="sensor"), np.random.default_rng(7))
    w = 0.4
    out, _ = mean_of_frames(np.full(FLAT_PX, w * s.full_well_e), g, 16, np.random.default_rng(8))
    sigma = math.sqrt((g.lambda_read[0] + g.lambda_shot[0] * w) / 16) * g.range_dn
    assert out.std() == pytest.approx(math.sqrt(sigma ** 2 + 1 / (12 * 16)), rel=0.012)  # measured 0.31 %


def test_bad_frames_and_brooks_without_a_burst_are_refused():
    with pytest.raises(SensorError, match="frames = 0"):
        mean_of_frames(np.zeros((2, 2)), SensorConfig(), 0, np.random.default_rng(0))
    with pytest.raises(SensorError, match="brooks"):
        mean_of_frames(np.zeros((2, 2)), SensorConfig(noise="gaussian", lambda_source="brooks"), 4,
                       np.random.default_rng(0))
    for bad in (0, -1, 2.5, True, 5000):
        with pytest.raises(SynthError, match="gt_frames"):
            SynthConfig(gt_frames=bad)


# ---------------------------------------------------------------- the pipeline


@pytest.fixture(scope="module")
def grey(udc, tmp_path_factory, render_cache):
    """A tiny monitor filling the frame with a mid-grey and a black half (both the sum and the per-frame path)."""
    doc = udc.monitor_doc(image="pattern:white", bands={"range_nm": [400, 700], "step_nm": 100}, framing="fit")
    scene = udc.write_scene(tmp_path_factory.mktemp("grey") / "grey.toml", doc)
    return scene, render_scene(scene, progress=False)


def test_none_is_the_noise_free_ground_truth(grey):
    """gt_frames None: the gt is the glass electrons / full well, bit for bit (the glass capture's mean
    electrons, mosaicked, are those electrons)."""
    scene, band_image = grey
    r = synthesize(band_image, scene, [D.preset("glass")], SynthConfig())
    fw = SynthConfig().sensor.full_well_e
    glass_e = r.captures["glass"].electrons
    np.testing.assert_array_equal(mosaic_of(r.gt), (glass_e / fw).astype(np.float32))
    assert r.meta["gt_frames"] is None and r.meta["gt_noise"] is None


def test_averaged_ground_truth_in_the_pipeline(grey):
    """gt_frames 16: the gt departs from the noise-free one by the 16-frame σ of each pixel (its normalised
    residual has unit variance), is deterministic, its own noise stream (a second display changes nothing),
    and recorded in synth.json's record."""
    scene, band_image = grey
    base = SynthConfig()
    ideal = synthesize(band_image, scene, [D.preset("glass")], base).gt
    cfg = replace(base, gt_frames=16)
    a = synthesize(band_image, scene, [D.preset("glass")], cfg)
    b = synthesize(band_image, scene, [D.preset("glass"), D.preset("toled")], cfg)
    np.testing.assert_array_equal(a.gt, b.gt)
    assert not np.array_equal(a.gt, synthesize(band_image, scene, [D.preset("glass")], cfg, item=1).gt)
    s = SensorConfig()
    g = s.dn_per_electron
    e = ideal.astype(np.float64) * s.full_well_e
    lit = e > 100
    sigma = np.sqrt((g * g * (e + s.read_noise_e ** 2) + 1 / 12) / 16) / (g * s.full_well_e)
    z = (a.gt.astype(np.float64) - ideal)[lit] / sigma[lit]
    assert lit.sum() > 3000 and np.var(z) == pytest.approx(1.0, rel=0.1) and abs(z.mean()) < 0.1
    rec = a.meta["gt_noise"]
    assert a.meta["gt_frames"] == 16 and rec["frames"] == 16 and rec["gain"] == 1.0
    assert "crc32('gt frames')" in rec["noise_seed"] and "mean of gt_frames" in a.meta["gt"]
    json.dumps(a.meta)


def test_profiles_average_sixteen_frames():
    """Both profiles take the paper's 16-frame ground truth (l.235, l.258–260); 'ideal' and N override it."""
    for name in ("paper", "physical"):
        cfg, _ = resolve_profile(name, SynthConfig(), [D.preset("glass")])
        assert cfg.gt_frames == PAPER_GT_FRAMES and cfg.profile["applied"]["gt_frames"] == 16
        cfg, _ = resolve_profile(name, SynthConfig(), [D.preset("glass")], gt_frames="ideal")
        assert cfg.gt_frames is None and cfg.profile["options"]["gt_frames"] == "ideal"
        cfg, _ = resolve_profile(name, SynthConfig(), [D.preset("glass")], gt_frames=4)
        assert cfg.gt_frames == 4


def _exact_sum_pmf(e: float, s: SensorConfig, n: int) -> np.ndarray:
    """The law of Σ_f DN_f over n frames of a pixel of mean e (black level 0, far below white and the full well), in
    closed form: one frame's DN is v with probability Σ_k Poisson(k; e) P(rint(g (k + σ G)) = v), v ≥ 1, and the
    rest of the mass at 0 (the clip); the sum's law is its n-fold convolution."""
    from scipy.stats import norm, poisson
    g, sigma = s.dn_per_electron, s.read_noise_e
    k = np.arange(int(e + 12 * math.sqrt(e) + 12) + 1)
    v = np.arange(int(g * (k[-1] + 12 * sigma)) + 2)
    below = norm.cdf((v[None, :] + 0.5 - g * k[:, None]) / (g * sigma))  # P(g (k + σ G) < v + ½)
    one = poisson.pmf(k, e) @ np.diff(below, axis=1, prepend=0.0)
    pmf = np.array([1.0])
    for _ in range(n):
        pmf = np.convolve(pmf, one)
    return pmf


@pytest.mark.parametrize("e0", [0.05, 0.7, 6.0, 11.9, 30.0])  # thinned below frames.THIN_BELOW_E, then not
def test_frames_drawn_one_by_one_follow_the_exact_law(e0):
    """The mean of 16 clipped frames of the pixels drawn frame by frame against the closed-form law of the sum: a χ²
    test over 30 000 pixels, bins of ≥ 20 expected, at a fixed seed (refused below p = 1e-4)."""
    from scipy.stats import chisquare
    s = replace(SensorConfig(), gain=1.0)
    e = np.full(60_000, e0)
    e[::2] = 40.0  # the other path interleaved: the pixels keep their place
    sums = np.rint(_frame_by_frame(e, s, 16, np.random.default_rng(7))[1::2] * 16).astype(int)
    pmf = _exact_sum_pmf(e0, s, 16)
    expected = pmf * sums.size
    edges = [0]  # bins of ≥ 20 expected, the tails merged
    acc = 0.0
    for i, x in enumerate(expected):
        acc += x
        if acc >= 20:
            edges.append(i + 1)
            acc = 0.0
    edges[-1] = max(len(pmf), sums.max() + 1)
    observed = np.histogram(sums, bins=edges)[0]
    want = np.add.reduceat(np.concatenate([expected, np.zeros(edges[-1] - len(pmf))]), edges[:-1])
    assert chisquare(observed, want * observed.sum() / want.sum()).pvalue > 1e-4


def test_frame_after_frame_is_expose_frames_bit_for_bit():
    """Above THIN_BELOW_E the pixels take expose's draws and arithmetic (Poisson counts, then the read noise's
    normals, every frame): the same bits as the sum of n expose frames of the same pixels, at the clips (0, the
    full well, the white level) too."""
    from udc_render.sensor.noise import expose
    from udc_render.sensor.readout import poisson_cap_e
    s = replace(SensorConfig(), gain=1.0)
    e = np.random.default_rng(1).exponential(20.0, 4000)
    e[:8] = [0.0, 1e9, s.full_well_e, 4e4, 0.1, 80.0, 1e-9, 2e5]
    rng = np.random.default_rng(5)
    want = sum(expose(e.reshape(2, -1), s, rng)[0].astype(np.float64) for _ in range(16)).ravel()
    mean = np.minimum(e, poisson_cap_e(s.full_well_e, s.read_noise_e))
    got = _frame_after_frame(mean, s, 16, np.random.default_rng(5))
    assert np.array_equal(got, want)
    assert got[1] == 16 * s.white_level_dn and got[0] >= 0


def test_thinned_counts_are_independent_poisson_frames():
    """T ~ Poisson(n λ) electrons put in uniform frames give n iid Poisson(λ) counts: each frame's counts against
    the Poisson pmf (χ² over 40 000 pixels × 16 frames, refused below p = 1e-4 at a fixed seed) and two frames'
    correlation within 4 standard errors of 0 (given T the frames are anti-correlated: only the mixture over T
    makes them independent)."""
    from scipy.stats import chisquare, poisson
    lam, px = 1.3, 40_000
    counts = _thinned_counts(np.full(px, lam), 16, np.random.default_rng(11))
    assert counts.shape == (px, 16)
    k = np.arange(8)
    want = np.append(poisson.pmf(k, lam), poisson.sf(k[-1], lam)) * counts.size
    observed = np.bincount(np.minimum(counts.ravel(), k[-1] + 1), minlength=k.size + 1)
    assert chisquare(observed, want).pvalue > 1e-4
    r = np.corrcoef(counts[:, 0], counts[:, 1])[0, 1]
    assert abs(r) < 4 / math.sqrt(px)
