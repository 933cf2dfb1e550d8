"""Sensor model: radiometry, RGGB, noise statistics, quantisation, saturation, packing, errors.

Statistical checks use fixed seeds, so they are deterministic; their bounds are set so that a
correct model would fail them with probability ≲ 1e-4 per comparison at a random seed:
  * means: within 4 standard errors, SE = σ / √n (σ from the model, n pixels of one channel);
  * variances, Gaussian data: (n − 1) s² / σ² inside the χ²(n − 1) quantiles 1e-6 and 1 − 1e-6;
  * variances, Poisson data (not normal): within 5 SE, Var(s²) = κ₄/n + 2κ₂²/(n − 1) from the
    cumulants (Poisson: every cumulant = λ; Gaussian read noise and rounding: κ₄ ≈ 0);
  * fractions: within 5 binomial standard errors.
Quantisation to integers adds 1/12 DN² to the variance (Sheppard), included where σ ≫ 1 DN.
Radiometric identities are checked to 1e-9 relative (float64 throughout).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

from udc_render.sensor import (
    CHANNELS,
    Capture,
    DefectConfig,
    SensorConfig,
    SensorError,
    capture,
    electrons_spectral,
    pack_rggb,
    sample_brooks,
    sensor_lambdas,
    unpack_rggb,
)

H_C = 6.62607015e-34 * 299792458.0
N_SIDE = 256  # flat fields: 256 × 256 mosaic, 16384 pixels per RGGB channel
BLACK = 4096


def flat_rgb(level: float, n: int = N_SIDE) -> np.ndarray:
    return np.full((3, n, n), level)


def channels(mosaic: np.ndarray) -> np.ndarray:
    """[4, n] samples of R, Gr, Gb, B."""
    return pack_rggb(mosaic).reshape(4, -1).astype(np.float64)


def assert_mean(x: np.ndarray, mu: float, sigma: float, what: str):
    se = sigma / math.sqrt(x.size)
    assert abs(x.mean() - mu) < 4 * se, f"{what}: mean {x.mean():.4f} vs model {mu:.4f} (4 SE = {4 * se:.4f})"


def assert_var_chi2(x: np.ndarray, var: float, what: str):
    n = x.size
    stat = (n - 1) * x.var(ddof=1) / var
    lo, hi = chi2.ppf([1e-6, 1 - 1e-6], n - 1)
    assert lo < stat < hi, (f"{what}: variance {x.var(ddof=1):.4f} vs model {var:.4f} (χ² {stat:.0f} not in "
                            f"[{lo:.0f}, {hi:.0f}])")


# ---------------------------------------------------------------- noise statistics


@pytest.mark.parametrize("level", [0.002, 0.02, 0.1, 0.4, 0.8])
def test_gaussian_flat_field_mean_and_variance(level):
    """DN = black + R (w + N(0, λ_read + λ_shot w)), per RGGB channel with its own λ."""
    lam_read, lam_shot = (1e-5, 2e-5, 3e-5, 4e-5), (1e-3, 5e-4, 2e-3, 1.5e-3)
    s = SensorConfig(form="per_channel", noise="gaussian", lambda_read=lam_read, lambda_shot=lam_shot,
                     black_level_dn=BLACK)
    cap = capture(flat_rgb(level), None, s, np.random.default_rng(11))
    R = s.range_dn
    for c, x in enumerate(channels(cap.mosaic_dn)):
        var = (lam_read[c] + lam_shot[c] * level) * R ** 2 + 1 / 12
        assert x.min() > 0 and x.max() < s.white_level_dn, "test levels must not clip"
        assert_mean(x, BLACK + level * R, math.sqrt(var), f"{CHANNELS[c]} at w={level}")
        assert_var_chi2(x, var, f"{CHANNELS[c]} at w={level}")
    assert np.allclose(cap.clean_dn, BLACK + level * R, rtol=1e-6)


def test_gaussian_goes_negative_near_zero_light():
    """At w = 0.002 with σ = sqrt(1e-5 + 2e-6) ≈ 0.0035 the Gaussian model puts Φ(−w/σ) ≈ 28 % of
    the pixels below the black level (negative signal): the pedestal keeps them, and the fraction
    matches the normal CDF within 5 binomial SE."""
    w, lr, ls = 0.002, 1e-5, 1e-3
    s = SensorConfig(form="per_channel", noise="gaussian", lambda_read=lr, lambda_shot=ls, black_level_dn=BLACK)
    x = channels(capture(flat_rgb(w), None, s, np.random.default_rng(5)).mosaic_dn).ravel()
    sigma = math.sqrt(lr + ls * w) * s.range_dn
    p = norm.cdf((-0.5 - w * s.range_dn) / sigma)  # DN < black ⇔ signal rounds below 0
    frac = np.mean(x < BLACK)
    assert frac > 0.2
    assert abs(frac - p) < 5 * math.sqrt(p * (1 - p) / x.size), (frac, p)


def test_gaussian_clipped_at_zero_without_black_level():
    """With black = 0 the negative half is clipped to 0 DN: mean = μΦ(μ/σ) + σφ(μ/σ) (the mean of a
    normal clipped at 0; rounding bias ≲ 1e-3 DN at σ ≈ 200 DN), the share of exact zeros
    Φ((0.5 − μ)/σ). Mean bound: 4 σ/√n (σ/√n exceeds the clipped SE, so this is conservative)."""
    w, lr, ls = 0.002, 1e-5, 1e-3
    s = SensorConfig(form="per_channel", noise="gaussian", lambda_read=lr, lambda_shot=ls, black_level_dn=0)
    x = channels(capture(flat_rgb(w), None, s, np.random.default_rng(6)).mosaic_dn).ravel()
    mu, sigma = w * s.range_dn, math.sqrt(lr + ls * w) * s.range_dn
    assert x.min() == 0
    assert_mean(x, mu * norm.cdf(mu / sigma) + sigma * norm.pdf(mu / sigma), sigma, "clipped mean")
    p0 = norm.cdf((0.5 - mu) / sigma)
    assert abs(np.mean(x == 0) - p0) < 5 * math.sqrt(p0 * (1 - p0) / x.size)


@pytest.mark.parametrize("level", [0.0005, 0.01, 0.1, 0.5, 0.9])
def test_poisson_flat_field_mean_and_variance(level):
    """Photon-exact model: e = level · FW electrons; DN mean = black + g e, variance = g²(e + σ_r²) + 1/12."""
    s = SensorConfig(form="per_channel", noise="poisson", black_level_dn=BLACK)
    cap = capture(flat_rgb(level), None, s, np.random.default_rng(21))
    g, e = s.dn_per_electron, level * s.full_well_e
    assert np.allclose(cap.electrons, e, rtol=1e-12)
    kappa2 = g ** 2 * (e + s.read_noise_e ** 2) + 1 / 12
    kappa4 = g ** 4 * e
    for c, x in enumerate(channels(cap.mosaic_dn)):
        n = x.size
        assert_mean(x, BLACK + g * e, math.sqrt(kappa2), f"{CHANNELS[c]} at {e:.1f} e-")
        se_var = math.sqrt(kappa4 / n + 2 * kappa2 ** 2 / (n - 1))
        assert abs(x.var(ddof=1) - kappa2) < 5 * se_var, f"{CHANNELS[c]}: {x.var(ddof=1):.2f} vs {kappa2:.2f}"


def test_poisson_near_zero_light_never_negative():
    """0.3 e⁻ per pixel, no read noise, 4 DN per e⁻: every pixel is black + 4k with k ≥ 0 (the
    Poisson model never goes below black), P(k = 0) = e^(−0.3), mean 0.3, variance 0.3 (5 SE).
    The Gaussian model with the equivalent λ ('sensor') puts ~29 % of the pixels below black."""
    e = 0.3
    s = SensorConfig(form="per_channel", noise="poisson", read_noise_e=0.0, conversion_gain_dn_per_e=4.0,
                     black_level_dn=100, white_level_dn=65535)
    x = channels(capture(flat_rgb(e * 4.0 / s.range_dn), None, s, np.random.default_rng(3)).mosaic_dn).ravel()
    assert x.min() >= 100 and np.all((x - 100) % 4 == 0)
    k = (x - 100) / 4
    n = k.size
    assert abs(np.mean(k == 0) - math.exp(-e)) < 5 * math.sqrt(math.exp(-e) * (1 - math.exp(-e)) / n)
    assert abs(k.mean() - e) < 4 * math.sqrt(e / n)
    assert abs(k.var(ddof=1) - e) < 5 * math.sqrt(e / n + 2 * e * e / (n - 1))
    sg = SensorConfig(form="per_channel", noise="gaussian", lambda_source="sensor", conversion_gain_dn_per_e=4.0,
                      read_noise_e=0.0, black_level_dn=100)
    lam_read, lam_shot = sensor_lambdas(sg)
    assert lam_read == 0 and math.isclose(lam_shot, 4.0 / sg.range_dn, rel_tol=1e-15)
    xg = channels(capture(flat_rgb(e * 4.0 / s.range_dn), None, sg, np.random.default_rng(3)).mosaic_dn).ravel()
    assert np.mean(xg < 100) > 0.2


@pytest.mark.parametrize("noise", ["poisson", "gaussian"])
def test_zero_light_gives_black_level_plus_read_noise(noise):
    """No light: mean = black (4 SE), σ = g σ_read (photon) or sqrt(λ_read) R (Gaussian), χ² bound."""
    s = SensorConfig(noise=noise, lambda_read=1e-7, black_level_dn=2048)
    cap = capture(np.zeros((30, N_SIDE, N_SIDE), np.float32), np.linspace(400, 700, 31), s, np.random.default_rng(8))
    var = ((s.dn_per_electron * s.read_noise_e) ** 2 if noise == "poisson" else 1e-7 * s.range_dn ** 2) + 1 / 12
    x = cap.mosaic_dn.astype(np.float64).ravel()
    assert np.all(cap.clean_dn == 2048)
    assert_mean(x, 2048, math.sqrt(var), "dark frame")
    assert_var_chi2(x, var, "dark frame")


# ---------------------------------------------------------------- extremes and quantisation


@pytest.mark.parametrize("noise", ["poisson", "gaussian", "none"])
@pytest.mark.parametrize("bits,white", [(16, None), (16, 60000), (12, None)])
def test_full_saturation_gives_white_level_exactly(noise, bits, white):
    s = SensorConfig(noise=noise, bit_depth=bits, white_level_dn=white, black_level_dn=64, lambda_read=1e-3,
                     lambda_shot=1e-2)
    cap = capture(np.full((30, 32, 32), 10.0), np.linspace(400, 700, 31), s, np.random.default_rng(1))
    assert np.all(cap.mosaic_dn == s.white_level_dn) and np.all(cap.clean_dn == s.white_level_dn)


@pytest.mark.parametrize("noise", ["poisson", "gaussian"])
def test_huge_gain_and_huge_radiance_clip_and_stay_finite(noise):
    """Gain 1e6 on a dim scene and a finite radiance of 1e300 (electrons overflow to inf): every
    pixel reads white, nothing wraps round to small values, nothing is NaN."""
    edges = np.linspace(400, 700, 31)
    for gain, level in ((1e6, 1e-4), (1.0, 1e300)):
        s = SensorConfig(noise=noise, gain=gain, lambda_read=1e-3, lambda_shot=1e-2)
        with np.errstate(over="ignore"):
            cap = capture(np.full((30, 16, 16), level), edges, s, np.random.default_rng(2))
        assert cap.mosaic_dn.dtype == np.uint16
        assert np.all(cap.mosaic_dn == 65535), (gain, level, cap.mosaic_dn.min())
        assert np.all(np.isfinite(cap.clean_dn)) and np.all(cap.clean_dn == 65535)


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_quantisation_is_integer_dn_in_range(bits):
    """Noisy data spanning both clips: uint16, integers in [0, 2^bits − 1], and both ends reached."""
    s = SensorConfig(form="per_channel", noise="gaussian", bit_depth=bits, lambda_read=1e-3, lambda_shot=1e-2)
    x = np.random.default_rng(0).uniform(0, 1.2, (3, 64, 64))
    cap = capture(x, None, s, np.random.default_rng(4))
    m = cap.mosaic_dn
    assert m.dtype == np.uint16 and m.min() == 0 and m.max() == 2 ** bits - 1
    assert cap.packed_dn.dtype == np.uint16 and cap.packed_dn.shape == (4, 32, 32)


# ---------------------------------------------------------------- radiometry


def hand_integral(wl, s, lo, hi):
    """∫_lo^hi S(λ) λ dλ of the linearly interpolated table (nm²): 2-point Gauss-Legendre on every
    table segment clipped to [lo, hi] (exact for the cubic-or-lower integrand)."""
    t = np.array([-1, 1]) / math.sqrt(3)
    nodes = np.unique(np.clip(np.concatenate([wl, [lo, hi]]), lo, hi))
    total = 0.0
    for a, b in zip(nodes[:-1], nodes[1:]):
        x = (a + b) / 2 + (b - a) / 2 * t
        total += (b - a) / 2 * np.sum(np.interp(x, wl, s, left=0, right=0) * x)
    return total


def test_radiometric_oracle_electrons_by_hand():
    """Two bands of constant radiance L1, L2 split at 523.3 nm (not a table node):
    e_c = π/(4N²) A t peak_qe/(hc) Σ L_i ∫_band S_c λ dλ · 1e-9, to 1e-9 relative; and the noise-free
    DN is black + g e exactly (well below the full well)."""
    import colour
    cam = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    wl, S = np.asarray(cam.wavelengths, float), np.asarray(cam.values, float).T
    S = S / S.max()
    s = SensorConfig(noise="none", f_number=2.2, exposure_s=0.01, pitch_um=1.55, peak_qe=0.55, black_level_dn=512)
    edges = np.array([372.0, 523.3, 790.0])
    L1, L2 = 3e-4, 7e-4
    img = np.empty((2, 6, 8))
    img[0], img[1] = L1, L2
    const = math.pi / (4 * 2.2 ** 2) * (1.55e-6) ** 2 * 0.01 * 0.55 / H_C * 1e-9
    expect = [const * (L1 * hand_integral(wl, S[c], 372.0, 523.3) + L2 * hand_integral(wl, S[c], 523.3, 790.0))
              for c in range(3)]
    cap = capture(img, edges, s, np.random.default_rng(0))
    e = pack_rggb(cap.electrons)
    for c, col in enumerate((0, 1, 1, 2)):
        assert np.allclose(e[c], expect[col], rtol=1e-9, atol=0), (CHANNELS[c], e[c, 0, 0], expect[col])
    assert 100 < min(expect) and max(expect) < s.full_well_e
    assert np.allclose(cap.clean_dn, 512 + s.dn_per_electron * cap.electrons, rtol=1e-6)  # float32 clean
    assert np.array_equal(cap.mosaic_dn, np.rint(512 + s.dn_per_electron * cap.electrons).astype(np.uint16))


def test_cos4_falloff_at_the_corner():
    """Corner pixel of an 8 × 8 mosaic at 1.55 µm, f = 20 µm: factor 1/(1 + r²/f²)², r = √2 · 3.5 p."""
    edges = np.linspace(400, 700, 31)
    img = np.full((30, 8, 8), 1e-3)
    flat = electrons_spectral(img, edges, SensorConfig())
    fall = electrons_spectral(img, edges, SensorConfig(cos4_falloff=True, focal_length_um=20.0))
    r2 = 2 * (3.5 * 1.55) ** 2
    assert math.isclose(fall[0, 0] / flat[0, 0], 1 / (1 + r2 / 400) ** 2, rel_tol=1e-12)
    assert math.isclose(fall[3, 3] / flat[3, 3], 1 / (1 + 2 * (0.5 * 1.55) ** 2 / 400) ** 2, rel_tol=1e-12)


@pytest.mark.parametrize("band,site", [((600, 700), (0, 0)), ((400, 480), (1, 1))])
def test_rggb_placement(band, site):
    """A red-only (600–700 nm) spectrum lights the R sites (0, 0) at least 5× more than any other;
    a blue-only (400–480 nm) one the B sites (1, 1) (Nikon 5100 ratios ≈ 9× and ≈ 4×–16×; 3× asserted for B vs G)."""
    edges = np.linspace(400, 700, 31)
    centres = (edges[:-1] + edges[1:]) / 2
    img = np.zeros((30, 8, 8))
    img[(centres > band[0]) & (centres < band[1])] = 1e-3
    e = electrons_spectral(img, edges, SensorConfig())
    sites = {(i, j): e[i::2, j::2].mean() for i in (0, 1) for j in (0, 1)}
    lit = sites.pop(site)
    assert all(lit > 3 * v for v in sites.values()), (lit, sites)
    assert sites.get((0, 1), 0) == sites.get((1, 0), 0)  # Gr and Gb share the green sensitivity


def test_csv_sensitivities_box_filters(tmp_path):
    """A CSV camera with box channels (R 600–700, G 500–600, B 400–500 nm): a 610–690 nm spectrum
    gives electrons at R sites only (exact zeros at G and B)."""
    wl = np.arange(380, 781, 1.0)
    rows = np.stack([wl, (wl > 600) & (wl < 700), (wl > 500) & (wl < 600), (wl > 400) & (wl < 500)], 1)
    path = tmp_path / "box.csv"
    np.savetxt(path, rows, delimiter=",", header="wavelength_nm,r,g,b", comments="")
    edges = np.array([610.0, 650.0, 690.0])
    e = electrons_spectral(np.full((2, 4, 4), 1e-3), edges, SensorConfig(camera=str(path)))
    assert np.all(e[0::2, 0::2] > 0) and np.all(e[0::2, 1::2] == 0) and np.all(e[1::2, :] == 0)


def test_input_pitch_binning_equals_block_mean():
    """A render at half the sensor pitch is block-averaged 2 × 2 before the mosaic."""
    edges = np.linspace(400, 700, 4)
    fine = np.random.default_rng(0).uniform(0, 1e-3, (3, 8, 12))
    coarse = fine.reshape(3, 4, 2, 6, 2).mean(axis=(2, 4))
    s = SensorConfig()
    assert np.allclose(electrons_spectral(fine, edges, s, input_pitch_um=0.775),
                       electrons_spectral(coarse, edges, s), rtol=1e-12)
    with pytest.raises(SensorError, match="input_pitch_um"):
        electrons_spectral(fine, edges, s, input_pitch_um=0.7)


# ---------------------------------------------------------------- packing, determinism, defects


def test_pack_unpack_round_trip_exact():
    m = np.random.default_rng(0).integers(0, 65536, (6, 8), dtype=np.uint16)
    p = pack_rggb(m)
    assert p.shape == (4, 3, 4) and p.dtype == np.uint16
    assert np.array_equal(p[0], m[0::2, 0::2]) and np.array_equal(p[1], m[0::2, 1::2])
    assert np.array_equal(p[2], m[1::2, 0::2]) and np.array_equal(p[3], m[1::2, 1::2])
    assert np.array_equal(unpack_rggb(p), m) and np.array_equal(pack_rggb(unpack_rggb(p)), p)


@pytest.mark.parametrize("shape", [(5, 8), (6, 7), (1, 2)])
def test_odd_sizes_rejected(shape):
    with pytest.raises(SensorError, match="even"):
        pack_rggb(np.zeros(shape))
    with pytest.raises(SensorError, match="even"):
        capture(np.zeros((3,) + shape), np.array([400.0, 500, 600, 700]), SensorConfig(), np.random.default_rng(0))


@pytest.mark.parametrize("noise,source", [("poisson", "fixed"), ("gaussian", "brooks")])
def test_determinism_with_a_seed(noise, source):
    s = SensorConfig(noise=noise, lambda_source=source)
    defects = DefectConfig(dead_fraction=0.01, hot_fraction=0.01)
    img = np.full((30, 16, 16), 1e-4)
    edges = np.linspace(400, 700, 31)
    a, b = (capture(img, edges, s, np.random.default_rng(7), defects=defects) for _ in range(2))
    c = capture(img, edges, s, np.random.default_rng(8), defects=defects)
    assert np.array_equal(a.mosaic_dn, b.mosaic_dn) and a.params == b.params
    assert not np.array_equal(a.mosaic_dn, c.mosaic_dn)
    # the recorded generator state regenerates the capture
    rng = np.random.default_rng()
    rng.bit_generator.state = a.params["rng_state_before"]
    assert np.array_equal(capture(img, edges, s, rng, defects=defects).mosaic_dn, a.mosaic_dn)


# ---------------------------------------------------------------- Brooks sampling


def test_brooks_sampling_distribution():
    """2000 draws. log λ_shot uniform on [log 1e-4, log 1.2e-2]: inside the range, mean within
    4 SE of the midpoint (SE = width/√12/√n). OLS of log λ_read on log λ_shot: slope 2.18 and
    intercept 1.20 within 4 standard errors computed from the draws (≈ ±0.017 and ±0.12);
    residual σ 0.26 within the χ²(n − 2) 1e-6 quantiles."""
    lam_read, lam_shot = sample_brooks(np.random.default_rng(2019), 2000)
    x, y = np.log(lam_shot), np.log(lam_read)
    lo, hi = math.log(1e-4), math.log(1.2e-2)
    n = x.size
    assert x.min() >= lo and x.max() <= hi
    assert abs(x.mean() - (lo + hi) / 2) < 4 * (hi - lo) / math.sqrt(12 * n)
    sxx = np.sum((x - x.mean()) ** 2)
    slope = np.sum((x - x.mean()) * (y - y.mean())) / sxx
    intercept = y.mean() - slope * x.mean()
    se_slope = 0.26 / math.sqrt(sxx)
    se_int = 0.26 * math.sqrt(1 / n + x.mean() ** 2 / sxx)
    assert abs(slope - 2.18) < 4 * se_slope, (slope, se_slope)
    assert abs(intercept - 1.20) < 4 * se_int, (intercept, se_int)
    resid = y - (intercept + slope * x)
    stat = np.sum(resid ** 2) / 0.26 ** 2
    assert chi2.ppf(1e-6, n - 2) < stat < chi2.ppf(1 - 1e-6, n - 2)


@pytest.mark.parametrize("per_channel", [False, True])
def test_brooks_parameters_recorded(per_channel):
    s = SensorConfig(form="per_channel", noise="gaussian", lambda_source="brooks", brooks_per_channel=per_channel)
    cap = capture(flat_rgb(0.2, 8), None, s, np.random.default_rng(0))
    r, sh = cap.params["lambda_read"], cap.params["lambda_shot"]
    assert len(r) == len(sh) == 4 and len(set(sh)) == (4 if per_channel else 1)
    assert all(1e-4 <= v <= 1.2e-2 for v in sh)


# ---------------------------------------------------------------- input and configuration errors


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("form", ["spectral", "per_channel"])
def test_nan_and_inf_input_rejected(bad, form):
    img = np.full((3, 4, 4), 1e-3)
    img[1, 2, 3] = bad
    with pytest.raises(SensorError, match=r"NaN or infinite.*\(1, 2, 3\)"):
        capture(img, np.array([400.0, 500, 600, 700]), SensorConfig(form=form), np.random.default_rng(0))


def test_negative_input_rejected_but_round_off_clamped():
    edges = np.array([400.0, 500, 600, 700])
    img = np.full((3, 4, 4), 1e-3)
    img[0, 0, 0] = -1e-9  # FFT round-off scale: clamped and counted
    cap = capture(img, edges, SensorConfig(noise="none"), np.random.default_rng(0))
    assert cap.params["negative_values_clamped"] == 1
    img[0, 0, 0] = -1e-4
    with pytest.raises(SensorError, match="negative"):
        capture(img, edges, SensorConfig(), np.random.default_rng(0))


@pytest.mark.parametrize("kwargs,field", [
    ({"f_number": 0.0}, "f_number"), ({"bit_depth": 17}, "bit_depth"), ({"black_level_dn": 65535}, "black_level_dn"),
    ({"white_level_dn": 5000, "bit_depth": 12}, "white_level_dn"), ({"noise": "salt"}, "noise"),
    ({"camera": "Nokia 3310"}, "camera"), ({"gamma_rggb": (1.0, 1.0, 1.0)}, "gamma_rggb"), ({"gain": True}, "gain"),
    ({"white_level_dn": 0}, "white_level_dn"), ({"lambda_shot": -1e-3}, "lambda_shot"),
    ({"peak_qe": 1.5}, "peak_qe"), ({"exposure_s": float("nan")}, "exposure_s")])
def test_config_errors_name_the_field(kwargs, field):
    with pytest.raises(SensorError) as err:
        SensorConfig(**kwargs)
    msg = str(err.value)
    assert msg.startswith(f"sensor.{field} = ") and "expected" in msg and "\n" not in msg


def test_config_from_dict_and_params_are_complete():
    s = SensorConfig.from_dict({"gain": 6, "gamma_rggb": [0.34, 0.34, 0.34, 0.2], "form": "per_channel"})
    assert s.gamma_rggb == (0.34, 0.34, 0.34, 0.2) and s.white_level_dn == 65535
    with pytest.raises(SensorError, match="sensor.iso = "):
        SensorConfig.from_dict({"iso": 100})
    cap = capture(flat_rgb(0.1, 4), None, s, np.random.default_rng(0))
    assert isinstance(cap, Capture)
    import json
    json.dumps(cap.params)
    assert cap.params["sensor"]["gain"] == 6 and cap.params["form"] == "per_channel"
    # γ form: electrons = γ_c x_c · FW at the default conversion gain; gain amplifies DN only
    assert np.allclose(pack_rggb(cap.electrons)[3], 0.2 * 0.1 * s.full_well_e, rtol=1e-12)
