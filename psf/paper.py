"""The paper's PSF recipe as printed (Zhou et al. 2021, l.164–171 and l.263): `psf --method paper`.

    M = |DFT(g_p)|²,   k = M↓r / Σ M↓r,   r = (2.41, 2.98, 3.44) at λ = (640, 520, 450) nm.

r is the printed one. The paper's formula r = δ_N N ρ / (λ f) with N δ_N = 3333 µm, ρ = 3.1 µm and
f = 6000 µm gives 2.69, 3.31, 3.83: the printed values are 0.896, 0.900, 0.899 of it, as if the sampled
window were ≈ 3.0 mm (docs/PHYSICS.md §2). Down-sampling by the printed r maps each pixel onto r DFT
cells of λf/(Nδ_N) where it spans the formula's r, so the recipe's kernels are the true pattern sampled
at (printed / formula) · ρ: wider, in pixels, by formula / printed (1.117 in R). Other rigs and
wavelengths keep that ratio (paper_ratio_r).

"Down-sampling" is read as cubic interpolation, which the paper does not specify further: scipy's cubic
B-spline (ndimage.map_coordinates, order 3, spline prefilter; the interpolant skimage.transform.resize
and rescale use at order = 3), clipped to the intensity's range as skimage's clip = True does (the
spline undershoots below 0 near the Airy nulls), sampled at the pixel centres about u = 0 (a resize that
kept the array's corner instead would shift every image by a fraction of a pixel), with the DFT's
periodic boundary. No anti-aliasing filter: the paper names none, and a Gaussian pre-filter
(skimage's anti_aliasing, σ = (r − 1)/2 cells) would add a blur the recipe does not state. The pupil is
zero-padded 2× (PAD_FACTOR), which samples the intensity at its Nyquist rate.
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from .fourier import WORKERS
from .lens import Lens

__all__ = ["PRINTED_R", "PAPER_PIXEL_UM", "PAD_FACTOR", "formula_ratio_r", "paper_ratio_r", "paper_kernel"]

PRINTED_R = {450.0: 3.44, 520.0: 2.98, 640.0: 2.41}  # l.263, for the B, G, R channels
PAPER_PIXEL_UM = 3.1  # the packed RGGB plane's pitch (l.263: 1.55 µm × 2)
PAD_FACTOR = 2


def formula_ratio_r(wavelength_nm: float, lens: Lens, pixel_um: float) -> float:
    """The paper's formula (eq. 5): r = δ_N N ρ / (λ f), N δ_N the aperture D."""
    return lens.aperture_um * pixel_um / (wavelength_nm * 1e-3 * lens.focal_length_um)


def paper_ratio_r(wavelength_nm: float, lens: Lens, pixel_um: float) -> float:
    """The r the recipe down-samples by: the formula's r × (printed / formula) on the paper's rig (Lens()
    and ρ = 3.1 µm), which gives the printed r there at 640, 520 and 450 nm; between them the ratio is
    interpolated linearly in λ, beyond them the nearest one is kept."""
    rig = Lens()
    lam = np.array(sorted(PRINTED_R))
    ratio = [PRINTED_R[w] / formula_ratio_r(w, rig, PAPER_PIXEL_UM) for w in lam]
    return formula_ratio_r(wavelength_nm, lens, pixel_um) * float(np.interp(wavelength_nm, lam, ratio))


def _cubic_samples(intensity: np.ndarray, step_y: float, step_x: float, size_px: int) -> np.ndarray:
    """intensity [L, L] (u = 0 at L//2) at the size_px² points L//2 + (j − size_px//2)·step, by cubic
    B-spline interpolation on the periodic grid, clipped to the intensity's range."""
    from scipy.ndimage import map_coordinates
    j = np.arange(size_px) - size_px // 2
    centre = intensity.shape[0] // 2
    yy, xx = np.meshgrid(centre + j * step_y, centre + j * step_x, indexing="ij")
    out = map_coordinates(intensity, [yy, xx], order=3, mode="grid-wrap", prefilter=True)
    return np.clip(out, intensity.min(), intensity.max())


def paper_kernel(g: np.ndarray, dx_um: float, dy_um: float, wavelength_nm: float, lens: Lens, pixel_um: float,
                 size_px: int) -> tuple[np.ndarray, float]:
    """(kernel [S, S], r): the DFT intensity of the pupil field g [ny, nx] (pitch dx, dy), zero-padded
    PAD_FACTOR×, cubic-resampled by 1/r with the printed r (module doc), and r.

    The recipe's pixel is r cells of the DFT of the aperture's N δ_N = D, i.e. r L δ / D cells of this
    L-point DFT; like the paper (the sensor at the focal plane) it ignores the image distance. The
    kernel sums to the power on the DFT cells inside the window (S recipe pixels per axis), so that
    energy_outside keeps its meaning (point samples of an Airy core finer than the pixel would sum to
    several times the power)."""
    ny, nx = g.shape
    L = sfft.next_fast_len(PAD_FACTOR * max(nx, ny))
    # |G|² dxdy/L²: the power on each DFT cell (Parseval: Σ = ∫|g|²); unchanged by the pupil's offset
    intensity = np.abs(sfft.fftshift(sfft.fft2(g, s=(L, L), workers=WORKERS))).astype(np.float64) ** 2 * (
        dx_um * dy_um / L ** 2)
    r = paper_ratio_r(wavelength_nm, lens, pixel_um)
    step_x, step_y = r * L * dx_um / lens.aperture_um, r * L * dy_um / lens.aperture_um
    kernel = _cubic_samples(intensity, step_y, step_x, size_px)
    return kernel * (_window_energy(intensity, step_y, step_x, size_px) / kernel.sum()), r


def _window_energy(intensity: np.ndarray, step_y: float, step_x: float, size_px: int) -> float:
    """The power on the window: Σ of the per-cell power over the DFT cells whose centres lie within
    size_px recipe pixels (size_px · step cells) about u = 0."""
    L = intensity.shape[0]
    cells = np.abs(np.arange(L) - L // 2)
    rows, cols = cells <= size_px / 2 * step_y, cells <= size_px / 2 * step_x
    return float(intensity[np.ix_(rows, cols)].sum())
