"""Why a layout restores below its Wiener restorability in DeP: the finite crop against the kernel's reach.

`study layout --restore dep` (layout_restore) restores 192-px crops of astronaut through 255-px kernels. For the
layouts given (turned tilings, the rig's exact kernels at the window's transmission, as `study layout` makes them),
on the green channel, this study separates what a finite crop costs from what the restorer costs:

- dep: DeP as the study runs it (the crop of a blur of the whole image: light from outside the crop enters it);
- dep_periodic: DeP on the crop blurred circularly (a periodic scene: the kernel's light never leaves the crop),
  restored without padding: the same noise draws, the same sampler;
- mmse_finite: the posterior mean of the crop under a Gaussian 1/f² prior given only the crop
  (udc_render.design.crop.posterior_mean), the best a linear restorer can do from it;
- wiener_periodic: the Wiener filter with the same prior on the periodic crop (no boundary);
- input: y / t against x;
each at crop sizes (192 px: the study's two crops; 384: two; 512: one), and for Gaussian scenes at RMS contrasts
0.3 and 1.0 (draws of the prior itself, 192 px): the exact finite-crop error (crop.crop_mse), the periodic
restorability (metrics.wiener_mse) and the objective 'crop''s stationary stand-in (crop.near_window).

    run_study(Path(DIR), ["D.toml[@edge]", …])   (writes layout_crop.json, .md; not a command: docs/guides/design.md)
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from psf.lens import Lens
from restore.dep import centred_psf, denoise_plane, wiener_plane
from udc_render.design import crop, metrics, torch_psf as tp
from udc_render.design.cells import frame_cell, layout_cell
from udc_render.design.options import RIG_PIXEL_UM
from udc_render.io.files import save_json, save_text
from udc_render.sensor.config import SensorConfig
from udc_render.streams import stream
from udc_render.studies.layout_restore import CROP_SETS, degrade, natural_crops, noisy

__all__ = ["CROPS", "CONTRASTS", "CHANNEL", "layout_kernels", "astronaut_modes", "gaussian_modes", "run_study"]

CROPS = {192: CROP_SETS["astronaut"], 384: (("astronaut", 0, 0), ("astronaut", 128, 128)),
         512: (("astronaut", 0, 0),)}
CONTRASTS = (0.3, 1.0)
CHANNEL = 1  # green (520 nm)
KERNEL_PX = 255
PRIOR_CONTRAST = 1.0  # the posterior mean's prior on astronaut (its crops' RMS contrast: 0.6 to 1.6 in green)


def layout_kernels(spec: str, seed: int = 0) -> tuple[str, np.ndarray, np.ndarray]:
    """(name, kernels [3, S, S], transmission [3]: open area × window fraction) of 'DISPLAY[@edge]', turned (D4,
    seed), on the rig (psf.Lens(), 3.1 µm, 640 / 520 / 450 nm, 255 px): `study layout`'s kernels."""
    from udc_render.optics.displays import load_display
    path, _, frame = spec.partition("@")
    display = load_display(path)
    cell, cell_um = layout_cell(display.layout)
    cell = frame_cell(cell, frame or "as_given")
    grid = tp.cell_grid(cell.shape[0], cell_um, Lens(), (640.0, 520.0, 450.0), RIG_PIXEL_UM, KERNEL_PX)
    with torch.no_grad():
        k, inside = tp.kernels_and_window(torch.tensor(cell), grid, tp.tile_transforms(grid.tiles, seed))
    trans = float(display.layout.power_transmittance) * inside.numpy()
    return f"{display.name}{'@' + frame if frame else ''}", k.numpy(), trans


