"""The noise frames' fit (udc_render/fit/noise.py) against frames drawn here from the Gaussian model it fits,
var = λ_read + λ_shot w (normalised units), with known λ per RGGB channel, quantised to DN and clipped at 0
and at the white level: the stated ± 2 σ covers the truth in ≥ 0.9 of trials (two series of 4 and 2 frames:
a fit that counted N residuals instead of N − 1 degrees of freedom would state σ too small by √(N / (N − 1)),
√2 for the pair), pixels near the clips do not bias it, and a λ below 0 is held at 0 in both records or
refused."""
from __future__ import annotations

import numpy as np
import pytest

from udc_render.fit.inputs import FitError, Frame
from udc_render.fit.noise import fit_series, sensor_toml
from udc_render.sensor import SensorConfig
from udc_render.streams import stream

RGGB = np.array([[0, 1], [1, 2]], np.int8)
LAMBDA_READ = np.array([1.0, 1.2, 0.8, 1.5]) * 1e-7  # R, Gr, Gb, B: a read noise of ~5 e- at a 15 500 e- full well
LAMBDA_SHOT = np.array([6.4, 6.0, 7.0, 5.0]) * 1e-5
BLACK, WHITE = 16.0, 65535.0  # the black clip 0.8 σ_read below w = 0: the darkest pixels touch it


def _site_values(values: np.ndarray, shape) -> np.ndarray:
    """Per-pixel values of the channels (R, Gr, Gb, B) on an RGGB mosaic."""
    site = np.tile(np.array([[0, 1], [2, 3]]), (shape[0] // 2, shape[1] // 2))
    return np.asarray(values)[site]


def draw_series(rng, n_frames: int, shape=(64, 64), lam_read=LAMBDA_READ, lam_shot=LAMBDA_SHOT, black=BLACK,
                name="s") -> list[Frame]:
    """n_frames of one scene of 4 × 4-px blocks with w uniform in 0 … 1.03 (some beyond the white clip), each
    frame DN = round(black + span (w + σ(w) z)) clipped to 0 … WHITE, σ² = λ_read + λ_shot w."""
    span = WHITE - black
    blocks = rng.uniform(0.0, 1.03, (shape[0] // 4, shape[1] // 4))
    w = np.kron(blocks, np.ones((4, 4)))
    sd = np.sqrt(_site_values(lam_read, shape) + _site_values(lam_shot, shape) * w)
    frames = []
    for i in range(n_frames):
        dn = np.clip(np.rint(black + span * (w + sd * rng.standard_normal(shape))), 0, WHITE)
        frames.append(Frame(f"{name}{i}", dn, "cfa", RGGB, black, WHITE, 16))
    return frames


def truth_read(black=BLACK) -> np.ndarray:
    """λ_read with the quantisation's 1/12 DN² (Sheppard), in normalised units."""
    return LAMBDA_READ + 1.0 / (12.0 * (WHITE - black) ** 2)


def coverage(trials: int, seed: int) -> tuple[float, float, np.ndarray, np.ndarray]:
    """(share of λ_read within ± 2 σ, of λ_shot, the pulls of each [trials, 4])."""
    pr, ps = [], []
    for t in range(trials):
        rng = stream(seed, "noise-coverage", t)
        fit = fit_series([draw_series(rng, 4, name="a"), draw_series(rng, 2, name="b")], "trial")
        pr.append((fit.lambda_read - truth_read()) / fit.lambda_read_sigma)
        ps.append((fit.lambda_shot - LAMBDA_SHOT) / fit.lambda_shot_sigma)
    pr, ps = np.array(pr), np.array(ps)
    return float(np.mean(np.abs(pr) <= 2)), float(np.mean(np.abs(ps) <= 2)), pr, ps


def test_two_sigma_covers_the_truth_fast():
    """40 trials × 4 channels: ± 2 σ covers λ_read and λ_shot in ≥ 0.9 of them, and the pulls are unbiased
    (their mean within 0.25, 3.5 standard errors of 160 pulls)."""
    cr, cs, pr, ps = coverage(40, 1)
    assert cr >= 0.9 and cs >= 0.9, (cr, cs)
    assert abs(pr.mean()) < 0.25 and abs(ps.mean()) < 0.25, (pr.mean(), ps.mean())


@pytest.mark.slow
def test_two_sigma_covers_the_truth():
    """400 trials × 4 channels (~40 s on a loaded machine): coverage ≥ 0.9 for both λ (measured 0.985 and
    0.956), and λ_shot's pulls spread 0.92 … 1.08 (measured 0.99; their standard error 0.018): a fit that
    counted N degrees of freedom instead of N − 1 spreads them 1.12 and covers 0.93. λ_read's spread is not
    asked: held at 0 where it comes out below 0 (a sixth of the trials here), its pulls there are cut to
    − truth / σ (measured spread 0.83)."""
    cr, cs, pr, ps = coverage(400, 2)
    assert cr >= 0.9 and cs >= 0.9, (cr, cs)
    assert 0.92 < ps.std() < 1.08, ps.std()


def test_a_read_noise_of_zero_is_held_at_zero_in_both_records():
    """No read noise (λ_read = the quantisation's 2e-11 only): where the line's λ_read comes out below 0, it
    is fitted again at 0, noted, and sensor.toml says 0 as the fit does; λ_shot stays within 3 σ."""
    held = 0
    for t in range(12):
        rng = stream(3, "noise-zero", t)
        series = [draw_series(rng, 4, lam_read=np.zeros(4), name="a"), draw_series(rng, 4, lam_read=np.zeros(4))]
        fit = fit_series(series, "zero")
        assert np.all(fit.lambda_read >= 0)
        assert np.all(np.abs(fit.lambda_shot - LAMBDA_SHOT) < 3 * fit.lambda_shot_sigma)
        if fit.notes:
            held += 1
            assert "held at 0" in fit.notes[0] and np.any(fit.lambda_read == 0)
            toml = sensor_toml(fit, "frames")
            assert f"lambda_read = [{', '.join(f'{v:.6g}' for v in fit.lambda_read)}]" in toml
    assert held > 0


def test_a_wrong_black_level_is_refused(tmp_path):
    """Frames whose black is 2000 DN read as if it were 0: λ_read comes out far below 0 (λ_shot × 2000 DN
    of offset): refused in one line naming the channel and the value."""
    rng = stream(4, "noise-black")
    series = [[Frame(f.path, f.dn, "cfa", RGGB, 0.0, WHITE, 16) for f in draw_series(rng, 4, black=2000.0)]]
    with pytest.raises(FitError, match=r"lambda_read of channel R is -[0-9.e-]+ ± .*below 0 by") as e:
        fit_series(series, "--noise-frames x")
    assert "\n" not in str(e.value)


def test_sensor_toml_loads_with_the_fitted_values(tmp_path):
    fit = fit_series([draw_series(stream(5, "noise-toml"), 4)], "toml")
    (tmp_path / "sensor.toml").write_text(sensor_toml(fit, "frames"))
    s = SensorConfig.from_toml(tmp_path / "sensor.toml")
    assert s.lambda_read == pytest.approx(tuple(fit.lambda_read), rel=1e-5)
    assert s.lambda_shot == pytest.approx(tuple(fit.lambda_shot), rel=1e-5) and s.black_level_dn == BLACK
