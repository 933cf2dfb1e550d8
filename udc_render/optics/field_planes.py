"""The field blend through a monitor's three planes (issue 46): one basis of weight maps shared by the bands.

convolve_field's 'source' blend at rank r is y_C = Σ_k w_Ck g_k Σ_r B_kr ⊗ (x_k W_kr), with the weight maps
W_kr = (w_yᵀ C_kr w_x) · m_k (optics.field). A monitor's bands are x_k = Σ_c M_ck r_c (optics.primaries), and the
K·r maps are all smooth functions of the one mask shift s(x): they share a span of few maps. With an orthonormal
basis U_j of it (the leading eigenvectors of the maps' Gram matrix, each map weighted by ‖B_kr‖₁) and the
least-squares coefficients A_kr,j of each map on its first J members:

    y_C ≈ Σ_c Σ_{j<J} H_Ccj ⊗ (r_c U_j),     H_Ccj = Σ_{k,r} w_Ck g_k M_ck A_kr,j B_kr

3J forward FFTs and 3 inverse per view, in place of K·r forward FFTs (120 at K = 30, r = 4); the 9J spectra of H
are made once per worker and view (they depend on the view's gains, the sensor's weights and the monitor only).
The truncation moves a pixel's electrons by at most (a kernel acts on a map bounded by its sup norm)

    Δ_C(J) = Σ_{k,r} |w_Ck| g_k ‖B_kr‖₁ x̂_k ‖W_kr − Σ_{j<J} A_kr,j U_j‖∞,    x̂_k = Σ_c |M_ck| max|r_c| ≥ max|x_k|

which is recorded with J, but is loose (11 e⁻ at J = 4 where the largest change is 0.32 e⁻ on the paper's T-OLED at
2 mm): J is a knob (SynthConfig.field_planes_rank) whose default comes from the measured error against run time
(benchmarks/bench_field_knobs.py --planes). The basis is a fixed function of the display, the lens and the render
grid: a derived entry of the kernel cache (synth_kernels.store_field_planes).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from udc_render.optics.convolution import OpticsError, _kernel_spectrum, _precision, _workers, fft_shape
from udc_render.optics.field import FieldBasis, _basis_map
from udc_render.optics.field_power import PowerMap
from udc_render.optics.kept import digest, kept, sha1_of

MAX_RANK = 8  # maps stored: the T-OLED needs 3-4 at 0.05 σ (benchmarks/bench_field_knobs.py --planes)
ROW_BLOCK = 32  # rows of the K·r maps made at a time (K·r · 32 · W float64: 79 MB at 120 maps, W = 2560)
# The basis costs 45-55 CPU-s per display once (the kernel cache keeps it) and saves ~7.5 CPU-s an item on the paper's
# frame (benchmarks/bench_field_planes.py): a randomized job takes it from this many items per panel on
PAYBACK_ITEMS = 8
KEEP_SPECTRA = 2  # sets of summed kernel spectra kept per process (a worker's views), each of its J members
_SPECTRA: OrderedDict = OrderedDict()


@dataclass(frozen=True, eq=False)
class PlaneBasis:
    """The weight maps of a field basis on a render grid (one per band k and basis member r: n = Σ_k r_k, a band's
    rank may be below the basis's), in one basis: W_i ≈ Σ_{j<J} coeffs[i, j] maps[j], i = (k, r) in band order.
    maps [J, H, W] float32, coeffs [n, J], residual_sup [n, J + 1] = ‖W_i − Σ_{j<J'} A_ij U_j‖∞ for J' = 0…J,
    kernel_l1 [n] = ‖B_kr‖₁, band [n]: each map's band k, values: the weighted Gram matrix's eigenvalues."""
    maps: np.ndarray
    coeffs: np.ndarray
    residual_sup: np.ndarray
    kernel_l1: np.ndarray
    band: np.ndarray
    values: np.ndarray

    @property
    def key(self) -> str:
        """A fingerprint of the basis (its coefficients and residuals), for the spectra kept per process."""
        return sha1_of(self.coeffs, self.residual_sup)

    def arrays(self) -> dict:
        return {"maps": self.maps, "coeffs": self.coeffs, "residual_sup": self.residual_sup,
                "kernel_l1": self.kernel_l1, "band": self.band, "values": self.values}

    @classmethod
    def from_arrays(cls, a) -> "PlaneBasis":
        return cls(a["maps"], np.asarray(a["coeffs"]), np.asarray(a["residual_sup"]), np.asarray(a["kernel_l1"]),
                   np.asarray(a["band"]), np.asarray(a["values"]))


def _rows_of_maps(basis: FieldBasis, powers: np.ndarray, power_map: PowerMap | None, wy: np.ndarray,
                  wx: np.ndarray, rows: slice) -> np.ndarray:
    """W_kr on rows `rows`: [Σ_k r_k, n_rows · W] float64 (convolve_field's weight maps, in float64)."""
    out = []
    for k, coeff in enumerate(basis.coeffs):
        exact = None if power_map is None else np.asarray(power_map.band(k)[rows], np.float64)
        for r in range(coeff.shape[1]):
            w = _basis_map(coeff[:, r], basis.live, powers[k], wy[:, rows], wx, np.float64)
            out.append((w if exact is None else w * exact).ravel())
    return np.stack(out)


def plane_basis(basis: FieldBasis, field_power: np.ndarray | None, power_map: PowerMap | None, wy: np.ndarray,
                wx: np.ndarray, max_rank: int = MAX_RANK) -> PlaneBasis:
    """The shared basis of a field basis's weight maps on the grid of wy [Py, H], wx [Px, W] (module doc), in three
    passes over row blocks: the weighted Gram matrix, the maps U_j (rounded to float32) with the coefficients
    (A = ⟨W, U⟩ ⟨U, U⟩⁻¹ in float64, so the stored float32 maps are the ones fitted), the residuals' sup norms.
    field_power [K, Py, Px]: the phases' powers (used when power_map is None)."""
    K, H, W = len(basis.bases), wy.shape[1], wx.shape[1]
    powers = (np.ones((K, wy.shape[0], wx.shape[0])) if power_map is not None
              else np.asarray(field_power, np.float64))
    l1 = np.array([float(np.abs(np.asarray(b[i], np.float64)).sum()) for b in basis.bases for i in range(b.shape[0])])
    band = np.array([k for k, b in enumerate(basis.bases) for _ in range(b.shape[0])])
    n, scale = l1.size, l1[:, None]
    blocks = [slice(i, min(i + ROW_BLOCK, H)) for i in range(0, H, ROW_BLOCK)]
    gram = np.zeros((n, n))
    for rows in blocks:
        x = (_rows_of_maps(basis, powers, power_map, wy, wx, rows) * scale).astype(np.float32)
        gram += (x @ x.T).astype(np.float64)
    values, vectors = np.linalg.eigh(gram)
    values, vectors = values[::-1], vectors[:, ::-1]
    J = max(1, min(int(max_rank), int(np.count_nonzero(values > values[0] * 1e-24))))
    project = vectors[:, :J] / np.sqrt(values[:J])[None, :]
    maps = np.empty((J, H, W), np.float32)
    inner, overlap = np.zeros((n, J)), np.zeros((J, J))
    for rows in blocks:
        w = _rows_of_maps(basis, powers, power_map, wy, wx, rows)
        u = (project.T @ (w * scale)).astype(np.float32)
        maps[:, rows] = u.reshape(J, -1, W)
        u = u.astype(np.float64)
        inner += w @ u.T
        overlap += u @ u.T
    coeffs = np.linalg.solve(overlap, inner.T).T
    sup = np.zeros((n, J + 1))
    for rows in blocks:
        e = _rows_of_maps(basis, powers, power_map, wy, wx, rows)
        u = maps[:, rows].reshape(J, -1)
        for j in range(J + 1):
            np.maximum(sup[:, j], np.abs(e).max(axis=1), out=sup[:, j])
            if j < J:
                e -= coeffs[:, j:j + 1] * u[j].astype(np.float64)[None, :]
    return PlaneBasis(maps, coeffs, sup, l1, band, values)


def planes_bound(pb: PlaneBasis, weights: np.ndarray, gains: np.ndarray, matrix: np.ndarray,
                 plane_peaks: np.ndarray) -> np.ndarray:
    """[J + 1] max_C Δ_C(J') for J' = 0…J (module doc) for channel weights [C, K], gains [K], the primaries' matrix
    [3, K] and the planes' max |r_c| [3]: a bound on any pixel's change, loose by ~35× on the paper's T-OLED."""
    x_hat = np.abs(np.asarray(matrix, np.float64)).T @ np.abs(np.asarray(plane_peaks, np.float64))
    amp = np.abs(np.asarray(weights, np.float64)) * (np.asarray(gains, np.float64) * x_hat)[None, :]  # [C, K]
    return ((amp[:, pb.band] * pb.kernel_l1[None, :]) @ pb.residual_sup).max(axis=0)


def _summed_spectra(pb: PlaneBasis, bases: list, weights: np.ndarray, matrix: np.ndarray, J: int, shape,
                    dtype, workers: int) -> list:
    """spectra[j] [C, P, …] of H_Ccj (module doc), j < J, each member made once per (plane basis, the field basis's
    kernels, weights, matrix, shape, dtype, j) and kept (optics.kept: KEEP_SPECTRA sets of members per process, and
    in a dataset job's kernel cache)."""
    key = (pb.key, digest(*bases), sha1_of(weights, matrix), tuple(shape), np.dtype(dtype).str)
    C, P = weights.shape[0], matrix.shape[0]
    return [kept(_SPECTRA, KEEP_SPECTRA * pb.maps.shape[0], key + (j,), lambda j=j: np.stack([np.stack([
        _kernel_spectrum(_summed_kernel(bases, weights[Cc] * matrix[c], pb.coeffs[:, j]).astype(dtype), shape, dtype,
                         workers) for c in range(P)]) for Cc in range(C)])) for j in range(J)]


def _summed_kernel(bases: list, band_weights: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Σ_{k,r} band_weights[k] a[(k, r)] B_kr in float64, a [Σ_k r_k] in band order (bands of zero weight skipped)."""
    out = np.zeros(bases[0].shape[-2:])
    i = 0
    for k, b in enumerate(bases):
        if band_weights[k] != 0:
            for r in range(b.shape[0]):
                out += band_weights[k] * a[i + r] * np.asarray(b[r], np.float64)
        i += b.shape[0]
    return out


def convolve_field_planes(planes: np.ndarray, matrix: np.ndarray, pb: PlaneBasis, basis: FieldBasis, gains,
                          channel_weights, margin_px: int, J: int, precision: str = "float32",
                          workers: int | None = None) -> np.ndarray:
    """The channel images [C, H − 2m, W − 2m] of the rank-r 'source' blend through the planes [3, H, W] at the
    shared basis's first J maps (module doc): 3J forward FFTs, the kept spectra of H, C inverse FFTs."""
    dtype = _precision(precision)
    workers = _workers(workers)
    P, H, W = planes.shape
    if pb.maps.shape[1:] != (H, W) or not 1 <= J <= pb.maps.shape[0]:
        raise OpticsError(f"plane basis of {pb.maps.shape[0]} maps on {pb.maps.shape[1:]} px: no rank {J} "
                          f"on a {H} × {W} grid")
    m = int(margin_px)
    shape = fft_shape((H, W), basis.bases[0].shape[-1], m)
    weights = np.asarray(channel_weights, np.float64) * np.asarray(gains, np.float64)[None, :]
    spectra = _summed_spectra(pb, basis.bases, weights, np.asarray(matrix, np.float64), J, shape, dtype, workers)
    padded = np.zeros(shape, dtype)
    view = padded[:H, :W]
    acc, term = None, None
    for c in range(P):
        for j in range(J):
            np.multiply(planes[c], pb.maps[j], out=view, casting="unsafe")
            f = sfft.rfft2(padded, workers=workers)
            if acc is None:
                acc, term = np.zeros((weights.shape[0],) + f.shape, f.dtype), np.empty_like(f)
            for Cc in range(weights.shape[0]):
                acc[Cc] += np.multiply(spectra[j][Cc][c], f, out=term)
    return np.stack([sfft.irfft2(a, s=shape, workers=workers)[m:H - m, m:W - m] for a in acc])
