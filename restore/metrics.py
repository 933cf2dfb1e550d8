"""The evaluation's image-quality metrics under both protocols of udc_render.metrics (restore.evaluate).

The restored image and the ground truth are linear camera RGB in units of the white level.
- 'paper' (the default for comparisons with the paper): both clipped to [0, 1], no white balance, no
  tone curve, BORDER_PX cropped; the input row is scored on its packed RAW against the ground
  truth's RGGB samples. PSNR and SSIM.
- 'srgb' (perceptual): both × the camera's daylight balance, clipped, sRGB-encoded, border cropped
  (display_referred). PSNR, SSIM and LPIPS AlexNet v0.1 (restore.lpips).
PSNR with peak 1 (udc_render.metrics.psnr_db); SSIM of Wang et al. (Gaussian window σ = 1.5, data
range 1, population statistics, mean over the channels; skimage).
"""
from __future__ import annotations

import numpy as np

from udc_render.metrics import border_px, display_referred, paper_linear, psnr_db
from udc_render.sensor import mosaic_of, pack_rggb


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM of two [C, H, W] images in [0, 1] (module doc)."""
    from skimage.metrics import structural_similarity
    return float(structural_similarity(a, b, channel_axis=0, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False))


def lpips_distance(a: np.ndarray, b: np.ndarray, model) -> float:
    """LPIPS of two [3, H, W] images in [0, 1] with a restore.lpips.LPIPS model, in float32 keeping the
    arrays' memory layout (a model's channels_last output scores ~1e-7 apart from a contiguous copy)."""
    import torch
    with torch.inference_mode():
        return float(model(torch.from_numpy(a[None]).float(), torch.from_numpy(b[None]).float())[0])


def _paper_pair(restored: np.ndarray, gt: np.ndarray, packed: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The paper protocol's images: linear, [0, 1] of the white level, border cropped; the packed RAW
    against the ground truth's RGGB samples when `packed` is given (the input row), else camera RGB."""
    if packed is not None:
        a, b = paper_linear(packed), pack_rggb(paper_linear(mosaic_of(gt)))
    else:
        a, b = paper_linear(restored), paper_linear(gt)
    k = border_px(*gt.shape[1:]) * a.shape[-1] // gt.shape[-1]  # 16 sensor px = 8 packed px
    crop = (slice(None), slice(k, a.shape[1] - k or None), slice(k, a.shape[2] - k or None))
    return a[crop], b[crop]


def paper_metrics(restored: np.ndarray | None, gt: np.ndarray, packed: np.ndarray | None = None) -> dict:
    """PSNR and SSIM under the 'paper' protocol (module doc) of a restored [3, H, W] image, or of the
    packed RAW `packed` [4, H/2, W/2] (white-level units) when given (the input row; `restored` is
    then not used), against the ground truth [3, H, W]."""
    a, b = _paper_pair(restored, gt, packed)
    return {"psnr_db_paper": psnr_db(a, b), "ssim_paper": ssim(a, b)}


def _gains(a: np.ndarray, b: np.ndarray, onto_a: bool) -> np.ndarray:
    """[C] each channel's least-squares gain: onto_a, g_c = Σ a_c b_c / Σ a_c² (a·g ≈ b); else the level
    k_c = Σ a_c b_c / Σ b_c² (a ≈ k·b). 1 where the divisor is 0."""
    flat_a, flat_b = a.reshape(a.shape[0], -1).astype(np.float64), b.reshape(b.shape[0], -1).astype(np.float64)
    ref = flat_a if onto_a else flat_b
    cross, power = np.einsum("cn,cn->c", flat_a, flat_b), np.einsum("cn,cn->c", ref, ref)
    return np.where(power > 0, cross / np.where(power > 0, power, 1.0), 1.0)


def _matched_psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    return psnr_db(np.clip(a * _gains(a, b, onto_a=True)[:, None, None], 0.0, 1.0).astype(a.dtype), b)


def level_matched_psnr_db(restored: np.ndarray | None, gt: np.ndarray, packed: np.ndarray | None = None) -> float:
    """The paper protocol's PSNR after each channel of the restored image (or of `packed`) is scaled by its
    least-squares gain onto the truth, g_c = Σ a_c b_c / Σ a_c² on the protocol's pair, and clipped again: the
    level and colour balance solved per image with the truth (an oracle). What it leaves is the error in the
    image's structure; the plain PSNR less this one is what the level and balance cost."""
    return _matched_psnr_db(*_paper_pair(restored, gt, packed))


LEVEL_KEYS = ("psnr_db_paper_matched", "level_r", "level_g", "level_b")  # level_scores' keys


def level_scores(restored: np.ndarray | None, gt: np.ndarray, packed: np.ndarray | None = None) -> dict:
    """On the paper protocol's pair: the level-matched PSNR (level_matched_psnr_db) and the output's level per
    channel, k_c = Σ a_c b_c / Σ b_c² (a ≈ k·b: 1 is the truth's level; the packed RAW's two greens averaged).
    An output at k × the truth loses 10·log10(mean(b²)·(1 − k)²)⁻¹ of PSNR to the level alone."""
    a, b = _paper_pair(restored, gt, packed)
    k = _gains(a, b, onto_a=False)
    green = k[1:3].mean() if len(k) == 4 else k[1]
    return dict(zip(LEVEL_KEYS, (_matched_psnr_db(a, b), float(k[0]), float(green), float(k[-1]))))


def image_metrics(restored: np.ndarray, gt: np.ndarray, balance: np.ndarray, lpips_model,
                  packed: np.ndarray | None = None) -> dict:
    """The scores of a restored [3, H, W] image against its ground truth under both protocols
    (udc_render.metrics): PSNR and SSIM under 'paper' (on `packed`, the RAW, when given: the input
    row), PSNR, SSIM and LPIPS (restore.lpips.LPIPS `lpips_model`) under 'srgb'; beside them the level-matched PSNR
    and the output's level per channel (level_scores)."""
    c, d = display_referred(restored, balance), display_referred(gt, balance)  # clipped to [0, 1] there
    return {**paper_metrics(restored, gt, packed), **level_scores(restored, gt, packed),
            "psnr_db_srgb": psnr_db(c, d), "ssim_srgb": ssim(c, d), "lpips_srgb": lpips_distance(c, d, lpips_model)}
