"""One `udc-render design-pattern` run in an output folder (udc_render.design.pattern): resumable (pattern_state.json,
written atomically every CHECKPOINT_S and at each sweep's end; the same command resumes it, other settings are
refused), a progress bar per sweep, from another run's end when given one (--start: read_start), and what it writes:

    cell.png, supercell.png, design.toml   the cell, its K c × K c period (the cell in each tile's D4 element)
                      and a display file of the cell with its tiles turned by the arrangement (tile_arrangement: the
                      engine rasters it tile by tile; the exact series of a 2688 µm period, which grows as the period
                      squared, ran out of 24 GB): every command takes it (psf, synth, bank, study layout-trained)
    pattern.json      the settings, each sweep's kept changes, bands, UPC's ratios and blur error (blur_db: with
                      --blur-floor, its floor, final value and the floor's draws; else null), and the final
                      figures: the bands on `study layout`'s 2 µm raster over the registrations of both periodic
                      displays (job.banding_comparison) and UPC's mean ring minima arranged and turned
                      (job.upc_comparison)
    pattern_bands.png the bands over the repeated T-OLED's and UPC's ratio over the turned T-OLED's, per sweep
"""
from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from tqdm import tqdm

from udc_render.design import torch_psf as tp
from udc_render.design.pattern import PatternSearch
from udc_render.io.files import save_json, save_text
from udc_render.io.plots import save_plot

__all__ = ["CHECKPOINT_S", "read_pattern_cell", "read_start", "run_pattern"]

CHECKPOINT_S = 60.0  # a sweep at K = 16 is 256 tiles of 7 scores (about 0.25 s each on a core) and their UPC checks


def read_pattern_cell(path: str) -> np.ndarray:
    """A design's cell.png: 21 × 21 grey of 0 and 255 (UPC's 8 µm squares), some open; as 0 / 1."""
    try:
        image = np.asarray(iio.imread(path))
    except (OSError, ValueError) as err:
        raise tp.DesignError(f"--cell {path}: not a readable PNG ({err})") from None
    if image.shape != (21, 21) or not np.isin(image, (0, 255)).all() or not image.any():
        raise tp.DesignError(f"--cell {path}: expected a 21 × 21 grey PNG of 0 and 255, some open (a design's "
                             f"cell.png on 8 µm squares), got shape {image.shape}")
    return (image == 255).astype(np.float64)


def _sha256(squares: np.ndarray) -> str:
    return hashlib.sha256(squares.astype(np.uint8).tobytes()).hexdigest()


def _settings(cell_path: str, cell: np.ndarray, k: int, floor: float, channels: str, seed: int,
              blur_floor: bool, blur_floor_draws: int = 1, start: tuple[str, np.ndarray] | None = None) -> dict:
    """The run's settings: the cell by its content (cell_sha256 of its 0 / 1 squares), the start's arrangement by its
    (start_sha256; None: random starts); the paths are recorded, not compared (_compared)."""
    return {"cell": cell_path, "cell_sha256": _sha256(cell), "open_squares": int(cell.sum()), "arrangement": k,
            "upc_floor": floor, "floor_channels": channels, "seed": seed, "blur_floor": blur_floor,
            "blur_floor_draws": blur_floor_draws, "start": None if start is None else start[0],
            "start_sha256": None if start is None else _sha256(start[1])}


def _compared(settings: dict) -> dict:
    """The settings a resume must match: all but the paths; a state saved before blur_floor_draws had one draw, one
    saved before start_sha256 random starts."""
    return {"blur_floor_draws": 1, "start_sha256": None,
            **{key: value for key, value in settings.items() if key not in ("cell", "start")}}


