"""Field-dependent blur of the optics stage (distance d > 0, docs/PHYSICS.md §4).

The beam of a scene point imaged at sensor position x (µm from the optical axis = the frame centre; +x
along columns, +y along rows) crosses the display at the mask shift s(x) = x · d / z_i, so its PSF and
transmitted power depend on x with period z_i · p / d. With field kernels k_q and powers P_q sampled at
phases q (KernelSet.field_*):

    blend='source' (default):  y = g · Σ_q k_q ⊗ (w_q · P_q · x)      (the PSF belongs to the source point)
    blend='output'          :  y = g · Σ_q w_q · P_q · (k_q ⊗ x)      (weights at the output pixel)

With the exact series of the kernel set (optics.field_power, the default), P_q is replaced by the exact power
m(s(x)) at each pixel's own shift. w_q(x) are bilinear (tensor-product linear) interpolation weights in phase,
periodic over the display period when the phases span a whole period, clamped at the end phases when they span
only the part of the display the sensor sees (psf.engine.field_shifts). 'source' conserves energy exactly
(Σ y = g · Σ x · P(s(x))); a flat field then shows the banding profile smoothed by the PSF.
'output' gives a flat field exactly the interpolated P(s(x)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from udc_render.optics.bright import BrightPixels, bright_blur, dimmed
from udc_render.optics.convolution import (
    OpticsError,
    _channel_weights,
    _check_margin,
    _check_spectra,
    _kernel_spectrum,
    _Output,
    _precision,
    _workers,
    fft_shape,
)
from udc_render.optics.field_power import PowerMap

BLENDS = ("source", "output")


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
    matrix M Mᵀ = U Σ² Uᵀ; B = Σ⁻¹ Uᵀ M, c = U Σ, each row of c then scaled so that k̃_q has k_q's sum (1 for field
    kernels): the truncation changes the kernels' shape, not their power, which would print its own bands: T-OLED
    at d = 9.6 mm, rank 2, first harmonic 1.15× without the scaling, tests/udc_render/test_field_power.py).
    Returns (B [r, S, S], c [n, r], the Frobenius error of the k̃_q over the kernels' norm)."""
    n, S = kernels.shape[0], kernels.shape[-1]
    M = kernels.reshape(n, S * S).astype(np.float64)
    vals, U = np.linalg.eigh(M @ M.T)
    order = np.argsort(vals)[::-1]
    vals, U = np.clip(vals[order], 0.0, None), U[:, order]
    r = max(1, min(int(rank), int(np.count_nonzero(vals > vals[0] * 1e-30))))
    sigma = np.sqrt(vals[:r])
    basis = (U[:, :r].T @ M) / sigma[:, None]
    coeffs = U[:, :r] * sigma[None, :]
    coeffs *= (M.sum(axis=1) / (coeffs @ basis.sum(axis=1)))[:, None]  # Σ k̃_q = Σ k_q: the power stays the blend's
    norm = float(np.linalg.norm(M))
    residual = float(np.linalg.norm(M - coeffs @ basis)) / norm if norm > 0 else 0.0
    return basis.reshape(r, S, S), coeffs, residual


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

    def arrays(self) -> dict:
        """As arrays (a kernel cache entry: psf.cache.cached_arrays); from_arrays reads them back."""
        out = {"rank": np.asarray(self.rank), "live": np.asarray(self.live, np.int64).reshape(-1, 2),
               "residuals": np.asarray(self.residuals, np.float64)}
        for k, (b, c) in enumerate(zip(self.bases, self.coeffs)):
            out[f"basis_{k}"], out[f"coeffs_{k}"] = b, c
        return out

    @classmethod
    def from_arrays(cls, a) -> "FieldBasis":
        K = a["residuals"].size
        return cls(int(a["rank"]), tuple((int(j), int(i)) for j, i in a["live"]), [a[f"basis_{k}"] for k in range(K)],
                   [a[f"coeffs_{k}"] for k in range(K)], [float(r) for r in a["residuals"]])


