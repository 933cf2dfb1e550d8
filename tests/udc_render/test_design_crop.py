"""The finite-crop restorability (udc_render.design.crop) and the designer's objective 'crop' and init 'toled'
(udc_render.design.optimise): oracles in closed form, limits, and the refusals."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from udc_render.design import crop, metrics
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import Designer
from udc_render.design.starts import toled_cell

TINY = dict(cell_um=200.0, feature_um=40.0, open_fraction=0.24, steps=2, pupil_samples=64, kernel_px=31, scatters=2,
            seed=3)


def test_the_posterior_mean_of_a_delta_kernel_on_the_whole_grid_is_the_wiener_filter():
    """S = 1: no margin, the crop is the whole (periodic) grid, and x̂ = F⁻¹[t P Y / (t² P + N)] in closed form."""
    variance, t, noise = 0.02, 0.3, 1e-3
    p = crop.crop_problem(48, 1, variance)
    y = torch.tensor(np.random.default_rng(0).normal(0.1, 0.2, (48, 48)))
    est = crop.posterior_mean(p, torch.ones((1, 1), dtype=torch.float64), t, noise, y).numpy()
    s = metrics.natural_spectrum(48, variance)
    ref = np.real(np.fft.ifft2(t * s * np.fft.fft2(y.numpy()) / (t * t * s + noise)))
    assert np.abs(est - ref).max() < 1e-10 * np.abs(ref).max()


@pytest.mark.slow  # CI time (20-min line): 20 s; a study-like claim
def test_a_kernel_reaching_past_the_crop_restores_it_worse_than_one_that_does_not():
    """The same energy split into a centre and copies 20 px away (a halo) against a delta: on a 24-px crop the
    halo's light comes from outside, the posterior mean's error rises above the delta's by more than the draw's
    spread (same draw, same transmission and noise)."""
    variance, t, noise = 0.25, 0.2, 5e-5
    delta, halo = np.zeros((41, 41)), np.zeros((41, 41))
    delta[20, 20] = 1.0
    halo[20, 20], halo[0, 20], halo[40, 20], halo[20, 0], halo[20, 40] = 0.2, 0.2, 0.2, 0.2, 0.2
    p = crop.crop_problem(24, 41, variance)
    x, w = crop.scene_draws(p, np.random.default_rng(1))
    errs = [crop.crop_mse(p, torch.tensor(k), t, noise, x, w) for k in (delta, halo)]
    assert errs[1] > 3 * errs[0]


def test_the_near_window_is_a_separable_triangle_of_half_the_crop():
    w = crop.near_window(9, 8)
    assert w[4, 4] == 1 and w[4, 6] == 0.5 and w[0, 4] == 0 and np.allclose(w, w[4][None, :] * w[:, 4][:, None])
    k = np.random.default_rng(0).random((9, 9))
    near, far = crop.split_kernel(k, w)
    assert np.allclose(near + far, k) and (far >= 0).all()


def test_interference_alone_leaves_the_prior_variance_and_no_interference_is_the_plain_wiener_error():
    s = metrics.natural_spectrum(16, 0.04)
    h = np.fft.fft2(np.random.default_rng(0).random((16, 16)))
    assert abs(metrics.wiener_mse(np.zeros((16, 16)), s, 1e-4, 0.5, h) - s.mean()) < 1e-15
    assert metrics.wiener_mse(h, s, 1e-4, 0.5, np.zeros((16, 16))) == metrics.wiener_mse(h, s, 1e-4, 0.5)


def test_the_crop_objective_tends_to_the_wiener_objective_for_a_crop_far_wider_than_the_kernel():
    cell = np.zeros((5, 5))
    cell[[0, 1, 3, 4, 2, 2], [0, 2, 4, 1, 3, 0]] = 1.0
    wiener = Designer(DesignConfig(**TINY)).score(cell)["objective"]
    crop = {**TINY, "objective": "crop", "contrast": 0.3}  # wiener's default contrast
    wide = Designer(DesignConfig(**{**crop, "crop_px": 10 ** 7})).score(cell)["objective"]
    narrow = Designer(DesignConfig(**{**crop, "crop_px": 8})).score(cell)["objective"]
    assert abs(wide / wiener - 1) < 1e-5 and narrow > 1.1 * wiener  # measured 1.23 ×


def test_the_toled_start_is_the_preset_slit_on_the_squares_at_the_tiles_edge():
    config = DesignConfig(init="toled")
    cell = toled_cell(config)
    cols = np.flatnonzero(cell.sum(axis=0))
    assert cell.sum() == config.open_squares == 88 and cols[0] == 0 and np.array_equal(cols, np.arange(len(cols)))
    assert len(cols) == 5 and np.array_equal(Designer(DesignConfig(**{**TINY, "init": "toled"})).cell,
                                             toled_cell(DesignConfig(**{**TINY, "init": "toled"})))


def _guide() -> str:
    root = Path(__file__).resolve().parents[2]
    return " ".join((root / "docs" / "guides" / "design.md").read_text(encoding="utf-8").split())


def _figures() -> Path:
    return Path(__file__).resolve().parents[2] / "docs" / "figures" / "design"


def test_the_guides_dep_rows_and_verdict_are_the_committed_studies():
    """docs/guides/design.md's DeP table of the `crop` design against the T-OLED and the P-OLED is the committed
    study JSONs' (same session), and its verdict (the miss against the T-OLED) is their difference."""
    text, mean = _guide(), {}
    for name in ("design", "toled168_20_edge", "poled_20", "design_crop128"):
        doc = json.loads((_figures() / "crop_studies" / name / "study_layout.json").read_text())
        for tiling in ("turned", "repeated"):
            r = doc["restored"][tiling]
            row = " / ".join(f"{v:.2f}" for v in r["psnr_db"]) + f" dB, {r['mean_psnr_db']:.2f}"
            assert row in text, row
        mean[name] = doc["restored"]["turned"]["mean_psnr_db"]
    miss = mean["toled168_20_edge"] - mean["design"]
    assert f"misses by {miss:.2f} dB" in text and miss > 0
    assert f"({mean['design']:.2f} against {mean['toled168_20_edge']:.2f} dB" in text
    second = mean["design_crop128"]
    assert f"misses by {mean['toled168_20_edge'] - second:.2f} dB ({second:.2f};" in text


def test_the_guides_diagnosis_rows_are_layout_crop_json():
    doc = json.loads((_figures() / "layout_crop" / "layout_crop.json").read_text())
    text = _guide()
    for name, rows in doc["astronaut"].items():
        for mode in ("dep", "dep_periodic", "mmse_finite", "wiener_periodic"):
            cells = " / ".join(f"{rows[c][mode]:.2f}" for c in ("192", "384", "512"))
            assert cells in text, (name, mode, cells)
    g = doc["gaussian"]["toled168_20@edge"]["1.0"]
    assert f"T-OLED {g['crop_objective']:.2f} against {g['mmse_finite']:.2f} dB exact" in text


@pytest.mark.parametrize("argv, contrast", [([], 0.3), (["--objective", "crop"], 1.0),
                                            (["--objective", "crop", "--contrast", "0.5"], 0.5),
                                            (["--objective", "upc"], 0.3)])
def test_the_contrast_defaults_per_objective(argv, contrast):
    """--contrast unset: 0.3 for wiener (and upc, which does not use it), 1.0 for crop (design.options), in the
    config the CLI builds."""
    from udc_render.cli import build_parser
    args = build_parser().parse_args(["design", *argv])
    assert DesignConfig(objective=args.objective, contrast=args.contrast).contrast == contrast
