"""Light past the kernel window: the far field of the two-scale kernel (docs/concepts/physics.md, 'Light past
the kernel window').

The PSF k_λ of a band (a share of the transmitted power) is split at the core window W, the S × S render
pixels of pitch ρ that the render margin allows (the band kernels of psf.compute_kernels):

    k = (1 − o) k_core + f,        Σ f = o − o_acc

k_core: the core kernel (unit sum over W), o: its energy outside W (KernelSet.energy_outside); f: the far
field, the same PSF computed by the engine (d = 0) at the coarse pitch cρ (c odd: a coarse pixel is exactly
c × c render pixels, centred on the core's centre pixel) over a window reaching the acceptance, each coarse
pixel's energy less the core's share of it (coarse pixels wholly inside W: none; straddling W's edge: the
coarse pixel less its render pixels inside W), zero past the acceptance disc |u| ≤ R_acc (the lens's image
circle: acceptance_um); o_acc: the energy beyond it (the far kernels' energy outside their window plus the
corners past the disc).

Applied at low resolution, in float64: the band image's c × c block means x̄ (the scene beyond the render grid,
which is not rendered, continued as its edge: a flat field stays flat, a dark surround stays dark; content
that ends exactly at the grid's edge is continued too), y = x̄ ⊗ f by a linear FFT convolution, the
coarse density interpolated bilinearly back to the render pixels' centres (a partition of unity: the light
is kept), with the gain g = T τ (the core's is T τ (1 − o)). The far field is field-independent: at d > 0
its kernel is the d = 0 one (the display's diffraction orders carry the same power at any d; what d
changes, the banding and the core's shape, lies within the core window).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from udc_render.optics.convolution import OpticsError

# The image circle of the paper's lens (f = 6 mm, f/1.8) covers its sensor, 2048 × 1024 pixels of 1.55 µm
# (l.263, l.275): light diffracted by up to its half-diagonal from the chief ray reaches the sensor plane
PAPER_FRAME_UM = (2048 * 1.55, 1024 * 1.55)


class FarFieldError(OpticsError):
    """A far-field request the optics cannot honour; one line."""


def acceptance_um(frame_um) -> float:
    """R_acc (µm): the lens's image circle, the half-diagonal of the paper's frame (a larger frame: its own)."""
    return max(math.hypot(*PAPER_FRAME_UM), math.hypot(*frame_um)) / 2


def far_window_px(frame_um, margin_um: float, coarse_um: float) -> tuple[int, float]:
    """(odd size in coarse pixels, half-width µm) of the far kernels: the acceptance, or less where no render
    pixel lies that far from a frame pixel (the frame's larger side plus the margin)."""
    half = min(acceptance_um(frame_um), max(frame_um) + margin_um)
    return 2 * math.ceil(half / coarse_um) + 1, half


@dataclass(frozen=True)
class FarField:
    """The far fields f_k of a kernel set (module doc): kernels [K, Sf, Sf] (float64, shares of the transmitted
    power per coarse pixel of coarse × the render pitch; zero for the bands not added), lost [K] (o_k),
    added [K] (Σ f_k), beyond [K] (o_acc,k), used [K] (o_k > threshold), the acceptance and the largest
    negative residue clipped on the coarse pixels straddling the core window (a share of the power)."""
    kernels: np.ndarray
    coarse: int
    pitch_um: float
    lost: np.ndarray
    added: np.ndarray
    beyond: np.ndarray
    used: np.ndarray
    acceptance_um: float
    threshold: float
    clipped: float
    spectra: dict = field(default_factory=dict, compare=False, repr=False)  # (band, FFT shape) -> rfft2 of f_k

    def spectrum(self, k: int, shape) -> np.ndarray:
        """rfft2 of f_k at FFT shape `shape`, made once (far_light)."""
        key = (int(k), tuple(shape))
        if key not in self.spectra:
            self.spectra[key] = sfft.rfft2(self.kernels[k], s=shape)
        return self.spectra[key]

    def describe(self) -> dict:
        return {"model": "two-scale kernel: core window + far field at coarse pitch (optics.far_field)",
                "threshold": self.threshold, "coarse_factor": self.coarse,
                "coarse_pitch_um": self.coarse * self.pitch_um, "far_kernel_px": int(self.kernels.shape[-1]),
                "acceptance_um": self.acceptance_um, "bands_added": int(self.used.sum()),
                "lost_share": self.lost.tolist(), "far_share": self.added.tolist(),
                "beyond_acceptance": self.beyond.tolist(), "clipped_residue": self.clipped,
                "sources_beyond_render": "the render grid's edge, continued"}

    def arrays(self) -> dict:
        """Its fields as arrays (a kernel cache entry: psf.cache.cached_arrays); from_arrays reads them back."""
        return {f: np.asarray(getattr(self, f)) for f in self.__dataclass_fields__ if f != "spectra"}

    @classmethod
    def from_arrays(cls, a) -> "FarField":
        scalars = {"coarse": int, "pitch_um": float, "acceptance_um": float, "threshold": float, "clipped": float}
        names = [f for f in cls.__dataclass_fields__ if f != "spectra"]
        return cls(**{f: scalars[f](a[f]) if f in scalars else a[f] for f in names})


def _blocks(size_px: int, coarse: int) -> tuple[np.ndarray, np.ndarray]:
    """(J, A): the coarse index J of each core offset −h…h (coarse pixel J holds the render offsets
    Jc − (c−1)/2 … Jc + (c−1)/2) and the aggregation matrix A [J, offset] (1 where the offset is in J)."""
    h = size_px // 2
    j = (np.arange(-h, h + 1) + (coarse - 1) // 2) // coarse
    js = np.arange(j.min(), j.max() + 1)
    return js, (j[None, :] == js[:, None]).astype(np.float64)


def make_far_field(core, far, coarse: int, acceptance: float, threshold: float) -> FarField:
    """The far fields of `core` (a KernelSet on the render grid) from `far` (the same PSF, d = 0, at coarse ×
    its pitch, an odd window reaching past the core's): module doc. Every band at once: the core's coarse
    blocks A k Aᵀ as one batched product, the rest elementwise."""
    if coarse < 1 or coarse % 2 == 0:
        raise FarFieldError(f"far_field_coarse = {coarse!r}: expected an odd whole number ≥ 1")
    if not math.isclose(far.pixel_um, coarse * core.pixel_um, rel_tol=1e-9):
        raise FarFieldError(f"far kernels of {far.pixel_um:g} µm pixels: expected {coarse} × {core.pixel_um:g} µm")
    js, agg = _blocks(core.size_px, coarse)
    sf, p = far.size_px, far.size_px // 2
    if js[-1] >= p:
        raise FarFieldError(f"far kernels of {sf} px of {far.pixel_um:g} µm do not reach past the "
                            f"{core.size_px}-px core")
    full = agg.sum(axis=1) == coarse
    inside = np.outer(full, full)
    u = (np.arange(sf) - p) * far.pixel_um
    disc = np.hypot(u[None, :], u[:, None]) <= acceptance
    sl = slice(p + js[0], p + js[-1] + 1)
    K = core.kernels.shape[0]
    lost = np.asarray(core.energy_outside, np.float64)
    used = lost > threshold
    kf = np.asarray(far.kernels, np.float64) * (1.0 - np.asarray(far.energy_outside, np.float64))[:, None, None]
    beyond = 1.0 - np.array([row.sum() for row in kf[:, disc]])  # row by row: the bits of a 1-d sum
    out, idx = np.zeros((K, sf, sf)), np.flatnonzero(used)
    core_blocks = agg @ (np.asarray(core.kernels[idx], np.float64) * (1.0 - lost[idx])[:, None, None]) @ agg.T
    f = np.where(disc, kf[idx], 0.0)
    f[:, sl, sl] = np.where(inside, 0.0, f[:, sl, sl] - core_blocks)
    clipped = max(0.0, float(-f.min())) if idx.size else 0.0
    out[idx] = np.maximum(f, 0.0)
    added = out.sum(axis=(1, 2))
    return FarField(out, int(coarse), float(core.pixel_um), lost, added, beyond, used, float(acceptance),
                    float(threshold), clipped)


def far_square_share(far, side_x_px: float, side_y_px: float, region_px: int,
                     region_y_px: int | None = None) -> np.ndarray:
    """[K] the share of the transmitted power that the far field f (optics.far_field.FarField) brings to the
    region's pixels, on average, from a uniform square (or rectangle) side_x × side_y render pixels centred on
    them: Σ_J f[J] A_x(J) A_y(J), A(J) the mean over the region's pixels p of the share of coarse pixel J's render
    offsets u whose source p − u lies in the square (|p − u| ≤ side / 2; side inf: a square that reaches the
    render grid's edges, continued past them as the far field continues the render). The region is region_px
    wide and region_y_px (default region_px) tall."""
    c, h = far.coarse, far.kernels.shape[-1] // 2
    offsets = (np.arange(-h, h + 1) * c)[:, None] + np.arange(c)[None, :] - (c - 1) // 2  # [J, c] render px

    def share(side, n):
        p = np.arange(n) - (n - 1) / 2
        return (np.abs(p[None, None, :] - offsets[:, :, None]) <= side / 2).mean(axis=(1, 2))
    rows = region_px if region_y_px is None else region_y_px
    return np.einsum("kij,i,j->k", far.kernels, share(side_y_px, rows), share(side_x_px, region_px))


def _upsampling(n_out: int, start: int, n_blocks: int, coarse: int) -> np.ndarray:
    """[n_out, n_blocks + 2]: linear interpolation at render pixels start … start + n_out − 1 from the coarse
    samples of blocks −1 … n_blocks (block B centred at render pixel Bc + (c − 1)/2)."""
    t = (np.arange(start, start + n_out) - (coarse - 1) / 2) / coarse + 1.0
    i0 = np.floor(t).astype(int)
    frac = t - i0
    m = np.zeros((n_out, n_blocks + 2))
    rows = np.arange(n_out)
    m[rows, i0] = 1.0 - frac
    m[rows, np.minimum(i0 + 1, n_blocks + 1)] += frac
    return m


def _block_means(band: np.ndarray, coarse: int, nby: int, nbx: int) -> np.ndarray:
    """c × c block means [nby, nbx] (float64) of one band, its last rows and columns held to fill the blocks."""
    H, W = band.shape
    x = np.pad(band, ((0, nby * coarse - H), (0, nbx * coarse - W)), mode="edge")
    return x.reshape(nby, coarse, nbx, coarse).mean(axis=(1, 3), dtype=np.float64)


def far_light(bands: np.ndarray, far: FarField, margin_px: int, weights: np.ndarray,
              blocks: dict | None = None) -> np.ndarray:
    """Σ_k weights[c, k] (x_k ⊗ f_k) on the sensor frame [C, H − 2m, W − 2m] (float64; module doc): bands
    [K, H, W] of the render grid (margin m), weights [C, K] (the gains T τ times channel weights, or a
    diagonal for the bands themselves). Bands not in far.used are skipped. blocks: a dict that keeps each
    band's block means for the next call on the same bands (views of one render share them)."""
    K, H, W = bands.shape
    w = np.asarray(weights, np.float64)
    if far.kernels.shape[0] != K or w.ndim != 2 or w.shape[1] != K:
        raise FarFieldError(f"far field of {far.kernels.shape[0]} bands, weights {w.shape}: expected {K} bands")
    c, p = far.coarse, far.kernels.shape[-1] // 2
    nby, nbx = -(-H // c), -(-W // c)
    pad = p + 1
    shape = tuple(sfft.next_fast_len(n + 2 * pad + 2 * p, real=True) for n in (nby, nbx))
    acc = [None] * w.shape[0]
    blocks = {} if blocks is None else blocks
    for k in np.flatnonzero(far.used):
        if (k, c) not in blocks:
            blocks[k, c] = _block_means(bands[k], c, nby, nbx)
        xs = np.pad(blocks[k, c], pad, mode="edge")
        spec = sfft.rfft2(xs, s=shape) * far.spectrum(k, shape)
        for ch in np.flatnonzero(w[:, k]):
            acc[ch] = spec * w[ch, k] if acc[ch] is None else acc[ch] + spec * w[ch, k]
    m = int(margin_px)
    uy = _upsampling(H - 2 * m, m, nby, c)
    ux = _upsampling(W - 2 * m, m, nbx, c)
    out = np.zeros((w.shape[0], H - 2 * m, W - 2 * m))
    for ch, a in enumerate(acc):
        if a is not None:
            y = sfft.irfft2(a, s=shape)[2 * p:2 * p + nby + 2, 2 * p:2 * p + nbx + 2]
            out[ch] = uy @ np.maximum(y, 0.0) @ ux.T  # the FFT's round-off (1e-16 of the peak) kept non-negative
    return out
