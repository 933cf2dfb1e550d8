"""`udc-render design-pattern`: a K × K arrangement of a fixed cell's D4 elements whose periodic display bands least
at d = 2 mm while UPC's ratio is held.

Why: UPC's mean ring minima need a display without period inside their 4 mm disc (a random tiling's fill between
the orders: random K × K patterns of `veil130`'s cell reach its turned ratio only at K ≈ 16–24), while a turned
tiling bands 1.6–2 × the repeated T-OLED (a tile at the aperture's edge shifts the transmitted power by its own
dipole, which no neighbour cancels: 2 × 2 blocks of the four quarter-turns band as the turned tiling does,
docs/guides/design.md). A long period searched tile by tile can hold both.

The search (coordinate descent): from a given arrangement (another run's end, under other floors) or the best of
STARTS random arrangements (UPC's ratio in the floor's channels highest, streams 'design', 'pattern', 'start', k),
each sweep visits the tiles in a random order (stream 'design', 'pattern', 'order', sweep) and tries each tile's
seven other elements; the element whose bands are lowest, max_c log(b_c / b_c^ref) below the current
(bands.BandingCeiling: the registered relative sd over the paper sensor's shifts on the cell's own squares, over the
T-OLED repeated), is kept when UPC's ratio (their mode, the arrangement repeated from the display's corner, over the
T-OLED turned: job.upc_comparison's 'arranged') stays at or above min(floor, its current value) and, with
blur_floor, the blur error (blur_error_db: the exact kernel of the paper's rig in G) stays at or above min(the cell
turned's, its current value), the cell turned's the mean over blur_floor_draws D4 draws (floor_draws; one by
default); else the next lowest (two are tried).
Sweeps stop when one keeps nothing or after `sweeps`. The cell is not changed. Without blur_floor the restoration
is not scored: through the simulator the committed pattern of `veil130`'s cell restores 0.35 dB (DeP) below the same
cell turned, its kernel's blur error 0.21 dB below the cell turned's (docs/guides/design.md, the long period).
"""
from __future__ import annotations

import numpy as np
import torch

from udc_render.design import metrics, torch_psf as tp, upc
from udc_render.design.bands import BandingCeiling
from udc_render.design.cells import RINGS, toled_reference, upc_cell
from udc_render.design.optimise import RIG_WAVELENGTHS_NM
from udc_render.design.options import CHANNELS
from udc_render.streams import stream

__all__ = ["BLUR_RIG", "STARTS", "PatternSearch", "blur_error_db", "check_settings", "floor_draws", "ring_minima"]

STARTS = 12  # random arrangements scored by UPC's ratio for the start: their G spans 1.24-1.27 at K = 16
BLUR_RIG = {"wavelengths_nm": (520.0,), "pixel_um": 6.2, "size_px": 129, "pupil_samples": 1024}  # G, the paper's rig


def ring_minima(cell: np.ndarray, transforms: np.ndarray, channels=(0, 1, 2)) -> np.ndarray:
    """UPC's mean ring minima of a 21 × 21 cell tiled so (their mode), in the channels given (indices into R, G, B)."""
    with torch.no_grad():
        p = upc.psf_and_kept(torch.tensor(cell), transforms, channels)[0].numpy()
    return np.asarray(metrics.ring_summary(p, RINGS)["mean_of_ring_minima"])


def blur_error_db(cell: torch.Tensor, grid: tp.CellGrid, transforms: np.ndarray, weights=None) -> float:
    """−10 log₁₀ mean_ν S_ν |1 − H_ν|²: the energy of a natural scene (metrics.natural_spectrum, the restorability's
    contrast and level) that the unit-sum kernel leaves, without noise. The kernel is the channel's over
    grid.wavelengths_nm, Σ w_λ t_λ k_λ / Σ w_λ t_λ (weights w: S_c(λ) E(λ) δλ, psf.spectral.channel_weights; t the
    power inside the window: psf.spectral.combine's rule), equal weights when none are given."""
    with torch.no_grad():
        ks, inside = tp.kernels_and_window(cell, grid, transforms)
    w = inside.double() * torch.as_tensor(np.ones(len(ks)) if weights is None else weights, dtype=torch.float64)
    k = (w[:, None, None] * ks.double()).sum(0) / w.sum()
    h = np.fft.fft2(np.fft.ifftshift(k.numpy()))
    scene = metrics.natural_spectrum(grid.size_px, (metrics.RMS_CONTRAST * metrics.MEAN_LEVEL) ** 2)
    return float(-10 * np.log10((scene * np.abs(1 - h) ** 2).mean()))


