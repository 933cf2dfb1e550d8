"""The optics of a band image made of three planes: a monitor's render is x_k = Σ_c M_ck r_c exactly (its panel's
primaries c = R, G, B at band means M [3, K], the drive-weighted planes r [3, H, W]: render.analytic and the
rgb_matrix path; BandImage.primaries_image), so a view's channel sums (apply_kernels with channel_weights w) are

    y_C = Σ_k w_Ck g_k (x_k ⊗ k_k) = Σ_c r_c ⊗ H_Cc,    H_Cc = Σ_k w_Ck g_k M_ck k_k

by linearity: 3 forward FFTs of the planes (shared by the views), C × 3 kernel spectra of the summed kernels (made
by a worker's first item and kept) and C inverse FFTs per view, in place of K forward FFTs, K kernel spectra and
C × K products. The far field the same way: y_C = Σ_c r̄_c ⊗ F_Cc, F_Cc = Σ_k v_Ck M_ck f_k (optics.far_field). The
same numbers as the band path but for float32 round-off in another order (tests/udc_render/test_primaries.py).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.fft as sfft

from udc_render.optics.convolution import OpticsError, _check_margin, _kernel_spectrum, _precision, _workers, fft_shape
from udc_render.optics.far_field import FarField, _block_means, _upsampling
from udc_render.optics.kept import digest, kept, sha1_of

KEEP_SPECTRA = 4  # the summed kernels' spectra kept per process: a worker's views (C × 3 spectra each, 16 MB apiece)
KEEP_FAR = 12  # the far fields' summed spectra kept (a view's channel C each, small: the coarse grid)
_SPECTRA: OrderedDict = OrderedDict()
_FAR: OrderedDict = OrderedDict()


@dataclass(frozen=True)
class Primaries:
    """planes [3, H, W] (float32) and matrix [3, K] with bands x_k = Σ_c matrix[c, k] planes[c]; spectra: rfft2 of
    the planes at the convolution's FFT shape (plane_spectra: made once, shared by the views), or None."""
    planes: np.ndarray
    matrix: np.ndarray
    spectra: np.ndarray | None = None

    @cached_property
    def peaks(self) -> np.ndarray:
        """max |r_c| of each plane [3] (float64; NaN where a plane holds one), made once and shared by the views."""
        flat = self.planes.reshape(self.planes.shape[0], -1)
        return np.maximum(np.abs(flat.max(axis=1).astype(np.float64)), np.abs(flat.min(axis=1).astype(np.float64)))


def plane_spectra(planes: np.ndarray, size_px: int, margin_px: int, precision: str = "float32",
                  workers: int | None = None) -> np.ndarray:
    """rfft2 of each plane [P, H, W] at fft_shape((H, W), size_px, margin_px): [P, Fy, Fx//2 + 1]."""
    dtype = _precision(precision)
    shape = fft_shape(planes.shape[1:], size_px, margin_px)
    return np.stack([sfft.rfft2(p.astype(dtype, copy=False), s=shape, workers=_workers(workers)) for p in planes])


def _summed(weights: np.ndarray, kernels: np.ndarray) -> np.ndarray:
    """Σ_k weights[k] kernels[k] in float64 (a loop: the same bits on any BLAS), bands of zero weight skipped."""
    out = np.zeros(kernels.shape[1:])
    for k in np.flatnonzero(weights):
        out += weights[k] * np.asarray(kernels[k], np.float64)
    return out


def _key(kernels: np.ndarray, w: np.ndarray, matrix: np.ndarray, shape, *more) -> tuple:
    """What a summed spectrum depends on: the kernels' bytes, the weights, the matrix, the FFT shape (and more)."""
    return (digest(kernels), kernels.shape, kernels.dtype.str,
            sha1_of(w, matrix), tuple(shape), *more)


def _summed_spectra(kernels: np.ndarray, w: np.ndarray, matrix: np.ndarray, shape, dtype,
                    workers: int) -> np.ndarray:
    """spectra [C, 3, …] of H_Cc (module doc), made once per (kernels, weights, matrix, shape, dtype) and kept
    (optics.kept: KEEP_SPECTRA sets per process, and in a dataset job's kernel cache): a job's items share their
    views' kernels, gains and sensor weights, so each item's C × 3 kernel FFTs are made once."""
    return kept(_SPECTRA, KEEP_SPECTRA, _key(kernels, w, matrix, shape, np.dtype(dtype).str), lambda: np.stack([
        np.stack([_kernel_spectrum(_summed(w[C] * matrix[c], kernels).astype(dtype), shape, dtype, workers)
                  for c in range(matrix.shape[0])]) for C in range(w.shape[0])]))


