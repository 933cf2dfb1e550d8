"""Optics stage: linear FFT convolution, centring, energy, field-dependent banding, input checks.

References are independent of udc_render.optics: scipy.signal.fftconvolve (mode='full', cropped by
hand), np.interp for the phase interpolation, psf.banding.banding_profile for the banding.
"""
import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.signal

from psf import compute_kernels, layouts
from psf.banding import SERIES_RTOL, PowerSeries, banding_profile
from psf.engine import KernelSet
from psf.lens import Lens
from udc_render.optics import OpticsError, apply_kernels, convolve_bands, fft_shape, field_power_map, phase_weights
from udc_render.optics.field import phase_basis
from udc_render.render import BandImage

PITCH = 12.4  # µm: 8 × the paper's 1.55 µm, so the banding period (360 µm) is ~29 px


def band_image(bands, margin, pitch=PITCH, edges=None):
    K = bands.shape[0]
    edges = np.linspace(400.0, 700.0, K + 1) if edges is None else np.asarray(edges, float)
    return BandImage(np.asarray(bands, np.float32), edges, pitch, margin, None)


def synthetic_set(kernels, wl, outside=None, trans=None, pitch=PITCH):
    K = kernels.shape[0]
    outside = np.zeros(K) if outside is None else np.asarray(outside, float)
    trans = np.ones(K) if trans is None else np.asarray(trans, float)
    return KernelSet(np.asarray(kernels), np.asarray(wl, float), pitch, outside, trans, np.ones(K),
                     {"distance_mm": 0.0})


def random_kernels(rng, K, S):
    k = rng.random((K, S, S)) ** 4  # asymmetric: a wrong flip or shift would show
    return k / k.sum(axis=(1, 2), keepdims=True)


def reference(bands, kernels, m):
    """fftconvolve(mode='full') cropped: frame pixel (i, j) ↔ full index (m + c + i, m + c + j)."""
    c = kernels.shape[-1] // 2
    H, W = bands.shape[-2:]
    return np.stack([scipy.signal.fftconvolve(b.astype(np.float64), k.astype(np.float64), mode="full")
                     [m + c:m + c + H - 2 * m, m + c:m + c + W - 2 * m] for b, k in zip(bands, kernels)])


# ------------------------------------------------------------------ convolution and centring


@pytest.mark.parametrize("precision,tol", [("float64", 1e-12), ("float32", 1e-6)])
def test_delta_gives_kernel_centred_on_it(precision, tol):
    rng = np.random.default_rng(0)
    S, m = 15, 7
    k = random_kernels(rng, 2, S)
    x = np.zeros((2, 64 + 2 * m, 48 + 2 * m))
    x[:, m + 20, m + 30] = 1.0                          # delta at frame pixel (row 20, col 30)
    y = convolve_bands(x, k, m, precision=precision)
    c = S // 2
    for b in range(2):
        np.testing.assert_allclose(y[b, 20 - c:20 + c + 1, 30 - c:30 + c + 1], k[b], atol=tol * k[b].max())
        rest = y[b].copy()
        rest[20 - c:20 + c + 1, 30 - c:30 + c + 1] = 0
        assert np.abs(rest).max() < tol * k[b].max()      # nothing anywhere else (1e-12 / 1e-6 of the peak)


@pytest.mark.parametrize("precision,tol", [("float64", 1e-10), ("float32", 1e-5)])
def test_equals_fftconvolve_full_cropped(precision, tol):
    rng = np.random.default_rng(1)
    S, m = 31, 20                                         # margin larger than the half-width
    k = random_kernels(rng, 3, S)
    x = rng.random((3, 90 + 2 * m, 70 + 2 * m))
    y = convolve_bands(x, k, m, precision=precision)
    ref = reference(x, k, m)
    assert y.dtype == np.dtype(precision)
    assert np.abs(y - ref).max() < tol * ref.max()