def phase_spread_l1(field_kernels: np.ndarray, mean_kernels: np.ndarray) -> np.ndarray:
    """[K] max_q ‖k_q − k̄‖₁ of each band's phase kernels k_q [K, P, P, S, S] about its mean kernel k̄ [K, S, S]:
    how far the field blend's kernel can stray from the field-independent one (field_print_bound)."""
    K = field_kernels.shape[0]
    out = np.empty(K)
    for k in range(K):
        mean = np.asarray(mean_kernels[k], np.float64)
        out[k] = max(float(np.abs(np.asarray(q, np.float64) - mean).sum())
                     for q in field_kernels[k].reshape((-1,) + mean.shape))
    return out


def live_phases(weights_y: np.ndarray, weights_x: np.ndarray) -> tuple:
    """The (j, i) phases whose interpolation weights are non-zero somewhere on the grid."""
    return tuple((j, i) for j in range(weights_y.shape[0]) for i in range(weights_x.shape[0])
                 if weights_y[j].any() and weights_x[i].any())


def field_basis(field_kernels: np.ndarray, live: tuple, rank: int) -> FieldBasis:
    """phase_basis of every band's live phase kernels (stored in the kernels' dtype)."""
    parts = [phase_basis(np.stack([field_kernels[k, j, i] for j, i in live]), rank)
             for k in range(field_kernels.shape[0])]
    return FieldBasis(int(rank), tuple(live), [b.astype(field_kernels.dtype) for b, _, _ in parts],
                      [c for _, c, _ in parts], [r for _, _, r in parts])


def _basis_map(coeff_r: np.ndarray, live, power: np.ndarray, wy: np.ndarray, wx: np.ndarray, dtype) -> np.ndarray:
    """W_r(row, col) = Σ_q c_qr P_q wy_j(row) wx_i(col) = wyᵀ C wx, C[j, i] = c_qr P_ji on the live phases."""
    c = np.zeros((wy.shape[0], wx.shape[0]))
    for q, (j, i) in enumerate(live):
        c[j, i] = coeff_r[q] * power[j, i]
    return wy.T.astype(dtype, copy=False) @ (c.astype(dtype) @ wx.astype(dtype, copy=False))


def _times(weight_map: np.ndarray, exact: np.ndarray | None) -> np.ndarray:
    """The weight map times the exact power map (in place), or as it is without one."""
    if exact is not None:
        weight_map *= exact
    return weight_map