def convolve_primaries(p: Primaries, kernels: np.ndarray, margin_px: int, gains, channel_weights,
                       precision: str = "float32", workers: int | None = None) -> np.ndarray:
    """The channel sums [C, H − 2m, W − 2m] of Σ_k w_Ck g_k (x_k ⊗ k_k) through the planes (module doc); kernels
    [K, S, S], gains [K], channel_weights [C, K]."""
    dtype = _precision(precision)
    workers = _workers(workers)
    planes, matrix = p.planes, np.asarray(p.matrix, np.float64)
    w = np.asarray(channel_weights, np.float64) * np.asarray(gains, np.float64)[None, :]
    K, S = kernels.shape[0], kernels.shape[-1]
    _, H, W = planes.shape
    m = int(margin_px)
    _check_margin(m, S, (H, W))
    if matrix.shape != (planes.shape[0], K) or w.shape[1] != K:
        raise OpticsError(f"primaries {matrix.shape} and channel weights {w.shape}: expected [P, K={K}] and [C, K]")
    shape = fft_shape((H, W), S, m)
    spectra = p.spectra if p.spectra is not None else plane_spectra(planes, S, m, precision, workers)
    out = np.empty((w.shape[0], H - 2 * m, W - 2 * m), dtype)
    summed = _summed_spectra(kernels, w, matrix, shape, dtype, workers)
    for C in range(w.shape[0]):
        acc = None
        for c in range(planes.shape[0]):
            term = summed[C][c] * spectra[c]
            if acc is None:
                acc = term
            else:
                acc += term
        out[C] = sfft.irfft2(acc, s=shape, workers=workers)[m:H - m, m:W - m]
    return out


def _far_spectra(kernels: np.ndarray, w: np.ndarray, matrix: np.ndarray, shape) -> np.ndarray:
    """rfft2 of F_Cc = Σ_k w_k M_ck f_k for each plane c (module doc) at `shape`, made once per (far kernels, weights,
    matrix, shape) and kept (optics.kept: KEEP_FAR sets per process, and in a dataset job's kernel cache)."""
    return kept(_FAR, KEEP_FAR, _key(kernels, w, matrix, shape), lambda: np.stack([
        sfft.rfft2(_summed(w * matrix[c], kernels), s=shape) for c in range(matrix.shape[0])]))


def far_light_primaries(p: Primaries, far: FarField, margin_px: int, weights: np.ndarray,
                        blocks: dict | None = None) -> np.ndarray:
    """far_field.far_light through the planes (module doc): [C, H − 2m, W − 2m] float64 of Σ_k weights[C, k]
    (x_k ⊗ f_k) over the bands in far.used; blocks: a dict keeping the planes' block means for the next view."""
    planes, matrix = p.planes, np.asarray(p.matrix, np.float64)
    _, H, W = planes.shape
    w = np.where(far.used[None, :], np.asarray(weights, np.float64), 0.0)
    c_, half = far.coarse, far.kernels.shape[-1] // 2
    nby, nbx = -(-H // c_), -(-W // c_)
    pad = half + 1
    shape = tuple(sfft.next_fast_len(n + 2 * pad + 2 * half, real=True) for n in (nby, nbx))
    blocks = {} if blocks is None else blocks
    spectra = []
    for c in range(planes.shape[0]):
        if ("plane", c, c_) not in blocks:
            blocks["plane", c, c_] = _block_means(planes[c], c_, nby, nbx)
        spectra.append(sfft.rfft2(np.pad(blocks["plane", c, c_], pad, mode="edge"), s=shape))
    m = int(margin_px)
    uy, ux = _upsampling(H - 2 * m, m, nby, c_), _upsampling(W - 2 * m, m, nbx, c_)
    out = np.zeros((w.shape[0], H - 2 * m, W - 2 * m))
    for C in range(w.shape[0]):
        if not w[C].any():
            continue
        summed = _far_spectra(far.kernels, w[C], matrix, shape)
        acc = sum(spectra[c] * summed[c] for c in range(len(spectra)))
        y = sfft.irfft2(acc, s=shape)[2 * half:2 * half + nby + 2, 2 * half:2 * half + nbx + 2]
        out[C] = uy @ np.maximum(y, 0.0) @ ux.T  # the FFT's round-off kept non-negative, as far_light
    return out
