"""DeP (restore.dep): gain on a T-OLED pair, finiteness, centring, padding, errors, determinism.

The T-OLED pair: the psf engine's T-OLED kernels at the packed planes' pitch (3.1 µm, 65 px), a
linear-RGB astronaut crop in [0, 0.8], blurred per packed channel by linear (non-wrapping)
convolution (computed on a frame larger by the kernel's half-width, then cropped), × γ = 0.97,
Poisson-Gaussian noise of variance λ_shot·x + λ_read (1e-3, 1e-6).
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from restore.dep import DENOISERS, DePError, centred_psf, denoise_plane, dep_restore, wiener_plane
from udc_render.metrics import psnr_db
from udc_render.sensor import demosaic_bilinear, mosaic_of, pack_rggb, unpack_rggb

GAMMA = 0.97
H, W = 128, 192  # packed plane size


@pytest.fixture(scope="module")
def toled():
    """(noisy packed [4, H, W], ground truth [3, 2H, 2W], kernels [4, 65, 65], noiseless blurred packed)."""
    import skimage.data

    from psf import Lens, compute_kernels, layouts
    k3 = compute_kernels(layouts.toled(pitch_um=60.0), Lens(), wavelengths_nm=[640, 520, 450], pixel_um=3.1,
                         size_px=65).kernels
    k4 = k3[[0, 1, 1, 2]].astype(np.float64)
    m = k4.shape[-1] // 2
    img = (skimage.data.astronaut()[40:40 + 2 * (H + 2 * m), :2 * (W + 2 * m)] / 255.0) ** 2.2 * 0.8
    big = pack_rggb(mosaic_of(np.moveaxis(img, -1, 0)))
    blur = GAMMA * np.stack([scipy.signal.fftconvolve(big[c], k4[c], mode="valid") for c in range(4)])
    rng = np.random.default_rng(0)
    shot, read = 1e-3, 1e-6
    noisy = shot * rng.poisson(np.clip(blur, 0, None) / shot) + np.sqrt(read) * rng.standard_normal(blur.shape)
    gt = np.moveaxis(img, -1, 0)[:, 2 * m:-2 * m, 2 * m:-2 * m]
    return noisy, gt, k4, blur


def test_dep_beats_the_degraded_input_on_toled(toled):
    noisy, gt, k4, _ = toled
    naive = psnr_db(demosaic_bilinear(unpack_rggb(noisy)) / GAMMA, gt)
    res = dep_restore(noisy, GAMMA, k4, rng=0)
    assert res.rgb.shape == (3, 2 * H, 2 * W) and res.rgb.dtype == np.float32
    assert res.denoiser == "nlm" and set(res.timings_s) >= {"denoise_s", "wiener_s", "demosaic_s", "total_s"}
    gain = psnr_db(res.rgb, gt) - naive
    assert gain > 3.0, f"DeP {gain:+.2f} dB over the bilinear-demosaiced input ({naive:.2f} dB)"


@pytest.mark.parametrize("kernel", [np.ones((4, 4)), np.ones((1, 9)), np.pad(np.ones((1, 9)), ((4, 4), (0, 0))),
                                    np.ones((33, 33))], ids=["box4", "row1x9", "row9x9", "box33"])
def test_finite_on_transfer_function_zeros(kernel):
    rng = np.random.default_rng(1)
    plane = rng.random((32, 48))
    for pad in (None, 0):
        out = wiener_plane(plane, kernel, rng=0, pad_px=pad)
        assert out.shape == plane.shape and np.isfinite(out).all()
    small = wiener_plane(rng.random((16, 16)), kernel, rng=0, pad_px=0)  # kernel larger than the plane
    assert np.isfinite(small).all()


@pytest.mark.parametrize("level", [0.0, 1.0, 3.0])
def test_constant_input_zero_and_saturated(level):
    packed = np.full((4, 16, 24), level)
    res = dep_restore(packed, 0.5, np.ones((3, 5, 5)), rng=0)
    assert np.isfinite(res.rgb).all()
    np.testing.assert_allclose(res.rgb, level / 0.5, rtol=1e-6)


def test_saturated_region_stays_finite(toled):
    noisy, _, k4, _ = toled
    clipped = np.minimum(noisy * 4, 1.0)  # a quarter of the frame at the white level
    assert (clipped == 1).mean() > 0.05
    assert np.isfinite(dep_restore(clipped, GAMMA, k4, denoiser="none", rng=0).rgb).all()


@pytest.mark.parametrize("size", [9, 10])
def test_no_shift_with_an_asymmetric_kernel(size):
    c = size // 2
    k = np.zeros((size, size))
    k[c, c], k[c, c + 3], k[c + 3, c - 2] = 0.5, 0.3, 0.2  # centre at size // 2, mass off to one side
    x = np.full((64, 80), 0.1)
    x[25, 47] = 1.0
    full = scipy.signal.fftconvolve(np.pad(x, size, mode="edge"), k, mode="full")  # y[i] = Σ_j k[j] x[i + c − j]
    y = full[c + size:c + size + 64, c + size:c + size + 80]
    out = wiener_plane(y, k, rng=0)
    assert np.unravel_index(np.argmax(out), out.shape) == (25, 47)
    for img, shifted in ((y, True), (out, False)):
        w = img[18:33, 40:55] - np.median(img)
        rows, cols = np.indices(w.shape)
        d = np.hypot((w * rows).sum() / w.sum() - 7, (w * cols).sum() / w.sum() - 7)
        assert (d > 0.5) if shifted else (d < 0.2), d


def test_centred_psf_wraps_large_kernels():
    k = np.arange(25.0).reshape(5, 5)
    p = centred_psf(k, (3, 4))
    assert p.sum() == k.sum() and p.shape == (3, 4)
    assert centred_psf(k, (8, 8))[4, 4] == k[2, 2]


def test_padding_reduces_the_error_at_the_edges(toled):
    noisy, _, k4, blur = toled
    m = k4.shape[-1] // 2
    import skimage.data
    img = (skimage.data.astronaut()[40:40 + 2 * (H + 2 * m), :2 * (W + 2 * m)] / 255.0) ** 2.2 * 0.8
    truth = pack_rggb(mosaic_of(np.moveaxis(img, -1, 0)))[1, m:-m, m:-m]
    edge = np.ones((H, W), bool)
    edge[16:-16, 16:-16] = False
    err = {pad: np.sqrt(np.mean((wiener_plane(noisy[1] / GAMMA, k4[1], rng=0, pad_px=pad) - truth)[edge] ** 2))
           for pad in (0, None)}
    assert err[None] < 0.7 * err[0], err


def test_errors_name_the_argument():
    good = np.zeros((4, 8, 8))
    k = np.ones((3, 3))
    cases = [(dict(packed=np.zeros((3, 8, 8))), "packed"), (dict(packed=np.zeros((4, 8))), "packed"),
             (dict(packed=np.full((4, 8, 8), np.nan)), "packed"), (dict(gamma_rggb=0.0), "gamma_rggb"),
             (dict(gamma_rggb=[1, -1, 1, 1]), "gamma_rggb"), (dict(gamma_rggb=[1, 1]), "gamma_rggb"),
             (dict(kernels_rggb=np.ones((2, 3, 3))), "kernels_rggb"), (dict(kernels_rggb=-k), "kernels_rggb"),
             (dict(denoiser="bm4d"), "denoiser"), (dict(boundary="wrap"), "boundary"), (dict(pad_px=-1), "pad_px")]
    for kw, name in cases:
        args = dict(packed=good + 0.1 * np.arange(8), gamma_rggb=1.0, kernels_rggb=k) | kw
        with pytest.raises(DePError, match=name):
            dep_restore(**args)
    with pytest.raises(DePError, match="sigma"):
        denoise_plane(np.random.default_rng(0).random((8, 8)), "nlm", sigma=-1)


def test_bm3d_missing_says_how_to_install(monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "bm3d", None)
    with pytest.raises(DePError, match=r"pip install udc-render\[bm3d\].*non-commercial"):
        denoise_plane(np.random.default_rng(0).random((16, 16)), "bm3d")


def test_denoisers_listed_run_or_say_what_is_missing():
    plane = np.random.default_rng(0).normal(0.5, 0.05, (32, 32))
    for name in DENOISERS:
        try:
            out = denoise_plane(plane, name)
        except DePError as e:
            assert "pip install" in str(e)
            continue
        assert out.shape == plane.shape and np.isfinite(out).all()
        if name != "none":
            assert np.std(out - 0.5) < np.std(plane - 0.5)


def test_deterministic_for_a_fixed_rng(toled):
    noisy, _, k4, _ = toled
    part = noisy[:, :48, :64]
    a = dep_restore(part, GAMMA, k4, rng=3).rgb
    b = dep_restore(part, GAMMA, k4, rng=np.random.default_rng(3)).rgb
    np.testing.assert_array_equal(a, b)
    c = dep_restore(part, GAMMA, k4, rng=4).rgb
    assert not np.array_equal(a, c) and np.abs(a - c).max() < 0.05