def floor_draws(tiles: int, seed: int, n: int) -> list[np.ndarray]:
    """The blur floor's n D4 draws of the cell turned: the first tile_transforms(tiles, seed) (the floor of one draw),
    the others keyed ('blur floor', i)."""
    return [tp.tile_transforms(tiles, seed, keys=("blur floor", i) if i else ()) for i in range(n)]


def check_settings(arrangement_tiles: int, floor_channels: str) -> None:
    """One line naming the option for a K outside 2 … 16 or channels not of R, G, B."""
    if not (isinstance(arrangement_tiles, int) and 2 <= arrangement_tiles <= 16):
        raise tp.DesignError(f"--arrangement {arrangement_tiles}: expected an integer in 2 … 16 (tiles a side)")
    if not (floor_channels and set(floor_channels) <= set(CHANNELS)):
        raise tp.DesignError(f"--floor-channels {floor_channels}: expected some of {CHANNELS}")


class PatternSearch:
    """The module doc's search of cell's arrangement at K tiles a side (state: arrangement, sweep, position)."""

    def __init__(self, cell: np.ndarray, arrangement_tiles: int, upc_floor: float, floor_channels: str = "G",
                 seed: int = 0, cell_um: float = 168.0, state: dict | None = None, blur_floor: bool = False,
                 blur_floor_draws: int = 1, start: np.ndarray | None = None):
        """state: a saved state (self.state()) to resume from; without one the search starts afresh, from start (a
        K × K arrangement, another search's end) when given, else from the best of STARTS random ones.
        blur_floor_draws: the floor is the mean blur error of this many D4 draws of the cell turned (floor_draws)."""
        self.cell, self.k, self.floor, self.seed = cell, arrangement_tiles, upc_floor, seed
        check_settings(arrangement_tiles, floor_channels)
        self.channels = [CHANNELS.index(c) for c in floor_channels]
        open_fraction = float(cell.mean())
        self.ceiling = BandingCeiling(1.0, cell.shape[0], cell_um, open_fraction, RIG_WAVELENGTHS_NM, seed=seed,
                                      turned=False, period_tiles=arrangement_tiles)
        self._cell_t = torch.tensor(cell, dtype=torch.float32)
        self._upc_cell = upc_cell(cell)
        self._toled_minima = ring_minima(toled_reference(cell_um, open_fraction), tp.tile_transforms(upc.TILES, seed))
        self._blur_grid = tp.cell_grid(cell.shape[0], cell_um / cell.shape[0], **BLUR_RIG) if blur_floor else None
        self.blur_floor_db = self._floor(blur_floor_draws) if blur_floor else None
        if state is not None:
            self.load(state)
            return
        first = self._start() if start is None else np.array(start, dtype=int)
        self.arrangement, self.sweep, self.position, self.kept, self.history = first, 0, 0, 0, []
        self.bands, self.upc_floor_ratio = self.log_bands(self.arrangement), self.floor_ratio(self.arrangement)
        self.blur_db = self.blur_of(self.arrangement)

    def _start(self) -> np.ndarray:
        starts = [stream(self.seed, "design", "pattern", "start", k).integers(0, 8, (self.k, self.k))
                  for k in range(STARTS)]
        return starts[int(np.argmax([self.floor_ratio(a) for a in starts]))].copy()

    def upc_ratios(self, arrangement: np.ndarray) -> np.ndarray:
        """UPC's mean ring minima of the arrangement over the T-OLED turned's, R / G / B."""
        return ring_minima(self._upc_cell, tp.arranged(arrangement, upc.TILES)) / self._toled_minima

    def floor_ratio(self, arrangement: np.ndarray) -> float:
        """The lowest of upc_ratios over the floor's channels, computed in those alone."""
        minima = ring_minima(self._upc_cell, tp.arranged(arrangement, upc.TILES), self.channels)
        return float((minima / self._toled_minima[self.channels]).min())

    def _floor(self, draws: int) -> float:
        """The mean blur error of the cell turned over its floor_draws."""
        return float(np.mean([self._blur(t) for t in floor_draws(self._blur_grid.tiles, self.seed, draws)]))

    def _blur(self, transforms: np.ndarray) -> float:
        return blur_error_db(torch.tensor(self.cell), self._blur_grid, transforms)

    def blur_of(self, arrangement: np.ndarray) -> float | None:
        """The arrangement's blur_error_db (dB), None without the blur floor."""
        return None if self._blur_grid is None else self._blur(tp.arranged(arrangement, self._blur_grid.tiles))

    def _holds_blur(self, arrangement: np.ndarray) -> tuple[bool, float | None]:
        blur = self.blur_of(arrangement)
        return blur is None or blur >= min(self.blur_floor_db, self.blur_db) - 1e-12, blur

    def band_ratios(self, arrangement: np.ndarray) -> np.ndarray:
        """The registered bands over the repeated T-OLED's, R / G / B (BandingCeiling.ratios, float32)."""
        with torch.no_grad():
            return self.ceiling.ratios(self._cell_t, "final", arrangement).double().numpy()

    def log_bands(self, arrangement: np.ndarray) -> float:
        return float(np.log(self.band_ratios(arrangement)).max())

    def order(self) -> np.ndarray:
        return stream(self.seed, "design", "pattern", "order", self.sweep).permutation(self.k * self.k)

    def visit(self) -> bool:
        """Try the tile at self.position of this sweep's order; True when an element was kept."""
        r, c = divmod(int(self.order()[self.position]), self.k)
        kept, trials = int(self.arrangement[r, c]), []
        for element in range(8):
            if element != kept:
                self.arrangement[r, c] = element
                trials.append((self.log_bands(self.arrangement), element))
        changed = False
        for score, element in sorted(t for t in trials if t[0] < self.bands - 1e-9)[:2]:
            self.arrangement[r, c] = element
            ratio = self.floor_ratio(self.arrangement)
            if ratio < min(self.floor, self.upc_floor_ratio):
                continue
            holds, blur = self._holds_blur(self.arrangement)
            if holds:
                kept, self.bands, self.upc_floor_ratio, self.blur_db, changed = element, score, ratio, blur, True
                break
        self.arrangement[r, c] = kept
        self.position, self.kept = self.position + 1, self.kept + changed
        return changed

    def end_sweep(self) -> dict:
        """Record the finished sweep (its kept changes, the bands and UPC's ratios after it) and open the next."""
        rec = {"sweep": self.sweep, "kept": self.kept, "band_ratios": self.band_ratios(self.arrangement).tolist(),
               "upc_ratios": self.upc_ratios(self.arrangement).tolist(), "blur_db": self.blur_db}
        self.history.append(rec)
        self.sweep, self.position, self.kept = self.sweep + 1, 0, 0
        return rec

    def finished(self, sweeps: int) -> bool:
        return self.sweep >= sweeps or bool(self.history and self.history[-1]["kept"] == 0)

    def state(self) -> dict:
        return {"arrangement": self.arrangement.tolist(), "sweep": self.sweep, "position": self.position,
                "kept": self.kept, "bands": self.bands, "upc_floor_ratio": self.upc_floor_ratio,
                "blur_db": self.blur_db, "history": self.history}

    def load(self, state: dict) -> None:
        self.arrangement = np.asarray(state["arrangement"], int)
        self.sweep, self.position, self.kept = state["sweep"], state["position"], state["kept"]
        self.history = state["history"]
        self.bands, self.upc_floor_ratio, self.blur_db = state["bands"], state["upc_floor_ratio"], state["blur_db"]