def convolve_field(bands: np.ndarray, field_kernels: np.ndarray, field_power: np.ndarray, weights_y: np.ndarray,
                   weights_x: np.ndarray, margin_px: int, gains=None, blend: str = "source",
                   precision: str = "float32", workers: int | None = None, rank: int | None = None,
                   channel_weights=None, basis: FieldBasis | None = None,
                   bright: BrightPixels | None = None, power_map: PowerMap | None = None,
                   kernel_spectra=None) -> tuple[np.ndarray, float]:
    """Field-varying blur: y_k = g_k Σ_{j,i} k_kji ⊗ (w_j(row) w_i(col) P_kji x_k)  (blend='source'),
    or g_k Σ_{j,i} w_j w_i P_kji (k_kji ⊗ x_k) (blend='output'). Frame cropped as convolve_bands.

    field_kernels [K, Py, Px, S, S], field_power [K, Py, Px], weights_y [Py, H], weights_x [Px, W]
    (rows/columns of the whole render grid). Phases whose weights vanish everywhere are skipped.
    rank r (None: every phase kernel, exact): the phase kernels of each band are replaced by their
    rank-r basis (phase_basis), k_q ≈ Σ_r c_qr B_r, so 'source' is Σ_r B_r ⊗ (W_r x) with the weight
    maps W_r = Σ_q c_qr P_q w_q: r FFT pairs per band instead of one per phase. channel_weights [C, K]
    (blend 'source' only): the channel images Σ_k w_ck y_k, summed in Fourier space (C inverse FFTs).
    basis: the rank-r bases made beforehand (field_basis; field_kernels may then be None).
    bright: pixels left out of the FFTs and convolved apart in float64 (optics.bright).
    power_map: the exact power m_k(s(x)) at every pixel (optics.field_power) in place of the phases' P_kji:
    the weight maps become w_j w_i m_k (None: the sampled powers, interpolated).
    kernel_spectra: with `basis`, each band's basis spectra [r, Fy, Fx//2 + 1] made beforehand
    (convolution.kernel_spectra of basis.bases[k]: the same numbers as made here).
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
        raise OpticsError("channel_weights need blend='source' "
                          "(blend 'output' weights each band after its inverse FFT)")
    wy = weights_y.astype(dtype)
    wx = weights_x.astype(dtype)
    live = live_phases(wy, wx)
    if kernel_spectra is not None and (basis is None or blend != "source"):
        raise OpticsError("kernel_spectra need a field basis and blend 'source'")
    if basis is not None and (basis.live != live or basis.rank != rank):
        raise OpticsError(f"field basis of rank {basis.rank} on {len(basis.live)} phases does not fit rank {rank} "
                          f"on this grid's {len(live)} phases: make it for this grid (field_basis)")
    out = _Output(K, H, W, m, shape, dtype, gains, cw, workers)
    fy, fx = slice(m, H - m), slice(m, W - m)
    worst = 0.0
    for k in range(K):
        x = dimmed(bands[k], bright, dtype)
        exact = None if power_map is None else power_map.band(k, dtype)
        power = field_power[k] if exact is None else np.ones(wy.shape[:1] + wx.shape[:1])
        if rank is None:
            def phase_terms(k=k, exact=exact, power=power):  # lazily: one weight map in memory at a time
                return ((field_kernels[k, j, i], _times(wy[j][:, None] * wx[i][None, :], exact), dtype(power[j, i]))
                        for j, i in live)
        else:
            b_k, coeff, residual = ((basis.bases[k], basis.coeffs[k], basis.residuals[k]) if basis is not None
                                    else phase_basis(np.stack([field_kernels[k, j, i] for j, i in live]), rank))
            worst = max(worst, residual)
            if kernel_spectra is not None:
                _check_spectra(kernel_spectra[k], b_k.shape[0], shape, f"band {k}'s rank-{b_k.shape[0]} basis")
            maps = [(b_k[r], _times(_basis_map(coeff[:, r], live, power, wy, wx, dtype), exact), dtype(1.0))
                    for r in range(b_k.shape[0])]

            def phase_terms(maps=maps):
                return iter(maps)
        terms = phase_terms()
        if blend == "source":
            acc, padded = None, np.zeros(shape, dtype)  # the FFT's zero padding kept: no copy per transform
            weighted = padded[:H, :W]
            spectra = None if kernel_spectra is None else kernel_spectra[k]
            for r, (kern, wmap, power) in enumerate(terms):
                np.multiply(x, wmap, out=weighted)
                if power != 1:
                    weighted *= power
                term = sfft.rfft2(padded, workers=workers)
                term *= (_kernel_spectrum(kern.astype(dtype, copy=False), shape, dtype, workers) if spectra is None
                         else spectra[r])
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
            out.add_frame(k, bright_blur(bands[k], bright, phase_terms(), (H - 2 * m, W - 2 * m), m,
                                          at_output=blend == "output"))
    return out.result(), worst



def _display_period_um(kernel_set, period_um) -> tuple[float, float]:
    """The display period (x, y) in µm: the override, else the KernelSet's own."""
    p = period_um if period_um is not None else kernel_set.period_um
    if p is None:
        raise OpticsError("field kernels need the display period: pass period_um (x, y) in µm")
    p = tuple(float(v) for v in np.broadcast_to(np.asarray(p, dtype=float), (2,)))
    if not all(v > 0 and math.isfinite(v) for v in p):
        raise OpticsError(f"period_um must be > 0, got {p}")
    return p



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
                    "periodic": [per_y, per_x],
                    "banding_period_px": [z * py / d_um / pitch_um, z * px / d_um / pitch_um],
                    "image_distance_um": z, "period_um": [px, py]}