def test_no_wraparound_from_far_margin_edge():
    """Margin = half-width and an FFT as long as the grid: wrapped light must land only in the cropped
    margin. A spot on the outermost margin pixel reaches the near frame edge (the kernel's edge row)
    and nothing reaches the opposite side (< 1e-12 (float64) / 1e-6 (float32) of the kernel peak; a
    wrapped kernel would put up to the whole kernel there)."""
    rng = np.random.default_rng(2)
    S, m = 15, 7
    H = W = 64                                            # next_fast_len(64) = 64: no padding at all
    assert fft_shape((H, W), S, m) == (64, 64)
    k = random_kernels(rng, 1, S)
    x = np.zeros((1, H, W))
    x[0, 0, 0] = 1.0                                      # top-left corner of the margin
    y = convolve_bands(x, k, m, precision="float64")[0]
    assert y[0, 0] == pytest.approx(k[0, -1, -1], rel=1e-10)   # reaches the frame through its edge
    assert np.abs(y[1:, :]).max() < 1e-12 and np.abs(y[:, 1:]).max() < 1e-12
    x[0, 0, 0], x[0, -1, -1] = 0.0, 1.0                   # bottom-right corner of the margin
    y = convolve_bands(x, k, m, precision="float32")[0]
    tol = 1e-6 * k.max()
    assert y[-1, -1] == pytest.approx(k[0, 0, 0], abs=tol)
    assert np.abs(y[:-1, :]).max() < tol and np.abs(y[:, :-1]).max() < tol


def test_kernel_larger_than_frame_is_exact_and_larger_than_grid_is_rejected():
    rng = np.random.default_rng(3)
    S = 63
    k = random_kernels(rng, 1, S)
    x = rng.random((1, 8 + 2 * 31, 8 + 2 * 31))           # 8 × 8 frame, 70 × 70 grid, 63 px kernel
    y = convolve_bands(x, k, 31, precision="float64")
    np.testing.assert_allclose(y, reference(x, k, 31), rtol=1e-10, atol=1e-12)
    small = rng.random((1, 40, 40))                       # the grid itself is smaller than the kernel
    with pytest.raises(OpticsError, match=r"margin_px=10 .*kernel 63×63"):
        convolve_bands(small, k, 10)


def test_margin_too_small_rejected():
    k = random_kernels(np.random.default_rng(4), 1, 31)
    bi = band_image(np.ones((1, 80, 80)), margin=14)
    with pytest.raises(OpticsError, match=r"margin_px=14 .*half-width 15 \(kernel 31×31 px\)"):
        apply_kernels(bi, synthetic_set(k, [550.0]))


# ------------------------------------------------------------------ energy


@pytest.mark.parametrize("precision,tol", [("float64", 2e-7), ("float32", 2e-6)])
def test_energy_conserved_up_to_transmission(precision, tol):
    """Σ out = Σ in · T · transmittance · (1 − energy_outside) when the blurred image fits in the frame.
    (float64 tolerance set by the float32 result images: 6e-8 per value.)"""
    rng = np.random.default_rng(5)
    S, m, K = 21, 10, 3
    k = random_kernels(rng, K, S)
    x = np.zeros((K, 60 + 2 * m, 50 + 2 * m))
    x[:, m + 10:m + 50, m + 10:m + 40] = rng.random((K, 40, 30))   # zero border ≥ S//2 inside the frame
    T, trans, outside = np.array([0.9, 0.5, 0.2]), np.array([0.21, 0.2, 0.19]), np.array([0.05, 0.1, -0.01])
    r = apply_kernels(band_image(x, m), synthetic_set(k, [450, 550, 650], outside, trans), transmission=T,
                      precision=precision)
    gains = T * trans * (1 - outside)
    np.testing.assert_allclose(r.gains, gains, rtol=1e-15)
    np.testing.assert_allclose(r.images.sum(axis=(1, 2), dtype=np.float64), x.sum(axis=(1, 2)) * gains, rtol=tol)
    assert r.images.dtype == np.float32 and r.images.shape == (K, 60, 50)


def test_glass_uses_bare_aperture_with_unit_transmission():
    ks = compute_kernels(None, wavelengths_nm=[550.0], pixel_um=PITCH, size_px=15, pupil_samples=256,
                         precision="float64")
    x = np.zeros((1, 64, 64))
    x[0, 24:40, 24:40] = 1.0
    r = apply_kernels(band_image(x, 7), ks)
    assert ks.transmittance[0] == pytest.approx(1.0, abs=1e-12)  # measured 2e-16: no display, no loss
    assert r.gains[0] == pytest.approx(1 - ks.energy_outside[0], abs=1e-12)
    assert r.images.sum(dtype=np.float64) == pytest.approx(256 * r.gains[0], rel=1e-6)  # float32: 5e-8