def read_start(folder: Path, cell: np.ndarray, k: int) -> np.ndarray:
    """The arrangement a design-pattern run in folder ended at (its pattern.json), refused in one line unless it was
    of the same cell (its squares) at K = k."""
    path = Path(folder) / "pattern.json"
    try:
        doc = json.loads(path.read_text())
        arrangement, sha256 = np.asarray(doc["arrangement"], dtype=int), doc["settings"]["cell_sha256"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise tp.DesignError(f"--start {folder}: expected a design-pattern folder with its pattern.json "
                             f"({err})") from None
    if sha256 != _sha256(cell) or arrangement.shape != (k, k):
        raise tp.DesignError(f"--start {folder}: a run of another cell or K ({arrangement.shape[0]} tiles a side); "
                             f"expected this --cell at --arrangement {k}")
    return arrangement


def _save_state(search: PatternSearch, settings: dict, path: Path) -> None:
    save_json(path, {"settings": settings, **search.state()})


def _saved_state(settings: dict, path: Path) -> dict | None:
    """The folder's checkpoint of this run, None without one; another run's is refused in one line."""
    if not path.is_file():
        return None
    state = json.loads(path.read_text())
    if _compared(state.get("settings") or {}) != _compared(settings):
        raise tp.DesignError(f"{path}: holds a run with other settings ({state.get('settings')}); use another --out")
    return state


def _figure(history: list, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"wspace": 0.35})
    sweeps = [h["sweep"] + 1 for h in history]
    for c, name in enumerate("RGB"):
        a.plot(sweeps, [h["band_ratios"][c] for h in history], "o-", color="rgb"[c], label=name)
        b.plot(sweeps, [h["upc_ratios"][c] for h in history], "o-", color="rgb"[c], label=name)
    a.axhline(1.0, color="k", lw=0.5)
    b.axhline(1.26, color="k", lw=0.5, label="UPC's gain (G)")
    a.set(xlabel="sweep", ylabel="bands / the repeated T-OLED's (8 µm squares)", xticks=sweeps)
    b.set(xlabel="sweep", ylabel="UPC's mean ring minima / the turned T-OLED's", xticks=sweeps)
    a.legend(fontsize=8)
    b.legend(fontsize=8)
    save_plot(fig, out / "pattern_bands.png")


def _write(search: PatternSearch, settings: dict, out: Path) -> dict:
    from udc_render.design.config import DesignConfig
    from udc_render.design.job import banding_comparison, display_toml, supercell, upc_comparison, write_png
    cell, arrangement = search.cell, search.arrangement
    write_png(out / "cell.png", cell)
    write_png(out / "supercell.png", supercell(cell, arrangement))
    save_text(out / "design.toml", display_toml("design", "cell.png", 8.0, float(cell.mean()), False, 0,
                                                arrangement=arrangement))
    config = DesignConfig(open_fraction=float(cell.mean()), tiling="arranged", arrangement=search.k,
                          seed=settings["seed"])
    doc = {"settings": settings, "arrangement": arrangement.tolist(), "history": search.history,
           "blur_db": {"floor": search.blur_floor_db, "final": search.blur_db,
                       "floor_draws": settings["blur_floor_draws"]},
           "banding": banding_comparison(cell, config, arrangement=arrangement),
           "upc": upc_comparison(cell, config, arrangement)}
    save_json(out / "pattern.json", doc)
    _figure(search.history, out)
    return doc


def run_pattern(cell_path: str, cell: np.ndarray, arrangement_tiles: int, upc_floor: float, floor_channels: str,
                sweeps: int, seed: int, out: Path, quiet: bool = False, blur_floor: bool = False,
                blur_floor_draws: int = 1, start: tuple[str, np.ndarray] | None = None) -> dict:
    """Search cell (read_pattern_cell of cell_path), from start (its folder and read_start's arrangement) when given,
    resuming pattern_state.json when the folder holds this run, and write the module doc's files."""
    settings = _settings(cell_path, cell, arrangement_tiles, upc_floor, floor_channels, seed, blur_floor,
                         blur_floor_draws, start)
    state_path = out / "pattern_state.json"
    state = _saved_state(settings, state_path)
    search = PatternSearch(cell, arrangement_tiles, upc_floor, floor_channels, seed, state=state,
                           blur_floor=blur_floor, blur_floor_draws=blur_floor_draws,
                           start=None if start is None else start[1])
    saved = time.monotonic()
    while not search.finished(sweeps):
        tiles = arrangement_tiles ** 2
        with tqdm(total=tiles, initial=search.position, disable=quiet, desc=f"sweep {search.sweep + 1}") as bar:
            while search.position < tiles:
                search.visit()
                bar.update(1)
                bar.set_postfix(bands=f"{np.exp(search.bands):.3f}", kept=search.kept)
                if time.monotonic() - saved >= CHECKPOINT_S:
                    _save_state(search, settings, state_path)
                    saved = time.monotonic()
        search.end_sweep()
        _save_state(search, settings, state_path)
    return _write(search, settings, out)