def _periodic_blur(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    return np.real(np.fft.ifft2(np.fft.fft2(x) * np.fft.fft2(np.fft.ifftshift(centred_psf(kernel, x.shape)))))


def _wiener_periodic(y: np.ndarray, kernel: np.ndarray, t: float, noise: float, variance: float) -> np.ndarray:
    """The Wiener filter of a periodic crop, prior 1/f² of `variance`, its mean from the data."""
    s = metrics.natural_spectrum(y.shape[0], variance)
    h = np.fft.fft2(np.fft.ifftshift(centred_psf(kernel, y.shape)))
    yf = np.fft.fft2(y)
    est = np.where(s > 0, t * np.conj(h) * yf * s / (t * t * np.abs(h) ** 2 * s + noise), yf / (t * h))
    return np.real(np.fft.ifft2(est))


def _mmse_finite(y: np.ndarray, kernel: np.ndarray, t: float, noise: float, variance: float) -> np.ndarray:
    p = crop.crop_problem(y.shape[0], kernel.shape[0], variance)
    mean = y.mean() / t
    est = crop.posterior_mean(p, torch.tensor(kernel), t, noise, torch.tensor(y - t * mean))
    return est.numpy() + mean


def astronaut_modes(kernel: np.ndarray, t: float, crop_px: int, sensor: SensorConfig | None = None,
                    seed: int = 0) -> dict:
    """PSNR (dB, peak: the full well) of each mode (module doc) on astronaut's crops of crop_px (CROPS), one
    channel (CHANNEL) through kernel [S, S] at transmission t; the noise and sampler streams of layout_restore."""
    sensor = sensor or SensorConfig()
    kernel = kernel / kernel.sum()
    m = kernel.shape[0] // 2
    noise = metrics.noise_variance(sensor, metrics.MEAN_LEVEL, t)
    variance = (PRIOR_CONTRAST * metrics.MEAN_LEVEL) ** 2
    errors: dict[str, list] = {}
    for i, region in enumerate(natural_crops(crop_px, m, CROPS[crop_px])):
        x = region[CHANNEL, m:m + crop_px, m:m + crop_px]
        y = degrade(region[CHANNEL], kernel, t, sensor, stream(seed, "layout_restore", "noise", i, CHANNEL))
        yp = noisy(_periodic_blur(x, kernel), t, sensor, stream(seed, "layout_restore", "noise", i, CHANNEL))

        def sampler():
            return stream(seed, "layout_restore", "wiener", i, CHANNEL)
        modes = {"input": lambda: y / t,
                 "dep": lambda: wiener_plane(denoise_plane(y) / t, kernel, sampler()),
                 "dep_periodic": lambda: wiener_plane(denoise_plane(yp) / t, kernel, sampler(), pad_px=0,
                                                      fill_iterations=0),
                 "mmse_finite": lambda: _mmse_finite(y, kernel, t, noise, variance),
                 "wiener_periodic": lambda: _wiener_periodic(yp, kernel, t, noise, variance)}
        for name, make in modes.items():
            errors.setdefault(name, []).append(np.mean((np.clip(make(), 0, None) - x) ** 2))
    return {name: float(-10 * np.log10(np.mean(v))) for name, v in errors.items()}


def gaussian_modes(kernel: np.ndarray, t: float, contrast: float, crop_px: int = 192, draws: int = 2,
                   sensor: SensorConfig | None = None, seed: int = 0) -> dict:
    """PSNR (dB) of Gaussian 1/f² scenes of RMS contrast `contrast` through kernel at t: the posterior mean's on
    the crop (crop.crop_mse, the mean over `draws` draws, and each), the periodic restorability, and the
    objective 'crop''s stand-in (near_window's split, metrics.wiener_mse's h_far) on the kernel's grid."""
    sensor = sensor or SensorConfig()
    kernel = kernel / kernel.sum()
    variance = (contrast * metrics.MEAN_LEVEL) ** 2
    noise = metrics.noise_variance(sensor, metrics.MEAN_LEVEL, t)
    p = crop.crop_problem(crop_px, kernel.shape[0], variance)
    exact = [crop.crop_mse(p, torch.tensor(kernel), t, noise, *crop.scene_draws(p, stream(seed, "layout_crop", j)))
             for j in range(draws)]
    signal = metrics.natural_spectrum(kernel.shape[0], variance)
    near, far = crop.split_kernel(kernel, crop.near_window(kernel.shape[0], crop_px))
    spectrum = [np.fft.fft2(np.fft.ifftshift(a)) for a in (kernel, near, far)]
    periodic = metrics.wiener_mse(spectrum[0], signal, noise, t)
    stand_in = metrics.wiener_mse(spectrum[1], signal, noise, t, spectrum[2])
    db = [float(-10 * np.log10(v)) for v in exact]
    return {"mmse_finite": float(-10 * np.log10(np.mean(exact))), "mmse_finite_draws": db,
            "wiener_periodic": float(-10 * np.log10(periodic)), "crop_objective": float(-10 * np.log10(stand_in))}


def _markdown(doc: dict) -> str:
    lines = ["# Why a layout loses in DeP: the finite crop (green, turned tilings)", "",
             "Astronaut (PSNR, dB; crops: 192 px the study's two, 384 px two, 512 px one):", "",
             "| layout | crop | input | DeP | DeP, periodic crop | posterior mean, finite crop | Wiener, periodic |",
             "|---|---|---|---|---|---|---|"]
    for name, rows in doc["astronaut"].items():
        for c, r in rows.items():
            lines.append(f"| {name} | {c} | {r['input']:.2f} | {r['dep']:.2f} | {r['dep_periodic']:.2f} | "
                         f"{r['mmse_finite']:.2f} | {r['wiener_periodic']:.2f} |")
    lines += ["", "Gaussian 1/f² scenes, 192-px crop (PSNR, dB):", "",
              "| layout | contrast | posterior mean, finite crop (draws) | periodic restorability | objective 'crop' |",
              "|---|---|---|---|---|"]
    for name, rows in doc["gaussian"].items():
        for c, r in rows.items():
            draws = " / ".join(f"{v:.2f}" for v in r["mmse_finite_draws"])
            lines.append(f"| {name} | {c} | {r['mmse_finite']:.2f} ({draws}) | {r['wiener_periodic']:.2f} | "
                         f"{r['crop_objective']:.2f} |")
    return "\n".join(lines) + "\n"


def run_study(out: Path, specs: list[str], crops=tuple(CROPS), contrasts=CONTRASTS, draws: int = 2) -> dict:
    """Every mode for every layout (module doc); writes layout_crop.json and layout_crop.md in out. crops: among
    CROPS' sizes."""
    if any(c not in CROPS for c in crops):
        raise ValueError(f"crops {crops}: expected sizes among {', '.join(map(str, CROPS))}")
    start = time.process_time()
    doc = {"channel": CHANNEL, "kernel_px": KERNEL_PX, "prior_contrast": PRIOR_CONTRAST, "cg_iterations":
           crop.CG_ITERATIONS, "crops": {str(c): [list(v) for v in CROPS[c]] for c in crops}, "layouts": {},
           "astronaut": {}, "gaussian": {}}
    for spec in specs:
        name, kernels, trans = layout_kernels(spec)
        k, t = kernels[CHANNEL], float(trans[CHANNEL])
        doc["layouts"][name] = {"spec": spec, "transmission": trans.tolist()}
        doc["astronaut"][name] = {str(c): astronaut_modes(k, t, c) for c in crops}
        doc["gaussian"][name] = {str(c): gaussian_modes(k, t, c, draws=draws) for c in contrasts}
        print(name, doc["astronaut"][name], doc["gaussian"][name], flush=True)
    doc["cpu_s"] = time.process_time() - start
    out.mkdir(parents=True, exist_ok=True)
    save_json(out / "layout_crop.json", doc)
    save_text(out / "layout_crop.md", _markdown(doc))
    return doc
