"""DeP, the paper's deconvolution baseline: per packed RAW channel denoise → ÷ γ → unsupervised
Wiener-Hunt deconvolution with the known kernel → RGGB mosaic → bilinear demosaic (clipped at 0).

Denoisers (DENOISERS): 'nlm' (default; skimage denoise_nl_means, fast mode, patch 5, distance 6,
h = 0.8 σ), 'wavelet' (skimage denoise_wavelet, BayesShrink, soft; needs PyWavelets), 'bm3d' (the
paper's; the optional `bm3d` package, licensed for non-commercial use only: `pip install
udc-render[bm3d]`), 'none'. σ per plane: estimate_sigma unless given. The noise is heteroscedastic
(λ_shot·x + λ_read); a generalized Anscombe transform before NLM gained 1.3–3 dB on the planes but
0.07–0.15 dB after deconvolution (T-OLED, λ_shot 1e-3 and 1e-2), so it is not used.

Deconvolution: skimage.restoration.unsupervised_wiener (Orieux, Giovannelli & Rodet, JOSA A 27,
1593, 2010; Gibbs sampler, stochastic, seeded by `rng`) with a first-difference prior (PRIORS). It
assumes circular convolution. Boundary convention: each plane is padded by pad_px (default half the
kernel, at most MAX_PAD_PX) plus up to a fast FFT length by repeating the edge pixels ('edge'), the
padding is then replaced by values consistent with circular blur (consistent_fill), and the result is
cropped back. The kernel is passed as an impulse response folded onto the padded grid, its centre
(size // 2 per axis, the psf package's convention) at the grid centre: skimage keeps only the real
part of a transfer function it is given (scikit-image issue #7363) and cannot take a kernel larger
than the image.

Measured (benchmarks/bench_dep.py, T-OLED pair, planes 256 × 512, 129-px kernels, 2 shared cores;
naive input 15.97 dB): nlm 18.55 dB, wavelet 18.44, bm3d 18.63 (61 s of denoising for 4 planes),
none 18.35; nlm costs ≈ 0.3 s per plane. Plain padding (symmetric, reflect, edge, taper to the mean)
without the fill: 13.4–16.8 dB; with it: 18.33–18.42 whatever the padding; no padding: 8.4 to 18.6 dB
depending on where the kernel's transfer-function zeros fall on the FFT grid. Laplacian prior: 17.21.
"""
from __future__ import annotations

import importlib.util
import time
from dataclasses import dataclass, field

import numpy as np

from udc_render.errors import UdcError
from udc_render.sensor import demosaic_bilinear, unpack_rggb

DENOISERS = ("nlm", "wavelet", "bm3d", "none")
BOUNDARIES = ("reflect", "symmetric", "edge", "taper")
PRIORS = ("gradient", "laplacian")
MAX_PAD_PX = 128
FILL_ITERATIONS = 30
FILL_LAMBDA = 1e-2
_DB2_HIGH = np.array([-0.48296291314469025, 0.836516303737469, -0.22414386804185735, -0.12940952255092145])


class DePError(UdcError):
    """A bad DeP argument; one line naming the argument, its value and what is allowed."""


@dataclass
class DePResult:
    """rgb [3, 2h, 2w] float32 linear camera RGB; the denoiser that ran and the noise std it was given
    per packed channel (0 for 'none'), the padding, and each step's time in seconds."""
    rgb: np.ndarray
    denoiser: str
    sigma: tuple
    pad_px: int
    boundary: str
    timings_s: dict = field(default_factory=dict)


def estimate_sigma(plane: np.ndarray) -> float:
    """Gaussian noise std of a plane: median |d| / 0.6745 over the finest diagonal db2 wavelet
    coefficients d (Donoho & Johnstone 1994; skimage's estimate_sigma, without PyWavelets)."""
    from scipy.ndimage import correlate1d
    d = correlate1d(_plane(plane, "plane"), _DB2_HIGH, axis=0, mode="mirror")
    d = correlate1d(d, _DB2_HIGH, axis=1, mode="mirror")
    return float(np.median(np.abs(d[1::2, 1::2])) / 0.6744897501960817)


