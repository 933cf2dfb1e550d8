"""The FFT convolution of the optics stage (docs/PHYSICS.md §1, §3 Boundaries/Centring): per band k,
on the render grid (sensor frame plus ``margin_px`` on every side),

    y_k = g_k · (x_k ⊗ k_k),    cropped to the frame

- ⊗ is *linear* convolution: the scene beyond the frame (the margin) blurs into it, nothing wraps.
  The margin is cropped afterwards, so the output is the sensor frame. Needs margin_px ≥ S // 2.
- Kernel convention (same as psf.engine): odd S, centre at index S // 2, so a delta at pixel p
  gives the kernel with its centre at p: y[p + u] = k[S//2 + u].

FFTs: scipy.fft rfft2/irfft2 with ``workers``; float32/complex64 by default, float64 on request.
FFT size per axis: next_fast_len(H) — the kernel is stored wrapped around index 0, so circular
wrap-around only reaches the margin rows/columns that are cropped (exact linear result in the frame
whenever margin_px ≥ S // 2; see ``convolve_bands``). Very bright pixels are left out of the FFTs
(optics.bright).
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from udc_render.errors import UdcError
from udc_render.optics.bright import BrightPixels, bright_blur, dimmed

PRECISIONS = {"float32": np.float32, "float64": np.float64}
# scipy.fft threads when a call does not name its own: all cores (-1); a dataset worker sets its share
# (udc_render.dataset.threads) so that N workers on N cores do not oversubscribe them.
FFT_WORKERS = -1


class OpticsError(UdcError):
    """Inputs the optics stage cannot honour (message is one line for the user)."""



def _check_margin(margin_px: int, size_px: int, shape) -> None:
    if size_px % 2 != 1:
        raise OpticsError(f"kernel size {size_px} px must be odd (centre at size // 2)")
    half = size_px // 2
    if margin_px < half:
        raise OpticsError(f"margin_px={margin_px} is smaller than the kernel half-width {half} "
                          f"(kernel {size_px}×{size_px} px); render with margin_px ≥ {half}")
    if shape[0] <= 2 * margin_px or shape[1] <= 2 * margin_px:
        raise OpticsError(f"margin_px={margin_px} leaves no sensor frame in a {shape[0]}×{shape[1]} px image")


def _workers(workers: int | None) -> int:
    return FFT_WORKERS if workers is None else workers


def _precision(precision: str):
    if precision not in PRECISIONS:
        raise OpticsError(f"precision must be one of {', '.join(PRECISIONS)}, got '{precision}'")
    return PRECISIONS[precision]


# ---------------------------------------------------------------------------- convolution core


def fft_shape(image_shape, size_px: int, margin_px: int) -> tuple[int, int]:
    """FFT size per axis: next_fast_len(max(n, n − m + S//2, S)) — enough for the frame to be exact."""
    half = size_px // 2
    return tuple(sfft.next_fast_len(max(n, n - margin_px + half, size_px), real=True) for n in image_shape)


def _kernel_spectrum(kernel: np.ndarray, shape, dtype, workers: int) -> np.ndarray:
    """rfft2 of the kernel stored wrapped around index 0 (centre S//2 → index 0), padded to `shape`."""
    S, half = kernel.shape[-1], kernel.shape[-1] // 2
    buf = np.zeros(shape, dtype=dtype)
    buf[:S, :S] = kernel
    buf = np.roll(buf, (-half, -half), axis=(0, 1))
    return sfft.rfft2(buf, workers=workers)


def kernel_spectra(kernels: np.ndarray, shape, precision: str = "float32", workers: int | None = None) -> np.ndarray:
    """[n, Fy, Fx//2 + 1] the spectra of kernels [n, S, S] at FFT shape `shape` (the convolutions' own,
    _kernel_spectrum), made once for many convolutions (convolve_bands' and convolve_field's kernel_spectra)."""
    dtype = _precision(precision)
    workers = _workers(workers)
    out = np.empty((kernels.shape[0], shape[0], shape[1] // 2 + 1), np.result_type(dtype, np.complex64))
    for i, k in enumerate(kernels):
        out[i] = _kernel_spectrum(np.asarray(k).astype(dtype, copy=False), shape, dtype, workers)
    return out


def _check_spectra(kernel_spectra, n: int, shape, what: str) -> None:
    """kernel_spectra [n, Fy, Fx//2 + 1] (None: made per call) for `what`, or a one-line OpticsError."""
    if kernel_spectra is not None and tuple(kernel_spectra.shape) != (n, shape[0], shape[1] // 2 + 1):
        raise OpticsError(f"kernel spectra of shape {tuple(kernel_spectra.shape)} do not match {what} at FFT shape "
                          f"{tuple(shape)}: make them for this grid (kernel_spectra)")


def band_spectra(bands: np.ndarray, size_px: int, margin_px: int, precision: str = "float32",
                 workers: int | None = None, bright: BrightPixels | None = None) -> np.ndarray:
    """rfft2 of every band [K, H, W] at fft_shape((H, W), size_px, margin_px): [K, Fy, Fx//2 + 1].
    One render's spectra serve the ground truth and every display of the same kernel size; without
    the bright pixels when given (they are convolved apart: optics.bright)."""
    dtype = _precision(precision)
    workers = _workers(workers)
    shape = fft_shape(bands.shape[1:], size_px, margin_px)
    out = np.empty((bands.shape[0], shape[0], shape[1] // 2 + 1), np.result_type(dtype, np.complex64))
    for k, b in enumerate(bands):
        out[k] = sfft.rfft2(dimmed(b, bright, dtype), s=shape, workers=workers)
    return out


def _channel_weights(channel_weights, K: int) -> np.ndarray | None:
    if channel_weights is None:
        return None
    w = np.asarray(channel_weights, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != K or not np.all(np.isfinite(w)):
        raise OpticsError(f"channel_weights: shape {w.shape}: expected finite [C, K={K}]")
    return w


class _Output:
    """Where per-band blurred spectra Y_k go: each band's frame (irfft2 per band), or, with channel
    weights w [C, K], the channel sums Σ_k w_ck g_k Y_k accumulated in Fourier space (linearity),
    so that only C inverse FFTs are made: y_c = g-weighted Σ_k w_ck (x_k ⊗ k_k)."""

    def __init__(self, K, H, W, m, shape, dtype, gains, channel_weights, workers):
        self.gains, self.w, self.shape, self.dtype, self.workers = gains, channel_weights, shape, dtype, workers
        self.crop = (slice(m, H - m), slice(m, W - m))
        n = K if channel_weights is None else channel_weights.shape[0]
        self.out = np.empty((n, H - 2 * m, W - 2 * m), dtype=dtype)
        self.acc = None if channel_weights is None else [None] * n
        self.spatial = None if channel_weights is None else [None] * n
        self._term = None  # w_ck · Y_k, in place (no new array per term)

    def add(self, k: int, spec: np.ndarray) -> None:
        if self.w is None:
            self.out[k] = sfft.irfft2(spec, s=self.shape, workers=self.workers)[self.crop] * self.dtype(self.gains[k])
            return
        for c, wc in enumerate(self.w[:, k] * self.gains[k]):
            if wc == 0:
                continue
            if self.acc[c] is None:
                self.acc[c] = spec * self.dtype(wc)
            else:
                if self._term is None:
                    self._term = np.empty_like(spec)
                self.acc[c] += np.multiply(spec, self.dtype(wc), out=self._term)

    def add_frame(self, k: int, frame: np.ndarray) -> None:
        """Band k's blurred frame made in space (the bright pixels' float64 blur), after add(k, ...): into
        the band's image, or into float64 channel sums added to the channels' inverse FFTs."""
        if self.w is None:
            self.out[k] += (frame * self.gains[k]).astype(self.dtype)
            return
        for c, wc in enumerate(self.w[:, k] * self.gains[k]):
            if wc != 0:
                if self.spatial[c] is None:
                    self.spatial[c] = frame * wc
                else:
                    self.spatial[c] += frame * wc

    def result(self) -> np.ndarray:
        if self.w is not None:
            for c, a in enumerate(self.acc):
                self.out[c] = 0 if a is None else sfft.irfft2(a, s=self.shape, workers=self.workers)[self.crop]
            for c, frame in enumerate(self.spatial):
                if frame is not None:
                    self.out[c] += frame.astype(self.dtype)
        return self.out


def convolve_bands(bands: np.ndarray, kernels: np.ndarray, margin_px: int, gains=None,
                   precision: str = "float32", workers: int | None = None, channel_weights=None,
                   spectra: np.ndarray | None = None, bright: BrightPixels | None = None,
                   kernel_spectra: np.ndarray | None = None) -> np.ndarray:
    """Linear convolution per band, cropped to the frame: y_k = g_k · (x_k ⊗ k_k)[m:H−m, m:W−m].

    bands [K, H, W], kernels [K, S, S] (odd S, centre S//2), margin_px ≥ S//2. Output [K, H−2m, W−2m]
    in `precision`. A kernel larger than the sensor frame is fine (exact) as long as the margin
    covers its half-width; a kernel larger than the whole grid necessarily fails that check.
    channel_weights [C, K]: return the channel images Σ_k w_ck y_k [C, H−2m, W−2m] instead (C inverse
    FFTs, not K). spectra: band_spectra(bands, ...) computed once and shared (no forward FFT here; made
    with the same `bright`). bright: pixels left out of the FFTs and convolved apart in float64 (optics.bright).
    kernel_spectra: the kernels' spectra made beforehand (kernel_spectra: the same numbers as made here).
    """
    dtype = _precision(precision)
    workers = _workers(workers)
    bands = np.asarray(bands)
    kernels = np.asarray(kernels)
    if (bands.ndim != 3 or kernels.ndim != 3 or kernels.shape[0] != bands.shape[0]
            or kernels.shape[1] != kernels.shape[2]):
        raise OpticsError(f"need bands [K, H, W] and kernels [K, S, S] with the same K, got "
                          f"{bands.shape} and {kernels.shape}")
    K, H, W = bands.shape
    m = int(margin_px)
    _check_margin(m, kernels.shape[-1], (H, W))
    gains = np.ones(K) if gains is None else np.asarray(gains, dtype=np.float64)
    shape = fft_shape((H, W), kernels.shape[-1], m)
    if spectra is not None and spectra.shape != (K, shape[0], shape[1] // 2 + 1):
        raise OpticsError(f"band spectra of shape {spectra.shape} do not match {K} bands at FFT shape {shape}")
    _check_spectra(kernel_spectra, K, shape, f"{K} kernels")
    out = _Output(K, H, W, m, shape, dtype, gains, _channel_weights(channel_weights, K), workers)
    product = None  # the shared band spectrum times the kernel's, in one reused array
    for k in range(K):
        kspec = (_kernel_spectrum(kernels[k].astype(dtype, copy=False), shape, dtype, workers) if kernel_spectra is None
                 else kernel_spectra[k])
        if spectra is None:
            spec = sfft.rfft2(dimmed(bands[k], bright, dtype), s=shape, workers=workers)
            spec *= kspec
        else:
            product = np.empty_like(spectra[k]) if product is None else product  # add() only reads it
            spec = np.multiply(spectra[k], kspec, out=product)
        out.add(k, spec)
        if bright is not None:
            out.add_frame(k, bright_blur(bands[k], bright, [(kernels[k], None, 1.0)], (H - 2 * m, W - 2 * m), m))
    return out.result()
