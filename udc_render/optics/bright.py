"""Very bright pixels (BrightPixels: the sun beside a dim room), left out of the FFTs of the optics and
convolved apart, in float64, on the boxes they occupy (bright_blur): a float32 FFT spreads a round-off of
about 0.6 · ε32 · ‖x‖₂ / √N over every pixel of the frame (measured: a point source on a 768 × 1280 grid),
which the sun's 1e9 dynamic range would lift above the sensor's noise floor (pipeline.bright_pixels
chooses them).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BrightPixels:
    """Pixels of the render grid convolved apart in float64 (this module's doc): mask [H, W] and the boxes
    (row slice, column slice) that hold them (scipy.ndimage.find_objects of its clusters)."""
    mask: np.ndarray
    boxes: tuple

    @classmethod
    def of_mask(cls, mask: np.ndarray) -> "BrightPixels | None":
        """The clusters of `mask` (8-connected), or None when it is empty."""
        if not mask.any():
            return None
        from scipy import ndimage  # here: scipy.ndimage and scipy.signal cost a worker's start-up ~1 s
        labels, _ = ndimage.label(mask, structure=np.ones((3, 3)))
        return cls(mask, tuple(ndimage.find_objects(labels)))


def dimmed(x: np.ndarray, bright: BrightPixels | None, dtype) -> np.ndarray:
    """x with the bright pixels set to 0 (a copy), in dtype; x itself (as dtype) without bright pixels."""
    x = x.astype(dtype, copy=False)
    return x if bright is None else np.where(bright.mask, dtype(0), x)


def bright_blur(x: np.ndarray, bright: BrightPixels, terms, frame_shape, m: int, at_output: bool = False) -> np.ndarray:
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
