"""The monitor alone, without Monte Carlo: exact pixel-area means of the panel (render path 'analytic').

The panel is a plane facing the pinhole camera on its axis (scene.geometry.camera_geometry), so the
pinhole projection maps it to the sensor by a scaling: render pixel (i, j) sees an axis-aligned
rectangle of the panel, and each panel pixel is a uniform square (Mitsuba's 'nearest' bitmap, as in
mitsuba_scene.monitor_shape). The box-filtered pixel value that Mitsuba's estimate converges to is then
the overlap-weighted mean of the drive levels, separable by axis:

    w_c(i, j) = Σ_r Σ_q  a_y[i, r] · a_x[j, q] · drive_c[r, q]

with a[i, r] the length of the overlap of render pixel i with panel pixel r along that axis (in
render pixels; 0 off the panel: the room is dark). Exact to float rounding: zero Monte Carlo noise,
and a few tenths of a second at 2048 × 1024 (two sparse products per channel).
tests/udc_render/test_render.py checks it against high-spp Mitsuba renders of the same scene.
"""
from __future__ import annotations

import numpy as np

from udc_render.content.resample import overlap_matrix, resample
from udc_render.scene.geometry import CameraGeometry


def panel_edges_px(geom: CameraGeometry, size_m: tuple[float, float], cols: int, rows: int):
    """Panel pixel edges in render-pixel coordinates: x (columns, left to right) and y (rows, top to
    bottom; panel row 0 is the top). Scale: v / (D · pitch) render pixels per metre on the panel."""
    distance_m = float(np.linalg.norm(geom.origin_m))
    px_per_m = geom.image_distance_um / (distance_m * geom.pitch_um)
    w_m, h_m = size_m
    x = geom.width_px / 2 + (np.linspace(0.0, 1.0, cols + 1) - 0.5) * w_m * px_per_m
    y = geom.height_px / 2 + (np.linspace(0.0, 1.0, rows + 1) - 0.5) * h_m * px_per_m
    return x, y


def monitor_area_means(geom: CameraGeometry, size_m: tuple[float, float], drive: np.ndarray) -> np.ndarray:
    """[3, H, W] float32 pixel-area means of the drive levels [3, rows, cols] (module doc)."""
    rows, cols = drive.shape[1:]
    x_edges, y_edges = panel_edges_px(geom, size_m, cols, rows)
    return resample(drive, overlap_matrix(y_edges, geom.height_px), overlap_matrix(x_edges, geom.width_px)
                    ).astype(np.float32)


def monitor_depth_m(geom: CameraGeometry, size_m: tuple[float, float]) -> np.ndarray:
    """[H, W] axial distance (m) at pixel centres: the camera-to-panel distance on the panel, inf off it."""
    x_edges, y_edges = panel_edges_px(geom, size_m, 1, 1)
    cx, cy = np.arange(geom.width_px) + 0.5, np.arange(geom.height_px) + 0.5
    on = ((cy >= y_edges[0]) & (cy <= y_edges[1]))[:, None] & ((cx >= x_edges[0]) & (cx <= x_edges[1]))[None, :]
    return np.where(on, np.float32(np.linalg.norm(geom.origin_m)), np.float32(np.inf)).astype(np.float32)
