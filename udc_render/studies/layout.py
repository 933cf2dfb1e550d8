"""`udc-render study layout`: score a display's pixel layout for restorability (issue 48).

For one layout (a preset, a display file or a micrograph), tiled plainly and with every tile turned and
mirrored at random (the 8 elements of D4, udc_render.design.torch_psf.tile_transforms):
- UPC's ring statistics in their sampling (udc_render.design.upc): the layout's cell (framed as given, or with
  its opening at the tile's edge: frame_cell) resampled to 21 × 21 and taken as 168 µm, their optics (f = 10 mm,
  a 4 mm disc, 610 / 530 / 470 nm);
- the same statistics on the project's exact kernels (udc_render.design.torch_psf, equal to psf.compute_kernels)
  with the same optics, 2 µm pixels, 295 px;
- the Wiener restorability (udc_render.design.metrics) on the exact kernels of the paper's rig (psf.Lens(),
  3.1 µm, 255 px, 640 / 520 / 450 nm) under the sensor's noise, with the layout's open area as transmission,
  and again with only the light inside the kernel's window (open area × window fraction: the rest is lost);
- the banding at the display-to-lens distance d (udc_render.studies.layout_banding: the exact power series of the
  layout repeated on the rig's lens; and the power of both tilings sampled in space over the shifts the paper's
  sensor sees, layout_banding.sampled_banding, the only figure a turned tiling has: it has no period);
- the open area and power transmittance.
- with restore='dep' (opt-in: seconds per plane), the restored PSNR by DeP of a natural image through the rig's
  kernels at the window's transmission (udc_render.studies.layout_restore).
Not here: the restored PSNR by a UNet trained through a bank of the layout (restore.studies.layout_trained:
`study layout-trained`, minutes to an hour a layout). The error against run time of the design's knobs is `study design`
(udc_render.studies.design_knobs).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from psf.lens import Lens
from udc_render.design import metrics, torch_psf as tp, upc
from udc_render.design.cells import RINGS, frame_cell, layout_cell, upc_cell
from udc_render.design.options import RIG_PIXEL_UM
from udc_render.design.tiling_power import DEFAULT_DISTANCE_MM, SAMPLE_UM, sampled_banding
from udc_render.sensor.config import SensorConfig
from udc_render.studies.layout_banding import layout_banding
from udc_render.studies.layout_restore import CROP_PX, CROP_SETS, QUICK_CROP_PX, RESTORERS, restored_psnr

__all__ = ["UPC_LENS", "FRAMES", "LayoutScores", "layout_cell", "frame_cell", "upc_cell", "score_layout"]

UPC_LENS = Lens(focal_length_um=upc.FOCAL_UM, aperture_um=upc.APERTURE_UM)
UPC_PIXEL_UM = 2.0
UPC_KERNEL_PX = 295
RIG_WAVELENGTHS_NM = (640.0, 520.0, 450.0)  # R, G, B
RIG_KERNEL_PX = 255
QUICK_SAMPLE_UM = 4.0  # the sampled banding's raster step with --quick (2 µm without: tiling_power.SAMPLE_UM)
FRAMES = ("as_given", "edge")
TILINGS = ("repeated", "turned")


@dataclass(frozen=True)
class LayoutScores:
    """Every figure of one study: per tiling, the UPC-mode and exact ring summaries (metrics.ring_summary) and
    the rig's restorability (metrics.restorability); the banding at d of the repeated tiling (layout_banding);
    the kernels' MTF maps (green) for the figures; with a restorer, its restored PSNR per tiling (layout_restore)."""
    name: str
    open_fraction: float
    power_transmittance: float
    period_um: float
    frame: str
    seed: int
    upc: dict
    exact: dict
    restorability: dict
    mtf_maps: dict
    seconds: float
    banding: dict
    restored: dict = field(default_factory=dict)


def _centre_mtf(kernel: np.ndarray) -> np.ndarray:
    return metrics.mtf(kernel).astype(np.float32)


