"""Optics stage: apply PSF kernels to rendered band images (docs/PHYSICS.md §1, §3 Boundaries/Centring, §4).

Per band k (wavelength λ_k), on the render grid (sensor frame plus ``margin_px`` on every side):

    y_k = g_k · (x_k ⊗ k_k),    g_k = T_display(λ_k) · transmittance_k · (1 − energy_outside_k)

- ⊗ is *linear* convolution: the scene beyond the frame (the margin) blurs into it, nothing wraps.
  The margin is cropped afterwards, so the output is the sensor frame. Needs margin_px ≥ S // 2.
- Kernel convention (same as psf.engine): odd S, centre at index S // 2, so a delta at pixel p
  gives the kernel with its centre at p: y[p + u] = k[S//2 + u].
- Light that the PSF sends outside the kernel window is lost (energy_outside), not renormalised.
- Glass (no display): pass the bare-lens KernelSet (transmittance 1) and transmission None (T = 1).

Field dependence (distance d > 0, docs/PHYSICS.md §4): the beam of a scene point imaged at sensor position
x (µm from the optical axis = the frame centre; +x along columns, +y along rows) crosses the display
at the mask shift s(x) = x · d / z_i, so its PSF and transmitted power depend on x with period
z_i · p / d. With field kernels k_q and powers P_q sampled at phases q (KernelSet.field_*):

    blend='source' (default):  y = g · Σ_q k_q ⊗ (w_q · P_q · x)      (the PSF belongs to the source point)
    blend='output'          :  y = g · Σ_q w_q · P_q · (k_q ⊗ x)      (weights at the output pixel)

w_q(x) are bilinear (tensor-product linear) interpolation weights in phase, periodic over the display
period when the phases span a whole period, clamped at the end phases when they span only the part
of the display the sensor sees (psf.engine.field_shifts). 'source' conserves energy exactly
(Σ y = g · Σ x · P(s(x))); a flat field then shows the banding profile smoothed by the PSF.
'output' gives a flat field exactly the interpolated P(s(x)). With d = 0 (or no field kernels) one
kernel per band is used and nothing field-dependent is computed.

Very bright pixels (BrightPixels: the sun beside a dim room) are left out of the FFTs and convolved apart, in
float64, on the boxes they occupy (_bright_blur): a float32 FFT spreads a round-off of about
0.6 · ε32 · ‖x‖₂ / √N over every pixel of the frame (measured: a point source on a 768 × 1280 grid), which
the sun's 1e9 dynamic range would lift above the sensor's noise floor (pipeline.bright_pixels chooses them).

FFTs: scipy.fft rfft2/irfft2 with ``workers``; float32/complex64 by default, float64 on request.
FFT size per axis: next_fast_len(H) — the kernel is stored wrapped around index 0, so circular
wrap-around only reaches the margin rows/columns that are cropped (exact linear result in the frame
whenever margin_px ≥ S // 2; see ``convolve_bands``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft
from udc_render.errors import UdcError

PRECISIONS = {"float32": np.float32, "float64": np.float64}
# scipy.fft threads when a call does not name its own: all cores (-1); a dataset worker sets its share
# (udc_render.dataset.threads) so that N workers on N cores do not oversubscribe them.
FFT_WORKERS = -1
BLENDS = ("source", "output")
PITCH_RTOL = 1e-6


class OpticsError(UdcError):
    """Inputs the optics stage cannot honour (message is one line for the user)."""


@dataclass(frozen=True)
class OpticsResult:
    """Irradiance at the sensor per band, sensor frame only.

    images          [K, H, W] float32, same units as the band images × (dimensionless gains);
                    [C, H, W] channel sums Σ_k w_ck y_k when apply_kernels was given channel_weights
    pitch_um        sensor-plane pixel pitch of images
    wavelengths_nm  [K] kernel wavelengths
    gains           [K] g_k = transmission_k · transmittance_k · (1 − energy_outside_k)
    transmission    [K] display spectral transmission T(λ_k) that was applied
    applied         what was done: model, blend, precision, fft_shape, margin_px, kernel_px, phases, ...
    """
    images: np.ndarray
    pitch_um: float
    wavelengths_nm: np.ndarray
    gains: np.ndarray
    transmission: np.ndarray
    applied: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------- checks


def _check_finite(bands: np.ndarray, names=None) -> None:
    bad = ~np.isfinite(bands).reshape(bands.shape[0], -1).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        name = names[k] if names is not None else f"band {k}"
        n = int((~np.isfinite(bands[k])).sum())
        raise OpticsError(f"{name} (index {k}) holds {n} NaN or infinite value(s); the optics need finite input")


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


# ---------------------------------------------------------------------------- very bright pixels


@dataclass(frozen=True)
class BrightPixels:
    """Pixels of the render grid convolved apart in float64 (module doc): mask [H, W] and the boxes
    (row slice, column slice) that hold them (scipy.ndimage.find_objects of its clusters)."""
    mask: np.ndarray
    boxes: tuple

    @classmethod
    def of_mask(cls, mask: np.ndarray) -> "BrightPixels | None":
        """The clusters of `mask` (8-connected), or None when it is empty."""
        from scipy import ndimage
        if not mask.any():
            return None
        labels, _ = ndimage.label(mask, structure=np.ones((3, 3)))
        return cls(mask, tuple(ndimage.find_objects(labels)))


def _dim(x: np.ndarray, bright: BrightPixels | None, dtype) -> np.ndarray:
    """x with the bright pixels set to 0 (a copy), in dtype; x itself (as dtype) without bright pixels."""
    x = x.astype(dtype, copy=False)
    return x if bright is None else np.where(bright.mask, dtype(0), x)


def _bright_blur(x: np.ndarray, bright: BrightPixels, terms, frame_shape, m: int, at_output: bool = False) -> np.ndarray:
    """float64 frame [h, w] of Σ_terms k ⊗ (w · P · x_bright) (blend 'source'), or Σ w · P · (k ⊗ x_bright)
    (at_output: blend 'output'), on each bright box only (direct FFT convolution of the box, full size:
    output row i of a box starting at row r0 is grid row r0 + i − S//2; the kernel convention of convolve_bands)."""
    from scipy.signal import fftconvolve
    h, w = frame_shape
    out = np.zeros((h, w))
    patches = [np.where(bright.mask[rows, cols], x[rows, cols], 0).astype(np.float64) for rows, cols in bright.boxes]
    for kern, wmap, power in terms:  # terms outer: a lazy generator of weight maps is read once
        half = kern.shape[-1] // 2
        k64 = kern.astype(np.float64)
        for (rows, cols), patch in zip(bright.boxes, patches):
            r0, c0 = rows.start - half - m, cols.start - half - m  # frame coordinates of the blur's corner
            src = patch if wmap is None or at_output else patch * wmap[rows, cols]
            blur = fftconvolve(src * float(power), k64, mode="full")
            fr = slice(max(r0, 0), min(r0 + blur.shape[0], h))
            fc = slice(max(c0, 0), min(c0 + blur.shape[1], w))
            if fr.start >= fr.stop or fc.start >= fc.stop:
                continue
            part = blur[fr.start - r0:fr.stop - r0, fc.start - c0:fc.stop - c0]
            if at_output and wmap is not None:
                part = part * wmap[fr.start + m:fr.stop + m, fc.start + m:fc.stop + m]
            out[fr, fc] += part
    return out


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


def band_spectra(bands: np.ndarray, size_px: int, margin_px: int, precision: str = "float32",
                 workers: int | None = None, bright: BrightPixels | None = None) -> np.ndarray:
    """rfft2 of every band [K, H, W] at fft_shape((H, W), size_px, margin_px): [K, Fy, Fx//2 + 1].
    One render's spectra serve the ground truth and every display of the same kernel size; without
    the bright pixels when given (they are convolved apart: module doc)."""
    dtype = _precision(precision)
    workers = _workers(workers)
    shape = fft_shape(bands.shape[1:], size_px, margin_px)
    return np.stack([sfft.rfft2(_dim(b, bright, dtype), s=shape, workers=workers) for b in bands])


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
                self.acc[c] += spec * self.dtype(wc)

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
                   spectra: np.ndarray | None = None, bright: BrightPixels | None = None) -> np.ndarray:
    """Linear convolution per band, cropped to the frame: y_k = g_k · (x_k ⊗ k_k)[m:H−m, m:W−m].

    bands [K, H, W], kernels [K, S, S] (odd S, centre S//2), margin_px ≥ S//2. Output [K, H−2m, W−2m]
    in `precision`. A kernel larger than the sensor frame is fine (exact) as long as the margin
    covers its half-width; a kernel larger than the whole grid necessarily fails that check.
    channel_weights [C, K]: return the channel images Σ_k w_ck y_k [C, H−2m, W−2m] instead (C inverse
    FFTs, not K). spectra: band_spectra(bands, ...) computed once and shared (no forward FFT here; made
    with the same `bright`). bright: pixels left out of the FFTs and convolved apart in float64 (module doc).
    """
    dtype = _precision(precision)
    workers = _workers(workers)
    bands = np.asarray(bands)
    kernels = np.asarray(kernels)
    if bands.ndim != 3 or kernels.ndim != 3 or kernels.shape[0] != bands.shape[0] or kernels.shape[1] != kernels.shape[2]:
        raise OpticsError(f"need bands [K, H, W] and kernels [K, S, S] with the same K, got "
                          f"{bands.shape} and {kernels.shape}")
    K, H, W = bands.shape
    m = int(margin_px)
    _check_margin(m, kernels.shape[-1], (H, W))
    gains = np.ones(K) if gains is None else np.asarray(gains, dtype=np.float64)
    shape = fft_shape((H, W), kernels.shape[-1], m)
    if spectra is not None and spectra.shape != (K, shape[0], shape[1] // 2 + 1):
        raise OpticsError(f"band spectra of shape {spectra.shape} do not match {K} bands at FFT shape {shape}")
    out = _Output(K, H, W, m, shape, dtype, gains, _channel_weights(channel_weights, K), workers)
    for k in range(K):
        spec = (sfft.rfft2(_dim(bands[k], bright, dtype), s=shape, workers=workers) if spectra is None
                else spectra[k].copy())
        spec *= _kernel_spectrum(kernels[k].astype(dtype, copy=False), shape, dtype, workers)
        out.add(k, spec)
        if bright is not None:
            out.add_frame(k, _bright_blur(bands[k], bright, [(kernels[k], None, 1.0)], (H - 2 * m, W - 2 * m), m))
    return out.result()


# ---------------------------------------------------------------------------- field dependence


def phase_weights(positions_um: np.ndarray, shifts_um: np.ndarray, distance_um: float, image_distance_um: float,
                  period_um: float, periodic: bool) -> np.ndarray:
    """Linear-interpolation weights [P, N] of N sensor positions x over P phase shifts s_i (one axis).

    s(x) = x · d / z_i. periodic: s_i = i p / P, fractional index u = (s / (p/P)) mod P, wrapping
    between phase P−1 and 0. Else s_i evenly spaced (field_shifts' centred cells): u clamped to
    [0, P−1]. Columns sum to 1.
    """
    s = np.asarray(positions_um, dtype=np.float64) * distance_um / image_distance_um
    shifts = np.asarray(shifts_um, dtype=np.float64)
    P = shifts.size
    w = np.zeros((P, s.size))
    if P == 1:
        w[0] = 1.0
        return w
    if periodic:
        u = np.mod((s - shifts[0]) / (period_um / P), P)
        i0 = np.floor(u).astype(int) % P
        i1 = (i0 + 1) % P
    else:
        step = (shifts[-1] - shifts[0]) / (P - 1)
        u = np.clip((s - shifts[0]) / step, 0.0, P - 1)
        i0 = np.minimum(np.floor(u).astype(int), P - 2)
        i1 = i0 + 1
    f = u - np.floor(u) if periodic else u - i0
    cols = np.arange(s.size)
    np.add.at(w, (i0, cols), 1.0 - f)
    np.add.at(w, (i1, cols), f)
    return w


def _axis_is_periodic(shifts: np.ndarray, period_um: float) -> bool:
    P = shifts.size
    return bool(P > 1 and np.allclose(shifts, np.arange(P) * period_um / P, rtol=1e-9, atol=1e-9 * period_um))


def phase_basis(kernels: np.ndarray, rank: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Rank-r basis of n phase kernels [n, S, S]: k_q ≈ Σ_r c_qr B_r (truncated SVD through the n × n Gram
    matrix M Mᵀ = U Σ² Uᵀ; B = Σ⁻¹ Uᵀ M, c = U Σ). Returns (B [r, S, S], c [n, r], relative residual
    √(Σ_{>r} σ²/Σ σ²), the Frobenius error of the truncated kernels over their norm)."""
    n, S = kernels.shape[0], kernels.shape[-1]
    M = kernels.reshape(n, S * S).astype(np.float64)
    vals, U = np.linalg.eigh(M @ M.T)
    order = np.argsort(vals)[::-1]
    vals, U = np.clip(vals[order], 0.0, None), U[:, order]
    r = max(1, min(int(rank), int(np.count_nonzero(vals > vals[0] * 1e-30))))
    sigma = np.sqrt(vals[:r])
    basis = (U[:, :r].T @ M) / sigma[:, None]
    residual = float(np.sqrt(vals[r:].sum() / vals.sum())) if vals.sum() > 0 else 0.0
    return basis.reshape(r, S, S), U[:, :r] * sigma[None, :], residual


@dataclass(frozen=True)
class FieldBasis:
    """A d > 0 kernel set's phase kernels reduced to rank r on the phases a render grid uses
    (field_basis): per band k, k_q ≈ Σ_r coeffs[k][q, r] · bases[k][r] over the live phases q. Enough
    for convolve_field at that rank, at r/P² of the phase kernels' memory (a dataset worker keeps
    this, not the [K, P, P, S, S] kernels: pipeline.compact_kernels)."""
    rank: int
    live: tuple
    bases: list  # K × [r, S, S]
    coeffs: list  # K × [n_live, r]
    residuals: list  # K relative residuals (phase_basis)


def live_phases(weights_y: np.ndarray, weights_x: np.ndarray) -> tuple:
    """The (j, i) phases whose interpolation weights are non-zero somewhere on the grid."""
    return tuple((j, i) for j in range(weights_y.shape[0]) for i in range(weights_x.shape[0])
                 if weights_y[j].any() and weights_x[i].any())


def field_basis(field_kernels: np.ndarray, live: tuple, rank: int) -> FieldBasis:
    """phase_basis of every band's live phase kernels (stored in the kernels' dtype)."""
    parts = [phase_basis(np.stack([field_kernels[k, j, i] for j, i in live]), rank) for k in range(field_kernels.shape[0])]
    return FieldBasis(int(rank), tuple(live), [b.astype(field_kernels.dtype) for b, _, _ in parts],
                      [c for _, c, _ in parts], [r for _, _, r in parts])


def _basis_map(coeff_r: np.ndarray, live, power: np.ndarray, wy: np.ndarray, wx: np.ndarray, dtype) -> np.ndarray:
    """W_r(row, col) = Σ_q c_qr P_q wy_j(row) wx_i(col) = wyᵀ C wx, C[j, i] = c_qr P_ji on the live phases."""
    c = np.zeros((wy.shape[0], wx.shape[0]))
    for q, (j, i) in enumerate(live):
        c[j, i] = coeff_r[q] * power[j, i]
    return wy.T.astype(dtype, copy=False) @ (c.astype(dtype) @ wx.astype(dtype, copy=False))


def convolve_field(bands: np.ndarray, field_kernels: np.ndarray, field_power: np.ndarray, weights_y: np.ndarray,
                   weights_x: np.ndarray, margin_px: int, gains=None, blend: str = "source",
                   precision: str = "float32", workers: int | None = None, rank: int | None = None,
                   channel_weights=None, basis: FieldBasis | None = None,
                   bright: BrightPixels | None = None) -> tuple[np.ndarray, float]:
    """Field-varying blur: y_k = g_k Σ_{j,i} k_kji ⊗ (w_j(row) w_i(col) P_kji x_k)  (blend='source'),
    or g_k Σ_{j,i} w_j w_i P_kji (k_kji ⊗ x_k) (blend='output'). Frame cropped as convolve_bands.

    field_kernels [K, Py, Px, S, S], field_power [K, Py, Px], weights_y [Py, H], weights_x [Px, W]
    (rows/columns of the whole render grid). Phases whose weights vanish everywhere are skipped.
    rank r (None: every phase kernel, exact): the phase kernels of each band are replaced by their
    rank-r basis (phase_basis), k_q ≈ Σ_r c_qr B_r, so 'source' is Σ_r B_r ⊗ (W_r x) with the weight
    maps W_r = Σ_q c_qr P_q w_q: r FFT pairs per band instead of one per phase. channel_weights [C, K]
    (blend 'source' only): the channel images Σ_k w_ck y_k, summed in Fourier space (C inverse FFTs).
    basis: the rank-r bases made beforehand (field_basis; field_kernels may then be None).
    bright: pixels left out of the FFTs and convolved apart in float64 (module doc).
    Returns (the images, the largest relative kernel residual over the bands; 0 when exact).
    """
    dtype = _precision(precision)
    workers = _workers(workers)
    if blend not in BLENDS:
        raise OpticsError(f"blend must be one of {', '.join(BLENDS)}, got '{blend}'")
    if rank is not None and (isinstance(rank, bool) or not isinstance(rank, (int, np.integer)) or rank < 1):
        raise OpticsError(f"field rank = {rank!r}: expected a whole number ≥ 1, or None (every phase kernel)")
    K, H, W = bands.shape
    m = int(margin_px)
    S = (field_kernels if basis is None else basis.bases[0]).shape[-1]
    _check_margin(m, S, (H, W))
    gains = np.ones(K) if gains is None else np.asarray(gains, dtype=np.float64)
    shape = fft_shape((H, W), S, m)
    cw = _channel_weights(channel_weights, K)
    if cw is not None and blend != "source":
        raise OpticsError("channel_weights need blend='source' (blend 'output' weights each band after its inverse FFT)")
    wy = weights_y.astype(dtype)
    wx = weights_x.astype(dtype)
    live = live_phases(wy, wx)
    if basis is not None and (basis.live != live or basis.rank != rank):
        raise OpticsError(f"field basis of rank {basis.rank} on {len(basis.live)} phases does not fit rank {rank} "
                          f"on this grid's {len(live)} phases: make it for this grid (field_basis)")
    out = _Output(K, H, W, m, shape, dtype, gains, cw, workers)
    fy, fx = slice(m, H - m), slice(m, W - m)
    worst = 0.0
    for k in range(K):
        x = _dim(bands[k], bright, dtype)
        if rank is None:
            def phase_terms(k=k):  # lazily: one weight map in memory at a time
                return ((field_kernels[k, j, i], wy[j][:, None] * wx[i][None, :], dtype(field_power[k, j, i]))
                        for j, i in live)
        else:
            b_k, coeff, residual = ((basis.bases[k], basis.coeffs[k], basis.residuals[k]) if basis is not None
                                    else phase_basis(np.stack([field_kernels[k, j, i] for j, i in live]), rank))
            worst = max(worst, residual)
            maps = [(b_k[r], _basis_map(coeff[:, r], live, field_power[k], wy, wx, dtype), dtype(1.0))
                    for r in range(b_k.shape[0])]

            def phase_terms(maps=maps):
                return iter(maps)
        terms = phase_terms()
        if blend == "source":
            acc, weighted = None, np.empty_like(x)
            for kern, wmap, power in terms:
                np.multiply(x, wmap, out=weighted)
                weighted *= power
                term = sfft.rfft2(weighted, s=shape, workers=workers)
                term *= _kernel_spectrum(kern.astype(dtype, copy=False), shape, dtype, workers)
                if acc is None:
                    acc = term
                else:
                    acc += term
            out.add(k, acc)
        else:
            spec = sfft.rfft2(x, s=shape, workers=workers)
            y = np.zeros((H - 2 * m, W - 2 * m), dtype=dtype)
            for kern, wmap, power in terms:
                blur = sfft.irfft2(spec * _kernel_spectrum(kern.astype(dtype), shape, dtype, workers), s=shape,
                                   workers=workers)[fy, fx]
                y += blur * wmap[fy, fx] * power
            out.out[k] = y * dtype(gains[k])
        if bright is not None:
            out.add_frame(k, _bright_blur(bands[k], bright, phase_terms(), (H - 2 * m, W - 2 * m), m,
                                          at_output=blend == "output"))
    return out.result(), worst


# ---------------------------------------------------------------------------- the stage


def _display_period_um(kernel_set, period_um) -> tuple[float, float]:
    """The display period (x, y) in µm: the override, else the KernelSet's own."""
    p = period_um if period_um is not None else kernel_set.period_um
    if p is None:
        raise OpticsError("field kernels need the display period: pass period_um (x, y) in µm")
    p = tuple(float(v) for v in np.broadcast_to(np.asarray(p, dtype=float), (2,)))
    if not all(v > 0 and math.isfinite(v) for v in p):
        raise OpticsError(f"period_um must be > 0, got {p}")
    return p