def denoise_plane(plane: np.ndarray, denoiser: str = "nlm", sigma: float | None = None) -> np.ndarray:
    """One plane denoised by `denoiser` (DENOISERS) for Gaussian noise of std `sigma` (None: estimated)."""
    x = _plane(plane, "plane")
    if denoiser not in DENOISERS:
        raise DePError(f"denoiser = {denoiser!r}: expected one of {', '.join(DENOISERS)}")
    if denoiser == "none":
        return x
    from skimage.restoration import denoise_nl_means, denoise_wavelet
    s = estimate_sigma(x) if sigma is None else float(sigma)
    if not np.isfinite(s) or s < 0:
        raise DePError(f"sigma = {sigma!r}: expected a finite number ≥ 0 or None")
    if s == 0:
        return x
    if denoiser == "nlm":
        return denoise_nl_means(x, patch_size=5, patch_distance=6, h=0.8 * s, sigma=s, fast_mode=True)
    if denoiser == "wavelet":
        if importlib.util.find_spec("pywt") is None:  # skimage's wavelet denoiser needs it; not a dependency
            raise DePError("denoiser = 'wavelet': PyWavelets is not installed: pip install PyWavelets")
        return denoise_wavelet(x, sigma=s, method="BayesShrink", mode="soft", rescale_sigma=True)
    try:
        import bm3d
    except ImportError:
        raise DePError("denoiser = 'bm3d': the bm3d package is not installed: pip install udc-render[bm3d] "
                       "(licensed for non-commercial use only)") from None
    return np.asarray(bm3d.bm3d(x, sigma_psd=s), np.float64)


def _plane(a, name: str) -> np.ndarray:
    x = np.asarray(a, dtype=np.float64)
    if x.ndim != 2 or min(x.shape) < 2:
        raise DePError(f"{name}: shape {x.shape}: expected a 2-D plane of at least 2 × 2")
    if not np.isfinite(x).all():
        raise DePError(f"{name}: {int((~np.isfinite(x)).sum())} non-finite values: expected finite numbers")
    return x


def _kernel(a, name: str) -> np.ndarray:
    k = np.asarray(a, dtype=np.float64)
    if k.ndim != 2 or k.size == 0:
        raise DePError(f"{name}: shape {k.shape}: expected a 2-D kernel")
    if not np.isfinite(k).all() or (k < 0).any() or k.sum() <= 0:
        raise DePError(f"{name}: expected finite values ≥ 0 with a positive sum (it is normalised to 1)")
    return k / k.sum()