def score_layout(name: str, layout, seed: int = 0, frame: str = "as_given", quick: bool = False,
                 sensor: SensorConfig | None = None, progress=None,
                 distance_mm: float = DEFAULT_DISTANCE_MM, restore: str | None = None,
                 crops: str = "astronaut") -> LayoutScores:
    """The study's figures for one layout (module doc); quick: 63-px kernels from 256 pupil samples (and one
    96-px crop for the restorer); restore: None or one of RESTORERS, on the crops of CROP_SETS[crops]."""
    if not distance_mm > 0:
        raise tp.DesignError(f"--distance-mm {distance_mm}: expected a distance > 0 mm")
    if restore is not None and restore not in RESTORERS:
        raise tp.DesignError(f"--restore {restore}: expected one of {', '.join(RESTORERS)}")
    if crops not in CROP_SETS:
        raise tp.DesignError(f"--restore-crops {crops}: expected one of {', '.join(CROP_SETS)}")
    if frame not in FRAMES:
        raise tp.DesignError(f"--frame {frame}: expected one of {', '.join(FRAMES)}")
    start = time.perf_counter()
    cell, cell_um = layout_cell(layout)
    cell = frame_cell(cell, frame)
    small = torch.tensor(upc_cell(cell))
    big = torch.tensor(cell)
    pupil = 256 if quick else None
    upc_grid = tp.cell_grid(cell.shape[0], cell_um, UPC_LENS, upc.WAVELENGTHS_NM, UPC_PIXEL_UM,
                            63 if quick else UPC_KERNEL_PX, pupil)
    rig_grid = tp.cell_grid(cell.shape[0], cell_um, Lens(), RIG_WAVELENGTHS_NM, RIG_PIXEL_UM,
                            63 if quick else RIG_KERNEL_PX, pupil)
    trans = float(layout.power_transmittance)
    out = {"upc": {}, "exact": {}, "restorability": {}, "mtf_maps": {}, "restored": {}}
    crop_px, crop_set = (QUICK_CROP_PX, CROP_SETS[crops][:1]) if quick else (CROP_PX, CROP_SETS[crops])
    with torch.no_grad():
        for tiling in TILINGS:
            s = seed if tiling == "turned" else None
            turns = tp.tile_transforms(upc.TILES, s)
            p, kept = upc.psf_and_kept(small, turns)
            p = p.numpy()
            out["upc"][tiling] = {**metrics.ring_summary(p, RINGS), "kept": kept.tolist()}
            k = tp.kernels(big, upc_grid, tp.tile_transforms(upc_grid.tiles, s)).numpy()
            out["exact"][tiling] = metrics.ring_summary(k, min(RINGS, upc_grid.size_px // 2))
            r, inside = (v.numpy() for v in tp.kernels_and_window(big, rig_grid, tp.tile_transforms(rig_grid.tiles, s)))
            out["restorability"][tiling] = metrics.restorability(r, trans, sensor)
            out["restorability"][tiling]["window_fraction"] = inside.tolist()
            out["restorability"][tiling]["window"] = metrics.restorability(r, trans * inside, sensor)
            if restore:
                out["restored"][tiling] = restored_psnr(r, trans * inside, sensor, crop_px, crop_set, seed)
            out["mtf_maps"][tiling] = {"upc": _centre_mtf(p[1]), "exact": _centre_mtf(k[1])}
            if tiling == "repeated":
                banding = layout_banding(layout, Lens(), RIG_WAVELENGTHS_NM, distance_mm, r, rig_grid.pixel_um)
                banding["sampled"] = sampled_banding(cell, cell_um, Lens(), RIG_WAVELENGTHS_NM, distance_mm, seed,
                                                     QUICK_SAMPLE_UM if quick else SAMPLE_UM, registered=True)
            if progress:
                progress(1)
    return LayoutScores(name, float(getattr(layout, "open_fraction", trans)), trans, float(cell.shape[0] * cell_um),
                        frame, int(seed), out["upc"], out["exact"], out["restorability"], out["mtf_maps"],
                        time.perf_counter() - start, banding, out["restored"])