def _transmission(transmission, K: int) -> np.ndarray:
    t = np.ones(K) if transmission is None else np.asarray(transmission, dtype=np.float64)
    t = np.broadcast_to(t, (K,)).astype(np.float64) if t.ndim == 0 else t
    if t.shape != (K,) or not np.all(np.isfinite(t)) or np.any(t < 0):
        raise OpticsError(f"transmission must be None, a scalar or [K={K}] finite values ≥ 0, "
                          f"got shape {t.shape}")
    return t


def field_weights(kernel_set, shape_hw, pitch_um: float, distance_mm: float, image_distance_um: float | None = None,
                  period_um=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """The phase interpolation weights [Py, H] and [Px, W] of a render grid of shape (H, W) (pixel
    centres from the optical axis at the grid centre; phase_weights), and what they assume."""
    H, W = shape_hw
    z = float(kernel_set.image_distance_um if image_distance_um is None else image_distance_um)
    px, py = _display_period_um(kernel_set, period_um)
    shifts = np.asarray(kernel_set.field_shifts_um, dtype=np.float64)
    sx, sy = shifts[0, :, 0], shifts[:, 0, 1]
    per_x, per_y = _axis_is_periodic(sx, px), _axis_is_periodic(sy, py)
    wx = phase_weights((np.arange(W) - (W - 1) / 2) * pitch_um, sx, distance_mm * 1000, z, px, per_x)
    wy = phase_weights((np.arange(H) - (H - 1) / 2) * pitch_um, sy, distance_mm * 1000, z, py, per_y)
    d_um = distance_mm * 1000
    return wy, wx, {"phases": [int(sy.size), int(sx.size)], "interpolation": "bilinear in phase",
                    "periodic": [per_y, per_x], "banding_period_px": [z * py / d_um / pitch_um, z * px / d_um / pitch_um],
                    "image_distance_um": z, "period_um": [px, py]}


def apply_kernels(band_image, kernel_set, transmission=None, precision: str = "float32", workers: int | None = None,
                  blend: str = "source", field: bool = True, distance_mm: float | None = None,
                  image_distance_um: float | None = None, period_um=None,
                  field_rank: int | None = None, channel_weights=None, spectra: np.ndarray | None = None,
                  field_basis: FieldBasis | None = None, bright: BrightPixels | None = None) -> OpticsResult:
    """Sensor irradiance per band from a udc_render.render.BandImage and a psf.KernelSet.

    y_k = T(λ_k) · transmittance_k · (1 − energy_outside_k) · (x_k ⊗ k_k), frame cropped (module doc).
    transmission: T(λ_k), None (= 1, T-OLED flat or glass), a scalar, or [K].
    field: use field kernels when the KernelSet has them (d > 0); False forces the mean kernel.
    distance_mm, image_distance_um, period_um (x, y): override the KernelSet's d, z_i and display period.
    field_rank: d > 0: a rank-r basis of each band's phase kernels (convolve_field; None: exact).
    channel_weights [C, K]: images are the channel sums Σ_k w_ck y_k [C, H, W] (one inverse FFT per
    channel; blend 'source'); spectra: band_spectra of the band image, shared between calls (d = 0 path).
    field_basis: the kernel set's rank-`field_rank` bases for this grid, made once (field_basis).
    bright: very bright pixels, convolved apart in float64 (module doc; pipeline.bright_pixels).
    """
    _precision(precision)  # validate early: one-line error for an unknown precision
    bands = np.asarray(band_image.bands)
    if bands.ndim != 3:
        raise OpticsError(f"band image must be [K, H, W], got shape {bands.shape}")
    K, H, W = bands.shape
    edges = np.asarray(band_image.edges_nm, dtype=np.float64)
    wl = np.asarray(kernel_set.wavelengths_nm, dtype=np.float64)
    names = [f"band {0.5 * (edges[k] + edges[k + 1]):g} nm" for k in range(K)] if edges.size == K + 1 else None
    _check_finite(bands, names)
    if kernel_set.kernels.shape[0] != K or wl.size != K:
        raise OpticsError(f"{K} band images but {kernel_set.kernels.shape[0]} kernels: one kernel per band needed")
    if edges.size == K + 1:
        outside = (wl < edges[:-1] - 1e-9) | (wl > edges[1:] + 1e-9)
        if outside.any():
            k = int(np.argmax(outside))
            raise OpticsError(f"kernel {k} at {wl[k]:g} nm lies outside band {k} [{edges[k]:g}, {edges[k + 1]:g}] nm")
    pitch = float(band_image.pitch_um)
    if not abs(kernel_set.pixel_um - pitch) <= PITCH_RTOL * pitch:
        raise OpticsError(f"kernel pixel {kernel_set.pixel_um:g} µm differs from the band image pitch {pitch:g} µm "
                          f"(relative tolerance {PITCH_RTOL:g}); compute kernels at pixel_um={pitch:g}")
    m = int(band_image.margin_px)
    S = kernel_set.size_px
    _check_margin(m, S, (H, W))
    t = _transmission(transmission, K)
    gains = t * np.asarray(kernel_set.transmittance, float) * (1.0 - np.asarray(kernel_set.energy_outside, float))

    d_mm = float(kernel_set.distance_mm if distance_mm is None else distance_mm)
    applied = {"convolution": "linear, FFT (scipy.fft rfft2), margin cropped", "precision": precision,
               "output": "bands" if channel_weights is None else "channel sums Σ_k w_ck y_k (Fourier space)",
               "fft_shape": list(fft_shape((H, W), S, m)), "margin_px": m, "kernel_px": S,
               "gain": "T · transmittance · (1 − energy_outside)", "distance_mm": d_mm, "workers": workers,
               "bright_pixels": 0 if bright is None else int(bright.mask.sum())}
    has_field = kernel_set.field_kernels is not None or field_basis is not None
    use_field = field and has_field and d_mm > 0
    if not use_field:
        why = ("field kernels disabled" if has_field and not field else "d = 0 or no field kernels: one kernel per band")
        applied.update(model="field-independent", skipped=[f"field-dependent blur ({why})"])
        images = convolve_bands(bands, kernel_set.kernels, m, gains, precision, workers, channel_weights, spectra, bright)
    else:
        wy, wx, geometry = field_weights(kernel_set, (H, W), pitch, d_mm, image_distance_um, period_um)
        images, residual = convolve_field(bands, kernel_set.field_kernels, kernel_set.field_power, wy, wx, m,
                                          gains, blend, precision, workers, field_rank, channel_weights, field_basis,
                                          bright)
        if field_rank is not None:
            applied.update(field_rank=int(field_rank), field_rank_kernel_residual=residual)
        applied.update(model="field-dependent", blend=blend, **geometry)
    return OpticsResult(np.ascontiguousarray(images, dtype=np.float32), pitch, wl.copy(), gains, t, applied)
