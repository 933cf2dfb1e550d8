"""The scene statistics of a clean set (restore.studies.scene_statistics) against closed forms, and the study's."""
from __future__ import annotations

import numpy as np

from restore.studies.layout_trained import BUDGETS
from restore.studies.robustness import WHITE_FILL
from restore.studies.scene_statistics import image_statistics, scene_statistics


def test_a_sinusoid_over_whole_periods_has_its_closed_form_contrast():
    """μ + a cos(2π x / 16) on 64-px windows (whole periods, every 32 px): each window's variance is a² / 2, so the
    contrast is a / (√2 μ) exactly; its power lies at one radius, so it has no spectrum slope (NaN, without a
    warning: no log of a zero power)."""
    import warnings
    x = np.arange(256)
    image = 0.4 + 0.1 * np.cos(2 * np.pi * x / 16)[None, :] * np.ones((128, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = image_statistics([image], window_px=64)
    assert np.isnan(s["spectrum_slope"])
    assert abs(s["mean_level"] - 0.4) < 1e-12
    assert abs(s["contrast"] - 0.1 / (np.sqrt(2) * 0.4)) < 1e-12
    assert s["windows"] == 3 * 7


def test_a_power_law_field_has_its_slope():
    """White noise shaped by |ν|^(−p/2) has the periodogram slope −p (p = 2 and 3: within 0.1 over 16 fields)."""
    rng = np.random.default_rng(0)
    f = np.fft.fftfreq(256)
    radius = np.hypot(f[None, :], f[:, None])
    for p in (2.0, 3.0):
        shape = np.where(radius > 0, np.where(radius > 0, radius, 1.0) ** (-p / 2), 0.0)
        fields = [1 + 0.01 * np.fft.ifft2(np.fft.fft2(rng.standard_normal((256, 256))) * shape).real
                  for _ in range(16)]
        assert abs(image_statistics(fields)["spectrum_slope"] + p) < 0.1, p


def test_the_layout_trained_scene_is_what_the_design_guide_gives_the_objective():
    """The validation images of `study layout-trained` (colour dead leaves, palettes uniform on [0, WHITE_FILL)):
    the mean within 0.03 of the palettes' WHITE_FILL / 2, and the guide's `--contrast` and `--mean-level` are their
    contrast and mean to two decimals."""
    from pathlib import Path
    s = scene_statistics(BUDGETS["full"], "val")
    assert s["images"] == 8 and abs(s["mean_level"] - WHITE_FILL / 2) < 0.03
    text = (Path(__file__).resolve().parents[2] / "docs" / "guides" / "design.md").read_text(encoding="utf-8")
    assert f"--contrast {s['contrast']:.2f} --mean-level {s['mean_level']:.2f}" in text
    assert f"slope {s['spectrum_slope']:.2f}".replace("-", "−") in text
