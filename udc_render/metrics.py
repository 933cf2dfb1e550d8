"""Image-quality figures and the two metric protocols, one definition each (capture summaries,
DeP, the restorers' evaluation).

Protocols (every table names the one it uses):

- ``paper``: what the paper measured (16-bit RAW, l.456; γ includes the camera gain, l.261): linear
  camera values in [0, 1] of the white level, no white balance, no tone curve. A capture is scored
  on its packed RAW [4, H/2, W/2] against the ground truth's RGGB samples; a restored image as
  linear camera RGB against the ground truth.
- ``srgb``: for perceptual comparisons: camera RGB × the daylight balance (D65 neutral), clipped to
  [0, 1], sRGB-encoded (no colour matrix), BORDER_PX cropped on each side (display_referred).

PSNR = 10 log10(peak² / MSE) with peak 1 in both.
"""
from __future__ import annotations

import math

import numpy as np

BORDER_PX = 16
BORDER_TEXT = f"{BORDER_PX}-px border cropped"  # display_referred crops it; restore.metrics crops the paper pair
PROTOCOLS = {
    "paper": "linear camera values in [0, 1] of the white level, no white balance, no tone curve "
             "(captures: packed RAW against the ground truth's RGGB samples)",
    "srgb": f"daylight-balanced camera RGB, clipped to [0, 1], sRGB-encoded, {BORDER_TEXT}",
}


def encode_srgb(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear values clipped to [0, 1] (the srgb protocol and every preview)."""
    x = np.clip(linear, 0.0, 1.0)
    low = x <= 0.0031308
    low_values = 12.92 * x[low]
    np.power(x, 1 / 2.4, out=x)  # in place: a frame holds millions of values
    x *= 1.055
    x -= 0.055
    x[low] = low_values
    return x


def psnr_db(a: np.ndarray, b: np.ndarray, peak: float = 1.0) -> float:
    """10 log10(peak² / MSE); inf for identical images."""
    d = np.subtract(a, b, dtype=np.float64)
    mse = float(np.mean(np.square(d, out=d)))  # in place: frames hold millions of values
    return math.inf if mse == 0 else 10 * math.log10(peak ** 2 / mse)


def border_px(h: int, w: int) -> int:
    """The border cropped from an h × w frame: BORDER_PX, none for frames of 4 · BORDER_PX px or less."""
    return BORDER_PX if min(h, w) > 4 * BORDER_PX else 0


def display_referred(rgb: np.ndarray, balance: np.ndarray) -> np.ndarray:
    """[3, H, W] → the srgb protocol's image [3, H − 2b, W − 2b] in [0, 1], float64 (module doc)."""
    return encode_srgb(without_border(np.clip(np.asarray(rgb, np.float64) * balance[:, None, None], 0, 1)))


def without_border(a: np.ndarray) -> np.ndarray:
    """[..., H, W] without its border_px border (a view)."""
    b = border_px(*a.shape[-2:])
    return a[..., b:a.shape[-2] - b or None, b:a.shape[-1] - b or None]


def display_referred_quarters(quarters: np.ndarray, range_dn: float, balance: np.ndarray) -> np.ndarray:
    """display_referred(quarters / 4 / range_dn, balance) bit for bit, for whole-number quarters [3, H, W] (an
    integer mosaic's bilinear demosaic in quarter DN: sensor.bilinear_quarters), through one table per channel over
    their range: a lookup per pixel in place of a power (the summaries' srgb PSNR of every capture)."""
    if not np.issubdtype(quarters.dtype, np.integer):
        raise TypeError(f"display_referred_quarters: integer quarters expected, got {quarters.dtype}")
    q = without_border(quarters)
    lo, hi = (int(q.min()), int(q.max())) if q.size else (0, 0)
    steps = np.arange(lo, hi + 1, dtype=np.float64) / 4 / range_dn  # the float64 operations of quarters / 4 / range_dn
    out = np.empty(q.shape)
    for c in range(q.shape[0]):
        table = encode_srgb(np.clip(steps * balance[c], 0, 1))
        np.take(table, q[c] - lo, out=out[c])
    return out


def paper_linear(x: np.ndarray) -> np.ndarray:
    """The paper protocol's values: linear, clipped to [0, 1] of the white level, float64."""
    return np.clip(np.asarray(x, np.float64), 0, 1)


def paired_differences(d) -> dict:
    """Paired differences d_i (one per image or crop, the same draws for both sides): their mean, standard error
    s_d / √n (NaN for n < 2), the count of d_i > 0 and n."""
    d = np.asarray(d, np.float64)
    se = float(np.std(d, ddof=1) / math.sqrt(d.size)) if d.size > 1 else math.nan
    return {"mean": float(d.mean()), "standard_error": se, "wins": int((d > 0).sum()), "n": int(d.size)}
