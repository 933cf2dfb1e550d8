"""Part (i) of `udc-render study design`: the blur floor's rig (udc_render.design.pattern.BLUR_RIG).

`design-pattern --blur-floor` keeps a change only while the exact kernel's blur error (design.pattern.blur_error_db:
−10 log₁₀ mean S |1 − H|², a natural scene's energy the unit-sum kernel leaves) stays at the cell turned's, one D4
draw (seed 0), or does not fall. Its rig: the paper's lens (psf.Lens()), 6.2 µm pixels, 520 nm alone, a window of
129 px, 1024 pupil samples. For each of the study's two cells (the T-OLED's slit at the tile's edge, a scatter of
20 % open squares) this part scores `blur_draws` D4 draws of the cell turned (tile_transforms(tiles, d), d = 0 …)
and `blur_patterns` random K × K arrangements of its D4 elements (K = `blur_tiles`; streams keys 'study', 'blur', p),
along one knob at a time, the others at the rig's:

- pupil samples across the aperture (size 129 px, 520 nm);
- the window, size_px, with the engine's pupil samples for it (psf.plan.auto_pupil_samples; 520 nm). The scene is
  the window's (metrics.natural_spectrum on its grid), so the blur error itself changes with the window by
  definition: only the pattern's gap to the cell turned is compared across windows;
- the wavelengths: 520 nm alone, or the G channel of the Nikon 5100 under illuminant E
  (psf.spectral.channel_weights, the samples of at least 1 % of G's peak weight) at `blur_step_nm` steps
  (1024 samples, 129 px).

Per setting: the cell turned's mean blur error over its draws and its sd (the floor is one draw: its uncertainty),
the patterns' mean, their gap to the cell turned (what the floor decides), the errors of the turned mean and of the
gap against the axis's finest setting, and the median CPU seconds (time.process_time) of one check.
"""
from __future__ import annotations

import numpy as np
import torch

from psf.lens import Lens
from psf.spectral import channel_weights
from udc_render.design import torch_psf as tp
from udc_render.design.pattern import BLUR_RIG, blur_error_db
from udc_render.streams import stream
from udc_render.studies.report import timed

__all__ = ["BLUR_CAMERA", "G_CUTOFF", "blur_rows", "blur_settings", "g_channel"]

BLUR_CAMERA = "Nikon 5100 (NPL)"
G_CUTOFF = 1e-2  # G's samples of at least this fraction of its peak weight


def g_channel(step_nm: float) -> tuple[tuple, np.ndarray]:
    """(wavelengths nm, weights S_G(λ) E(λ) δλ) of BLUR_CAMERA's G channel at step_nm, G_CUTOFF of its peak kept."""
    lam, weights, names, _ = channel_weights(BLUR_CAMERA, "E", step_nm)
    g = weights[names.index("green")]
    keep = g >= G_CUTOFF * g.max()
    return tuple(float(v) for v in lam[keep]), g[keep]


def blur_settings(cfg: dict) -> list[dict]:
    """The part's settings, one knob at a time (the axis's finest last): pupil, window, wavelengths."""
    rig = {"pupil_samples": BLUR_RIG["pupil_samples"], "size_px": BLUR_RIG["size_px"], "step_nm": None}
    return ([{"axis": "pupil", **rig, "pupil_samples": n} for n in cfg["blur_pupil"]]
            + [{"axis": "window", **rig, "size_px": s, "pupil_samples": None} for s in cfg["blur_px"]]
            + [{"axis": "wavelengths", **rig, "step_nm": step} for step in (None, *cfg["blur_step_nm"])])


def _grid(cell_px: int, cell_um: float, setting: dict) -> tuple[tp.CellGrid, np.ndarray | None]:
    wavelengths, weights = g_channel(setting["step_nm"]) if setting["step_nm"] else (BLUR_RIG["wavelengths_nm"], None)
    grid = tp.cell_grid(cell_px, cell_um / cell_px, wavelengths_nm=wavelengths, pixel_um=BLUR_RIG["pixel_um"],
                        size_px=setting["size_px"], pupil_samples=setting["pupil_samples"])
    return grid, weights


def _setting_row(cfg: dict, name: str, cell: np.ndarray, setting: dict) -> dict:
    """One setting's blur errors of the cell turned (its draws) and of the random patterns, with CPU seconds."""
    grid, weights = _grid(cell.shape[0], cfg["cell_um"], setting)
    x = torch.tensor(cell, dtype=torch.float64)
    k = cfg["blur_tiles"]
    layouts = ([tp.tile_transforms(grid.tiles, d) for d in range(cfg["blur_draws"])]
               + [tp.arranged(stream(0, "study", "blur", p).integers(0, 8, (k, k)), grid.tiles)
                  for p in range(cfg["blur_patterns"])])
    found = [timed(lambda t=t: blur_error_db(x, grid, t, weights), 1) for t in layouts]
    blur = np.array([f.result for f in found])
    turned, patterns = blur[: cfg["blur_draws"]], blur[cfg["blur_draws"]:]
    return {"part": "blur", "cell": name, **setting, "pupil_used": round(Lens().aperture_um / grid.step_um),
            "wavelengths": len(grid.wavelengths_nm), "turned_db": float(turned.mean()),
            "turned_sd_db": float(turned.std(ddof=1)) if turned.size > 1 else 0.0,
            "pattern_db": float(patterns.mean()), "gap_db": float(patterns.mean() - turned.mean()),
            "cpu_s": float(np.median([f.cpu_seconds[0] for f in found]))}


def _errors(rows: list[dict]) -> None:
    """Each row's errors against its axis's finest setting (the axis's last row), in place."""
    for r in rows:
        ref = [q for q in rows if q["cell"] == r["cell"] and q["axis"] == r["axis"]][-1]
        r["error_turned_db"] = None if r["axis"] == "window" else abs(r["turned_db"] - ref["turned_db"])
        r["error_gap_db"] = abs(r["gap_db"] - ref["gap_db"])


def blur_rows(cfg: dict, cells: dict, progress=None) -> list[dict]:
    """Part (i): per cell of {name: amplitudes} and per setting of blur_settings, its row (module doc)."""
    rows = []
    for name, cell in cells.items():
        for setting in blur_settings(cfg):
            rows.append(_setting_row(cfg, name, cell, setting))
            if progress:
                progress(1)
    _errors(rows)
    return rows