# ------------------------------------------------------------------ field dependence and banding


@pytest.fixture(scope="module")
def toled_d1():
    """T-OLED 1 mm in front of the pupil, 8 × 8 field phases, 15 px kernels at 12.4 µm (~4 s)."""
    return compute_kernels(layouts.toled(pitch_um=60.0), wavelengths_nm=[520.0], pixel_um=PITCH, size_px=15,
                           distance_mm=1.0, field_phases=8, pupil_samples=256, precision="float64")


def flat_field(ks, frame=(33, 256), margin=7):
    x = np.ones((1, frame[0] + 2 * margin, frame[1] + 2 * margin))
    return band_image(x, margin, edges=[500.0, 540.0])


def harmonic_fit(values, x_um, period_um, n=3):
    """Least squares mean + n harmonics at a known period: (mean, amplitude of the first)."""
    cols = [np.ones_like(x_um)]
    for h in range(1, n + 1):
        cols += [np.cos(2 * np.pi * h * x_um / period_um), np.sin(2 * np.pi * h * x_um / period_um)]
    coef = np.linalg.lstsq(np.stack(cols, 1), values, rcond=None)[0]
    return coef[0], math.hypot(coef[1], coef[2])


@pytest.mark.parametrize("blend", ["source", "output"])
def test_flat_field_banding_period_and_amplitude(toled_d1, blend):
    """Bands at z_i p / d (spectrum peak within one FFT bin) with the amplitude of psf.banding's profile: as is
    for blend='output' (within 6e-4: measured 1.9e-4); times the mean kernel's MTF along x at the banding
    frequency for blend='source' (each point's power P(s) is spread by its PSF: the flat field is P ⊗ k; here
    the T-OLED's ±1 orders 4 px away give an MTF of 0.78; within 6 %: measured 2.9 %). Bilinear interpolation
    over 8 phases keeps sinc²(1/8) = 0.95 of the first harmonic."""
    ks = toled_d1
    z, p, d_um = ks.params["image_distance_um"], layouts.toled(pitch_um=60.0).pitch_x_um, 1000.0
    period_px = z * p / d_um / PITCH                      # 360 µm / 12.4 µm = 29.0 px
    r = apply_kernels(flat_field(ks), ks, precision="float64", blend=blend)
    assert r.applied["model"] == "field-dependent" and r.applied["periodic"] == [True, True]
    row = r.images[0, 16].astype(np.float64)              # frame height 33: row 16 is on the axis (y = 0)
    W = row.size
    spec = np.abs(np.fft.rfft(row - row.mean()))
    peak = int(np.argmax(spec[1:])) + 1
    assert abs(peak - W / period_px) <= 1.0               # within one FFT bin (expected 8.82)
    x_um = (np.arange(W) - (W - 1) / 2) * PITCH
    mean, a1 = harmonic_fit(row, x_um, period_px * PITCH)
    _, prof = banding_profile(layouts.toled(pitch_um=60.0), wavelength_nm=520.0, distance_mm=1.0, positions_um=x_um)
    pm, pa1 = harmonic_fit(prof, x_um, period_px * PITCH)
    assert pa1 / pm > 1e-4                                # there is banding to see
    expected = pa1 / pm
    if blend == "source":
        u = np.arange(ks.size_px) - ks.size_px // 2
        mtf = abs(np.sum(ks.kernels[0].sum(0) * np.exp(-2j * np.pi * u / period_px)))
        assert mtf < 0.9                                  # the smoothing is real, not a formality
        expected *= mtf
    assert a1 / mean == pytest.approx(expected, rel=0.06 if blend == "source" else 6e-4)