def centred_psf(kernel: np.ndarray, shape: tuple) -> np.ndarray:
    """The kernel on a grid of `shape`, centre (size // 2) at shape // 2, wrapped circularly if larger."""
    out = np.zeros(shape)
    rows = (np.arange(kernel.shape[0]) - kernel.shape[0] // 2 + shape[0] // 2) % shape[0]
    cols = (np.arange(kernel.shape[1]) - kernel.shape[1] // 2 + shape[1] // 2) % shape[1]
    np.add.at(out, (rows[:, None], cols[None, :]), kernel)
    return out


def pad_plane(x: np.ndarray, widths, boundary: str) -> np.ndarray:
    """x padded by np.pad `widths` in the `boundary` convention (BOUNDARIES); 'taper': symmetric padding
    blended to the plane's mean by a raised cosine that reaches it at the outer edge."""
    if boundary != "taper":
        return np.pad(x, widths, mode=boundary)
    (top, bottom), (left, right) = np.broadcast_to(np.asarray(widths), (2, 2))

    def ramp(n, lo, hi):
        return np.concatenate([0.5 - 0.5 * np.cos(np.pi * np.arange(lo) / max(lo, 1)), np.ones(n),
                               0.5 - 0.5 * np.cos(np.pi * np.arange(hi, 0, -1) / max(hi, 1))])
    m = x.mean()
    weight = ramp(x.shape[0], top, bottom)[:, None] * ramp(x.shape[1], left, right)[None, :]
    return m + (np.pad(x, widths, mode="symmetric") - m) * weight


def _gradient_reg(shape: tuple) -> np.ndarray:
    """Transfer function R, |R|² = |1 − e^{−iω_y}|² + |1 − e^{−iω_x}|² (first differences), rfft layout."""
    wy = 2 * np.pi * np.fft.fftfreq(shape[0])[:, None]
    wx = 2 * np.pi * np.fft.rfftfreq(shape[1])[None, :]
    return np.sqrt(4 - 2 * np.cos(wy) - 2 * np.cos(wx)).astype(np.complex128)


def consistent_fill(padded: np.ndarray, inner: tuple, kernel: np.ndarray, iterations: int,
                    lam: float = FILL_LAMBDA) -> np.ndarray:
    """The padding (outside the `inner` slices) made consistent with circular blur, the data kept:
    solve M (I − G) (d + u) = 0 for the padding u by conjugate gradients (`iterations` steps; M masks
    the padding, d is the data), where G = H · H* / (|H|² + lam |R|²) re-blurs the Wiener estimate
    (a fixed point of "deconvolve, re-blur, keep the data": missing-data EM with the prior held fixed)."""
    H = np.fft.rfft2(np.fft.ifftshift(centred_psf(kernel, padded.shape)))
    keep = 1 - np.abs(H) ** 2 / (np.abs(H) ** 2 + lam * np.abs(_gradient_reg(padded.shape)) ** 2)  # I − G
    mask = np.ones(padded.shape)
    mask[inner] = 0
    data = padded * (1 - mask)
    u = padded * mask

    def a(v):
        return mask * np.fft.irfft2(np.fft.rfft2(v) * keep, s=v.shape)
    r = -a(data + u)
    p, rr = r.copy(), float((r * r).sum())
    for _ in range(iterations):
        ap = a(p)
        pap = float((p * ap).sum())
        if pap <= 0 or rr == 0:
            break
        u += rr / pap * p
        r -= rr / pap * ap
        rr, rr_old = float((r * r).sum()), rr
        p = r + rr / rr_old * p
    return data + u


def _wiener_args(pad_px, kernel_shape, boundary, fill_iterations, prior) -> int:
    """The padding in pixels (pad_px, or None: min(kernel size // 2, MAX_PAD_PX)); checks the rest."""
    p = min(max(kernel_shape) // 2, MAX_PAD_PX) if pad_px is None else pad_px
    if not isinstance(p, (int, np.integer)) or isinstance(p, bool) or p < 0:
        raise DePError(f"pad_px = {pad_px!r}: expected an integer ≥ 0 or None")
    if boundary not in BOUNDARIES:
        raise DePError(f"boundary = {boundary!r}: expected one of {', '.join(BOUNDARIES)}")
    if not isinstance(fill_iterations, (int, np.integer)) or isinstance(fill_iterations, bool) or fill_iterations < 0:
        raise DePError(f"fill_iterations = {fill_iterations!r}: expected an integer ≥ 0")
    if prior not in PRIORS:
        raise DePError(f"prior = {prior!r}: expected one of {', '.join(PRIORS)}")
    return int(p)


def wiener_plane(plane: np.ndarray, kernel: np.ndarray, rng=None, pad_px: int | None = None,
                 boundary: str = "edge", fill_iterations: int = FILL_ITERATIONS,
                 prior: str = "gradient") -> np.ndarray:
    """Unsupervised Wiener-Hunt deconvolution of one plane by `kernel` (unit sum, centre at size // 2).

    The plane is padded by pad_px (None: min(kernel size // 2, MAX_PAD_PX)) plus up to a fast FFT length
    in the `boundary` convention (BOUNDARIES), the padding made consistent with circular blur
    (consistent_fill, fill_iterations), deconvolved, and cropped back. prior: 'gradient' (first
    differences, |R|² ∝ ω² at low ω: the 1/f² spectrum of natural images) or 'laplacian' (skimage's
    default, |R|² ∝ ω⁴: too weak at the low frequencies where the T-OLED kernel has zeros).
    """
    from scipy.fft import next_fast_len
    from skimage.restoration import unsupervised_wiener
    x = _plane(plane, "plane")
    k = _kernel(kernel, "kernel")
    p = _wiener_args(pad_px, k.shape, boundary, fill_iterations, prior)
    if np.ptp(x) == 0:
        return x  # a constant plane is its own deconvolution (unit-sum kernel); the sampler divides by 0
    extra = [next_fast_len(max(n + 2 * p, 8), real=True) - n - 2 * p for n in x.shape]
    padded = pad_plane(x, ((p, p + extra[0]), (p, p + extra[1])), boundary)
    inner = (slice(p, p + x.shape[0]), slice(p, p + x.shape[1]))
    if fill_iterations and (p or any(extra)):
        padded = consistent_fill(padded, inner, k, int(fill_iterations))
    reg = _gradient_reg(padded.shape) if prior == "gradient" else None
    out, _ = unsupervised_wiener(padded, centred_psf(k, padded.shape), reg=reg, clip=False,
                                 rng=np.random.default_rng(rng))
    return out[inner]


def _four(a, name: str, trailing: int) -> np.ndarray:
    """[4, ...] per packed channel (R, Gr, Gb, B) from 1 (shared), 3 (R, G, B) or 4 entries."""
    x = np.asarray(a, dtype=np.float64)
    if x.ndim == trailing:
        x = x[None]
    if x.ndim != trailing + 1 or x.shape[0] not in (1, 3, 4):
        raise DePError(f"{name}: shape {np.shape(a)}: expected one, 3 (R, G, B) or 4 (R, Gr, Gb, B) entries")
    return x[[0, 0, 0, 0] if x.shape[0] == 1 else [0, 1, 1, 2] if x.shape[0] == 3 else [0, 1, 2, 3]]


def dep_restore(packed: np.ndarray, gamma_rggb, kernels_rggb, denoiser: str = "nlm", rng=None,
                pad_px: int | None = None, boundary: str = "edge", fill_iterations: int = FILL_ITERATIONS,
                prior: str = "gradient") -> DePResult:
    """Restore a packed RAW [4, h, w] (R, Gr, Gb, B; black subtracted, in units of white − black)
    to linear camera RGB [3, 2h, 2w] in the same units divided by γ: per channel x̂ = Wiener(denoise(y) / γ),
    then unpack to RGGB and demosaic bilinearly (clipped at 0).

    gamma_rggb: γ, a number or 3 (R, G, B) or 4 (R, Gr, Gb, B) values > 0.
    kernels_rggb: [k, k], [3, k, k] (R, G, B) or [4, k, k] kernels at the packed planes' pitch (twice
        the sensor pitch), centre at size // 2, normalised to unit sum.
    rng: seed or Generator for the Wiener sampler (one generator drawn in channel order).
    """
    t0 = time.perf_counter()
    y = np.asarray(packed, dtype=np.float64)
    if y.ndim != 3 or y.shape[0] != 4 or min(y.shape[1:]) < 2:
        raise DePError(f"packed: shape {y.shape}: expected [4, h, w] (R, Gr, Gb, B), h, w ≥ 2")
    if not np.isfinite(y).all():
        raise DePError(f"packed: {int((~np.isfinite(y)).sum())} non-finite values: expected finite numbers")
    g = _four(gamma_rggb, "gamma_rggb", 0)
    if not (np.isfinite(g).all() and (g > 0).all()):
        raise DePError(f"gamma_rggb = {np.asarray(gamma_rggb).tolist()}: expected finite values > 0")
    ks = _four(kernels_rggb, "kernels_rggb", 2)
    for c in range(4):
        _kernel(ks[c], f"kernels_rggb[{c}]")
    if denoiser not in DENOISERS:
        raise DePError(f"denoiser = {denoiser!r}: expected one of {', '.join(DENOISERS)}")
    p = _wiener_args(pad_px, ks.shape[-2:], boundary, fill_iterations, prior)
    t1 = time.perf_counter()
    sigma = tuple(estimate_sigma(y[c]) for c in range(4)) if denoiser != "none" else (0.0,) * 4
    den = np.stack([denoise_plane(y[c], denoiser, sigma[c]) for c in range(4)]) / g[:, None, None]
    t2 = time.perf_counter()
    gen = np.random.default_rng(rng)
    dec = np.stack([wiener_plane(den[c], ks[c], gen, p, boundary, fill_iterations, prior) for c in range(4)])
    t3 = time.perf_counter()
    rgb = np.clip(demosaic_bilinear(unpack_rggb(dec)), 0, None).astype(np.float32)
    t4 = time.perf_counter()
    return DePResult(rgb, denoiser, sigma, p, boundary,
                     {"checks_s": t1 - t0, "denoise_s": t2 - t1, "wiener_s": t3 - t2, "demosaic_s": t4 - t3,
                      "total_s": t4 - t0})
