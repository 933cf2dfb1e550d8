"""sRGB previews (never used for data): band radiance via CIE XYZ, camera RGB via a daylight balance."""
from __future__ import annotations

import numpy as np

from udc_render.content import spectra
from udc_render.metrics import encode_srgb
from udc_render.sensor import photon_weights

XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                        [-0.9692660, 1.8760108, 0.0415560],
                        [0.0556434, -0.2040259, 1.0572252]])


def preview_rgb(bands: np.ndarray, edges_nm) -> tuple[np.ndarray, float]:
    """8-bit sRGB [H, W, 3] of band radiance [K, H, W] and the luminance (cd/m²) shown as white."""
    xyz = np.einsum("ck,khw->chw", spectra.band_xyz(edges_nm), bands.astype(np.float64))
    white = float(np.percentile(xyz[1], 99)) if np.any(xyz[1] > 0) else 1.0
    rgb = np.einsum("ij,jhw->hwi", XYZ_TO_SRGB, xyz / white)
    return (encode_srgb(rgb) * 255 + 0.5).astype(np.uint8), white


def daylight_balance(camera: str = "Nikon 5100 (NPL)") -> np.ndarray:
    """[3] channel gains that make D65 neutral in this camera (for previews only; RAW is never balanced)."""
    edges = np.arange(380.0, 781.0, 5.0)
    d65 = spectra.band_means(spectra.illuminant("D65"), edges)
    resp = photon_weights(edges, camera) @ (d65 * np.diff(edges))
    return resp[1] / resp


def preview_srgb(rgb: np.ndarray, balance: np.ndarray, white: float = 1.0) -> np.ndarray:
    """8-bit sRGB [H, W, 3] of camera RGB [3, H, W] (white → 1.0 after `balance`); no colour matrix."""
    x = np.asarray(rgb, float) * balance[:, None, None] / white
    return (encode_srgb(np.moveaxis(x, 0, -1)) * 255 + 0.5).astype(np.uint8)