def test_output_blend_is_the_exact_power_series(toled_d1):
    """blend='output' on a flat field gives gain · P(s(x)) / P̄ at every pixel: psf.banding's whole series
    (not the kernel set's truncated one) at each pixel's shift, P̄ the mean over the phases; within the
    truncation's bound SERIES_RTOL · w_0 / P̄."""
    ks = toled_d1
    r = apply_kernels(flat_field(ks), ks, blend="output", precision="float64")
    assert r.applied["field_power"].startswith("exact series")
    z = ks.params["image_distance_um"]
    series = PowerSeries(layouts.toled(pitch_um=60.0), Lens(), 0.52, 1000.0)  # the fixture's default lens
    H, W = r.images.shape[1:]
    x_um = (np.arange(W) - (W - 1) / 2) * PITCH
    y_um = (np.arange(H) - (H - 1) / 2) * PITCH
    shifts = np.stack(np.broadcast_arrays(x_um[None, :], y_um[:, None]), -1) * 1000.0 / z
    mean_phases = series(ks.field_shifts_um).mean()
    expect = series(shifts) / mean_phases
    assert np.ptp(expect) > 1e-3                           # there are bands to get right
    bound = SERIES_RTOL * series.weights[series.ky.size // 2, series.kx.size // 2].real / mean_phases
    np.testing.assert_allclose(r.images[0], r.gains[0] * expect, rtol=0, atol=r.gains[0] * bound)


def test_output_blend_without_series_is_exact_interpolated_power(toled_d1):
    """Without the series (kernels made before it): blend='output' on a flat field gives gain · P
    interpolated linearly (periodically) between phases."""
    ks = replace(toled_d1, field_series=None)
    r = apply_kernels(flat_field(ks), ks, blend="output", precision="float64")
    assert r.applied["field_power"].startswith("the phases' powers")
    P = ks.field_power.shape[-1]
    p, z = layouts.toled(pitch_um=60.0).pitch_x_um, ks.params["image_distance_um"]
    H, W = r.images.shape[1:]
    x_um = (np.arange(W) - (W - 1) / 2) * PITCH
    y_um = (np.arange(H) - (H - 1) / 2) * PITCH
    sx, sy = np.mod(x_um * 1000 / z, p), np.mod(y_um * 1000 / z, p)
    grid = np.arange(P + 1) * p / P
    fp = np.concatenate([ks.field_power[0], ks.field_power[0][:1]], 0)
    fp = np.concatenate([fp, fp[:, :1]], 1)                # periodic closure [P+1, P+1]
    along_x = np.stack([np.interp(sx, grid, fp[j]) for j in range(P + 1)])      # [P+1, W]
    expect = np.stack([np.interp(sy, grid, along_x[:, i]) for i in range(W)], 1)  # [H, W]
    np.testing.assert_allclose(r.images[0], r.gains[0] * expect, rtol=1e-6)


def test_field_source_blend_conserves_energy(toled_d1):
    ks = toled_d1
    m = 7
    x = np.zeros((1, 60 + 2 * m, 90 + 2 * m))
    x[0, m + 10:m + 50, m + 10:m + 80] = np.random.default_rng(6).random((40, 70))
    r = apply_kernels(band_image(x, m, edges=[500.0, 540.0]), ks, precision="float64")
    H, W = x.shape[1:]
    p, z = layouts.toled(pitch_um=60.0).pitch_x_um, ks.params["image_distance_um"]
    wx = phase_weights((np.arange(W) - (W - 1) / 2) * PITCH, ks.field_shifts_um[0, :, 0], 1000.0, z, p, True)
    wy = phase_weights((np.arange(H) - (H - 1) / 2) * PITCH, ks.field_shifts_um[:, 0, 1], 1000.0, z, p, True)
    power = field_power_map(ks, (H, W), PITCH, 1.0, z, (p, p)).band(0, np.float64)  # P(s(x)) at every source pixel
    assert np.abs(wx.sum(0) - 1).max() < 1e-12 and np.abs(wy.sum(0) - 1).max() < 1e-12  # the blend adds no power
    # float32 images: each value rounded once, unbiased, so the sum's error averages down (measured 1.6e-10
    # relative over 6300 values; 5e-9 asserted); the modulation itself is 7.6e-6 (asserted > 100× that)
    total = r.images.sum(dtype=np.float64)
    assert total == pytest.approx(r.gains[0] * (x[0] * power).sum(), rel=5e-9)
    assert abs(total / (r.gains[0] * x.sum()) - 1) > 5e-7


def test_no_banding_at_zero_distance():
    ks = compute_kernels(layouts.toled(pitch_um=60.0), wavelengths_nm=[520.0], pixel_um=PITCH, size_px=15,
                         distance_mm=0.0, pupil_samples=256)
    assert ks.field_kernels is None
    r = apply_kernels(flat_field(ks), ks)
    assert r.applied["model"] == "field-independent"
    img = r.images[0].astype(np.float64)
    assert (img.max() - img.min()) / img.mean() < 1e-6
    assert img.mean() == pytest.approx(r.gains[0], rel=1e-6)


def test_phase_weights_periodic_and_clamped():
    P, p = 4, 60.0
    shifts = np.arange(P) * p / P
    s = np.array([0.0, 7.5, 52.5, 60.0, -7.5])            # with d = z_i, x = s
    w = phase_weights(s, shifts, 1.0, 1.0, p, periodic=True)
    np.testing.assert_allclose(w.sum(0), 1.0, rtol=1e-15)
    np.testing.assert_allclose(w[:, 2], [0.5, 0, 0, 0.5])   # between the last phase and the first (wrap)
    np.testing.assert_allclose(w[:, 3], [1, 0, 0, 0])       # one whole period later: phase 0
    np.testing.assert_allclose(w[:, 4], [0.5, 0, 0, 0.5])
    span = np.array([-15.0, -5.0, 5.0, 15.0])
    w = phase_weights(np.array([-100.0, 0.0, 100.0]), span, 1.0, 1.0, p, periodic=False)
    np.testing.assert_allclose(w.T, [[1, 0, 0, 0], [0, 0.5, 0.5, 0], [0, 0, 0, 1]])


# ------------------------------------------------------------------ precision and input checks


def test_float32_matches_float64(toled_d1):
    rng = np.random.default_rng(7)
    x = rng.random((1, 47, 120))
    bi = band_image(x, 7, edges=[500.0, 540.0])
    for ks in (toled_d1, synthetic_set(random_kernels(rng, 1, 15), [520.0])):
        a = apply_kernels(bi, ks, precision="float32").images.astype(np.float64)
        b = apply_kernels(bi, ks, precision="float64").images.astype(np.float64)
        assert np.abs(a - b).max() < 2e-6 * np.abs(b).max()  # measured 3.3e-7, 2.9e-7 (float32 rounding)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_rejected_naming_the_band(bad):
    x = np.ones((3, 40, 40))
    x[1, 5, 5] = bad
    k = random_kernels(np.random.default_rng(8), 3, 15)
    with pytest.raises(OpticsError, match=r"band 550 nm \(index 1\) holds 1 NaN or infinite"):
        apply_kernels(band_image(x, 7), synthetic_set(k, [450, 550, 650]))


def test_pitch_mismatch_rejected():
    k = random_kernels(np.random.default_rng(9), 1, 15)
    bi = band_image(np.ones((1, 40, 40)), 7, pitch=PITCH * (1 + 1e-5))
    with pytest.raises(OpticsError, match=r"kernel pixel 12.4 µm differs from the band image pitch"):
        apply_kernels(bi, synthetic_set(k, [550.0]))
    ok = band_image(np.ones((1, 40, 40)), 7, pitch=PITCH * (1 + 1e-7))  # within 1e-6 relative
    assert apply_kernels(ok, synthetic_set(k, [550.0])).images.shape == (1, 26, 26)


@pytest.mark.parametrize("blend", ["source", "output"])
def test_field_rank_full_is_exact_and_lower_ranks_err_within_their_kernel_residual(toled_d1, blend):
    """A rank-r basis of the phase kernels: at r = the number of phases it reproduces the exact field
    blur (float64 round-off); below, the image error stays within a few times the kernel residual it
    records, and falls as r grows."""
    m = 7
    x = np.zeros((1, 60 + 2 * m, 90 + 2 * m))
    x[0, m:-m, m:-m] = np.random.default_rng(7).random((60, 90))
    bi = band_image(x, m, edges=[500.0, 540.0])
    exact = apply_kernels(bi, toled_d1, precision="float64", blend=blend).images.astype(np.float64)
    full = apply_kernels(bi, toled_d1, precision="float64", blend=blend, field_rank=64)
    np.testing.assert_allclose(full.images, exact, rtol=1e-5, atol=1e-6 * exact.max())
    errors = []
    for r in (1, 2, 4):
        res = apply_kernels(bi, toled_d1, precision="float64", blend=blend, field_rank=r)
        err = np.sqrt(np.mean((res.images - exact) ** 2)) / np.sqrt(np.mean(exact ** 2))
        assert res.applied["field_rank"] == r and err <= 3 * res.applied["field_rank_kernel_residual"] + 1e-7
        errors.append(err)
    assert errors[0] > errors[1] > errors[2]


def test_phase_basis_reconstructs_its_kernels(toled_d1):
    rng = np.random.default_rng(3)
    base = rng.random((3, 9, 9))
    kernels = np.einsum("qr,rij->qij", rng.random((16, 3)), base)  # rank 3 exactly
    b, c, residual = phase_basis(kernels, 3)
    np.testing.assert_allclose(np.einsum("qr,rij->qij", c, b), kernels, rtol=1e-9, atol=1e-12)
    assert residual < 1e-7
    _, _, r1 = phase_basis(kernels, 1)
    assert 0 < r1 < 1
    with pytest.raises(OpticsError, match="field rank = 0: expected a whole number"):
        apply_kernels(band_image(np.ones((1, 20, 20)), 7, edges=[500.0, 540.0]), toled_d1, field_rank=0)


# ------------------------------------------------------------------ channel sums in Fourier space


@pytest.mark.parametrize("precision,tol", [("float64", 3e-7), ("float32", 2e-6)])  # images are stored float32
def test_channel_sums_equal_the_weighted_sum_of_blurred_bands(precision, tol):
    """channel_weights w [C, K]: Σ_k w_ck y_k summed in Fourier space (C inverse FFTs) equals the sum of
    the K blurred bands, with the band spectra computed here or shared (band_spectra)."""
    from udc_render.optics import band_spectra
    rng = np.random.default_rng(11)
    K, S, m = 4, 9, 6
    x = rng.random((K, 40 + 2 * m, 52 + 2 * m))
    ks = synthetic_set(random_kernels(rng, K, S), [420.0, 500.0, 580.0, 660.0], trans=[0.9, 0.8, 0.7, 0.6])
    w = rng.random((3, K)) * (rng.random((3, K)) > 0.3)  # some zero weights: skipped terms
    bi = band_image(x, m)
    per_band = apply_kernels(bi, ks, 0.5, precision).images.astype(np.float64)
    want = np.einsum("ck,khw->chw", w, per_band)
    spectra = band_spectra(bi.bands, S, m, precision)
    for shared in (None, spectra):
        got = apply_kernels(bi, ks, 0.5, precision, channel_weights=w, spectra=shared)
        assert got.images.shape == (3, 40, 52) and got.applied["output"].startswith("channel sums")
        np.testing.assert_allclose(got.images, want, rtol=0, atol=tol * np.abs(want).max())
    with pytest.raises(OpticsError, match="channel_weights: shape"):
        apply_kernels(bi, ks, channel_weights=w[:, :2])


def test_field_channel_sums_equal_the_weighted_sum_of_blurred_bands(toled_d1):
    """The same on the field-dependent path (blend 'source', exact and rank 2); 'output' is refused."""
    m = 7
    x = np.random.default_rng(5).random((1, 50 + 2 * m, 70 + 2 * m))
    bi = band_image(x, m, edges=[500.0, 540.0])
    w = np.array([[0.2], [1.0], [0.5]])
    for rank in (None, 2):
        per_band = apply_kernels(bi, toled_d1, precision="float64", field_rank=rank).images
        got = apply_kernels(bi, toled_d1, precision="float64", field_rank=rank, channel_weights=w).images
        np.testing.assert_allclose(got, w[:, :, None, None][:, 0] * per_band, rtol=0, atol=3e-7 * per_band.max())
    with pytest.raises(OpticsError, match="channel_weights need blend='source'"):
        apply_kernels(bi, toled_d1, blend="output", channel_weights=w)
