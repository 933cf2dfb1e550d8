"""PNG figures: log-scale PSFs, MTFs along x and y, banding profiles, capture previews side by side."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from udc_render.io.files import atomic_path, save_figure


def pyplot():
    """matplotlib.pyplot on the file-only Agg backend (chosen here, never at import)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_plot(fig, path: Path, tight_bbox: bool = True) -> None:
    """fig as a 110-dpi PNG at `path` (written atomically; bbox 'tight' or the whole figure), then closed."""
    try:
        if tight_bbox:
            save_figure(fig, path)
        else:
            with atomic_path(path, ".png") as tmp:
                fig.savefig(tmp, dpi=110, format="png")
    finally:
        pyplot().close(fig)


def _labels(ks):
    names = ks.params.get("channels")
    return [f"{n} ({w:.0f} nm)" for n, w in zip(names, ks.wavelengths_nm)] if names else \
        [f"{w:g} nm" for w in ks.wavelengths_nm]


def mtf_lines(kernel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frequency in cycles/pixel, MTF along x, MTF along y) of a unit-sum kernel, 0…0.5."""
    otf = np.abs(np.fft.fft2(np.fft.ifftshift(kernel.astype(np.float64))))
    n = kernel.shape[-1]
    half = n // 2 + 1
    return np.arange(half) / n, otf[0, :half] / otf[0, 0], otf[:half, 0] / otf[0, 0]


def plot_kernels(ks, path) -> None:
    plt = pyplot()
    k = ks.kernels.shape[0]
    fig, axes = plt.subplots(1, k, figsize=(4 * k, 3.8), squeeze=False)
    half = ks.size_px // 2 * ks.pixel_um
    for ax, kern, label in zip(axes[0], ks.kernels, _labels(ks)):
        img = np.log10(np.maximum(kern, 1e-12))
        im = ax.imshow(img, extent=(-half, half, -half, half), vmin=max(img.max() - 7, -12), vmax=img.max(),
                       cmap="inferno", origin="lower")
        ax.set_title(label)
        ax.set_xlabel("x on sensor (µm)")
        fig.colorbar(im, ax=ax, label="log10 energy per pixel", shrink=0.8)
    axes[0, 0].set_ylabel("y on sensor (µm)")
    fig.suptitle(f"PSF, display {ks.params['display'].get('name', 'none')}, {ks.pixel_um} µm pixels, "
                 f"d = {ks.params['distance_mm']} mm")
    save_figure(fig, path)
    plt.close(fig)


def plot_mtf(ks, path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for kern, label in zip(ks.kernels, _labels(ks)):
        f, mx, my = mtf_lines(kern)
        lpmm = f / (ks.pixel_um * 1e-3)
        axes[0].plot(lpmm, mx, label=label)
        axes[1].plot(lpmm, my, label=label)
    for ax, name in zip(axes, ("x", "y")):
        ax.set_xlabel("spatial frequency (line pairs / mm)")
        ax.set_title(f"MTF along {name}")
        ax.set_yscale("log")
        ax.set_ylim(1e-4, 1.2)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("MTF of the pixel-sampled kernel")
    axes[1].legend()
    save_figure(fig, path)
    plt.close(fig)


def plot_banding(profiles: dict, period_um: tuple[float, float], path) -> None:
    """profiles: {(axis, label): (positions_um, relative power)}."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for (axis, label), (x, p) in profiles.items():
        ax = axes[0 if axis == "x" else 1]
        ax.plot(x, (p - 1) * 1e3, label=label)
    for ax, name, per in zip(axes, ("x", "y"), period_um):
        ax.set_xlabel(f"image position {name} on the sensor (µm)")
        ax.set_title(f"banding along {name}, period {per:.1f} µm")
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("transmitted power − 1 (‰ of mean)")
    axes[1].legend()
    save_figure(fig, path)
    plt.close(fig)


def plot_side_by_side(previews: dict, summary: dict, path: Path) -> None:
    plt = pyplot()
    n = len(previews)
    h, w = next(iter(previews.values())).shape[:2]
    fig, axes = plt.subplots(1, n, figsize=(4.5 * n, 4.5 * h / w + 0.6), squeeze=False)
    for ax, (name, img) in zip(axes[0], previews.items()):
        ax.imshow(img)
        v = summary["views"][name]
        ax.set_title(f"{name}: PSNR {v['psnr_db_vs_gt']:.1f} dB (paper), {v['psnr_db_vs_gt_srgb']:.1f} dB (srgb)")
        ax.axis("off")
    fig.suptitle("captures (bilinear demosaic, daylight balance, sRGB; RAW levels as recorded)")
    save_figure(fig, path)
    plt.close(fig)
