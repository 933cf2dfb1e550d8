"""The evaluation protocol's image-quality metrics, one definition each (restore.evaluate's tables).

The restored image and the ground truth are linear camera RGB in units of the white level; both are
multiplied by the camera's daylight balance (udc_render.io.previews.daylight_balance: D65 neutral),
clipped to [0, 1], sRGB-encoded (IEC 61966-2-1, no colour matrix) and cropped by BORDER_PX pixels on
each side (display_referred). On those images: PSNR with peak 1 (udc_render.metrics.psnr_db); SSIM
of Wang et al. (Gaussian window σ = 1.5, data range 1, population statistics, mean over R, G, B;
skimage); LPIPS AlexNet v0.1 (restore.lpips).
"""
from __future__ import annotations

import numpy as np

from udc_render.metrics import display_referred, psnr_db

def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM of two [3, H, W] images in [0, 1] (module doc)."""
    from skimage.metrics import structural_similarity
    return float(structural_similarity(a, b, channel_axis=0, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False))


def lpips_distance(a: np.ndarray, b: np.ndarray, model) -> float:
    """LPIPS of two [3, H, W] images in [0, 1] with a restore.lpips.LPIPS model, in float32 keeping the
    arrays' memory layout (a model's channels_last output scores ~1e-7 apart from a contiguous copy)."""
    import torch
    with torch.inference_mode():
        return float(model(torch.from_numpy(a[None]).float(), torch.from_numpy(b[None]).float())[0])


def image_metrics(restored: np.ndarray, gt: np.ndarray, balance: np.ndarray, lpips_model) -> dict:
    """PSNR (dB), SSIM and LPIPS (restore.lpips.LPIPS `lpips_model`) of a restored [3, H, W] image against
    its ground truth (module doc)."""
    a, b = display_referred(restored, balance), display_referred(gt, balance)  # clipped to [0, 1] there
    return {"psnr_db": psnr_db(a, b, peak=1.0), "ssim": ssim(a, b), "lpips": lpips_distance(a, b, lpips_model)}
