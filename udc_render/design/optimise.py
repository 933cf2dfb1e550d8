"""`udc-render design`: optimise a binary display cell for restorability (issue 48), through the differentiable PSF.

The cell is c × c squares of the minimum feature size (c = cell_um / feature_um), each open (amplitude 1) or
opaque, with K = round(open_fraction · c²) open: every opening and every opaque bar is a union of whole squares, so
none is smaller than feature_um, and the open area is exact to one square. The search starts from a random scatter
of K squares (udc_render.streams), or (init 'toled') from the preset T-OLED on the squares, and moves by swaps of
an open and an opaque square, which keep K:

    each step: g = ∂J/∂a at the current binary cell (one backward pass, the transmission held at K / c²);
    the swap (close i, open j) changes J by ≈ g_j − g_i to first order; the `candidates` swaps of lowest
    predicted change are scored exactly, in that order, and the first that lowers J is taken;
    none lowers J: a local optimum of this neighbourhood, and the run stops early (converged).

With symmetry 'c2' the cell stays point-symmetric (udc_render.design.symmetry): a swap closes a square and its 180°
image and opens another such pair (predicted change: the pairs' summed gradients), and the start and the kicks keep
the symmetry; 'none' moves single squares, as above.

With tiling 'arranged' the tiles follow a K × K arrangement of D4 elements repeated over the window
(torch_psf.arranged): one periodic display, the same for the search and the final scores. At each local optimum of
the swaps a sweep turns the arrangement's tiles in raster order, each to whichever of its eight elements scores
lowest exactly (coordinate descent, 7 K² evaluations); when a tile turned the swaps go on, and the search stops
where neither a swap nor a sweep lowers J (then kicks, if any, perturb the best cell on the best arrangement).

With kicks N (iterated local search, Lourenço, Martin & Stützle, "Iterated Local Search", Handbook of
Metaheuristics 2003): at each local optimum the best cell so far takes kick_swaps random swaps (stream 'design',
'kick', n) and the swaps above descend again, N times; the design is the best local optimum. The swaps alone stop
at the first optimum of their neighbourhood (veil130_b90, the veil design with both targets: 9 swaps from its start).

Why not a relaxation: a sigmoid-relaxed cell's optimum is a uniform grey cell (an attenuator that does not
diffract: 37.0 dB against 27.8 dB for a binary scatter at 20 %), so the gradient of a relaxed cell flattens its
transmissions instead of reordering them, and projecting back to binary returns the initial scatter (the former
Adam optimiser: 8 of 441 squares moved in 150 steps, 0.001 dB; docs/guides/design.md).

Objective J, on the exact kernels of the paper's rig (psf.Lens(), pixels of pixel_um: 3.1 µm, the paper rig's packed
planes, unless given; 640 / 520 / 450 nm), the cell tiled plainly or by one fixed random D4 tiling (the search's;
search_tilings M > 1: the mean of J over M fixed draws; the final scores take another: held out; with packed, the
kernels of pixel_um's pixels on the packed planes of a Bayer camera, 2 × 2 pixels weighted ½, 1, ½, the kernel DeP
deconvolves with: torch_psf.packed, and crop_px and the scene's spectrum in packed pixels):
- 'wiener' (default): the mean over channels of the Wiener estimate's expected error under a 1/f² scene and the
  sensor's shot and read noise (udc_render.design.metrics) at the transmission K / c² times the fraction of the
  transmitted light inside the kernel's window (torch_psf.kernels_and_window): the light diffracted past the
  window counts as lost. Without that factor the unit-sum kernel does not see the light it loses, and the search
  threw light past the 127-px window: +1.1 dB on its own kernels, +0.2 dB on `study layout`'s 255-px ones;
- 'crop': the same with the restorer seeing only a crop of crop_px (`study layout --restore dep`'s 192): the share
  w(Δ) = (1 − 2|Δy|/C)₊ (1 − 2|Δx|/C)₊ of the kernel at offset Δ is signal, the rest interference from a scene the
  crop does not show (udc_render.design.crop.near_window; metrics.wiener_mse's h_far), at the RMS contrast given
  (natural crops reach 0.6–1.7; the restorability's 0.3 is low for them). A stationary stand-in, checked against
  the exact posterior mean on finite crops (crop.crop_mse): the designed cell of 'wiener' restores 9 dB below the
  T-OLED in DeP on 192-px crops because its light reaches ±96 px and more (docs/guides/design.md);
  The scene's mean μ (noise, signal variance (c μ)², veil) is mean_level, 0.5 of the full well by default;
  `study layout-trained`'s validation images (dead leaves) hold μ 0.41, c 0.51 (restore.studies.scene_statistics),
  with which the objective's margins over the exact T-OLED come nearer that study's plain DeP for the designs near
  the T-OLED, and further from it for those far below (docs/guides/design.md);
- 'upc': UPC's first term, −0.01 × the mean of the lowest 30 % of |H|² / (|H|² + 0.015) (their image L2 term,
  which needs an image set, is left out; their open-area term is met exactly by the swaps);
- 'rings': UPC's figure of merit itself, −mean over the channels of log(the mean over rings k = 1 … S/2 − 1 of the
  ring minimum of the MTF) (metrics.ring_summary's statistic; its gradient reaches only each ring's minimum).
With far_veil, 'wiener' and 'crop' add the squared bias of the light past the kernel's window, ((1 − f) / f)² μ²
per channel (far_veil_mse): the veil a restorer whose kernel holds only the window leaves in its estimate (plain DeP
in `study layout-trained`, where the bank adds that light as its far field). Without it that light only counts as
lost. Each objective takes the channels given (default R, G, B; e.g. 'B' alone). optics 'upc' computes the kernels in
UPC's sampling instead (udc_render.design.upc: 610 / 530 / 470 nm, f = 10 mm, their 21 × 21 cell of 8 µm, the
display tiled over 73 × 73 cells): their loss or their statistic in their optics, the comparison with their
optimised cell. It takes the objectives 'upc' and 'rings' (the Wiener objectives need the rig's sensor sampling).
With upc_floor R, 'wiener' and 'crop' are searched times a hinge that holds UPC's mean ring minima at R × the
T-OLED's in the floor's channels (udc_render.design.floor): the restoration objective under UPC's target. With
banding_ceiling R, times a hinge that holds the bands at d = 2 mm at most R × the T-OLED's (udc_render.design.bands).
init takes 'scatter', 'toled' or a former design's cell.png (a search from another start).
With channel_step_nm > 0 the rig's objectives see the camera's channels instead of one wavelength each: the kernels
at the camera's band sampled at that step, summed with the weights S_c(λ) D65(λ) δλ (objective_wavelengths;
torch_psf.channel_sum: psf.spectral.channel_kernels' sum, the kernels `study layout-trained`'s bank takes). A cell
fitted at 640 / 520 / 450 nm keeps structure that the band washes out: the committed designs' margins over the
simulator's T-OLED fall by 0.09-0.10 dB (docs/guides/design.md, "One wavelength per channel").
The search scores in float32 (a swap is taken only if it lowers J by more than IMPROVE_REL of J, well above
float32's rounding); every reported score is float64.

Minimum feature size: DEFAULT_FEATURE_UM = 8 µm, UPC's pupil sampling (so the design is scored in their mode),
5× the 1.5 µm that LTPS backplane lithography patterns (Azores Corp., "Flat Panel Display Applications": LTPS
feature sizes down to 1.5 µm, amorphous silicon 3 to 5 µm). Smaller features down to LITHOGRAPHY_UM are taken.
"""
from __future__ import annotations

from dataclasses import asdict

import numpy as np
import torch

from psf.lens import Lens
from psf.spectral import channel_weights
from udc_render.design import metrics, torch_psf as tp, upc
from udc_render.design.bands import BandingCeiling
from udc_render.design.config import DesignConfig
from udc_render.design.crop import near_window, split_kernel
from udc_render.design.floor import UpcFloor
from udc_render.design.mtf import mean_ring_minima, ring_index, spectrum
from udc_render.design.options import ARRANGEMENT_TILES, CHANNELS, RIG_PIXEL_UM
from udc_render.design.starts import initial_cell
from udc_render.design.symmetry import kicked_orbits, orbit_swaps, orbits
from udc_render.sensor.config import SensorConfig
from udc_render.streams import stream

__all__ = ["IMPROVE_REL", "RIG_WAVELENGTHS_NM", "CHANNEL_ILLUMINANT", "Designer", "far_veil_mse",
           "objective_wavelengths"]

IMPROVE_REL = 1e-5
RAISABLE = ("steps", "kicks")  # the search's budget: a resumed run may raise it and go on
RIG_WAVELENGTHS_NM = (640.0, 520.0, 450.0)
_LATER_DEFAULTS = {  # options added after the first checkpoints, at the settings those runs had
    "optics": "rig", "channels": CHANNELS, "far_veil": False, "upc_floor": None, "floor_channels": "G",
    "floor_uncropped": False, "banding_ceiling": None, "kicks": 0, "kick_swaps": 4, "search_tilings": 1,
    "channel_step_nm": 0.0, "reference": False,
    "mean_level": metrics.MEAN_LEVEL, "symmetry": "none", "pixel_um": RIG_PIXEL_UM,
    "packed": False, "arrangement": ARRANGEMENT_TILES}
CHANNEL_ILLUMINANT = "D65"  # the white of the bank's channel kernels (udc_render.dataset.bank_make)


def far_veil_mse(inside: torch.Tensor, mean_level: float = metrics.MEAN_LEVEL) -> torch.Tensor:
    """[C] the squared bias ((1 − f) / f)² μ² that the light past the kernel's window leaves in a restorer whose
    kernel holds only the window (f: the share inside it): that light lands as a veil of about the scene's mean,
    relative to the window's light, and passes the restorer's filter at its DC gain of 1 (restore.dep_far)."""
    return ((1 - inside) / inside) ** 2 * mean_level ** 2


def _listed(arrangement: np.ndarray | None) -> list | None:
    return None if arrangement is None else arrangement.tolist()


def objective_wavelengths(config: DesignConfig, sensor: SensorConfig) -> tuple[tuple, torch.Tensor | None]:
    """(the objective's wavelengths in nm, the weights [3, K] that sum them into the camera's channels, or None):
    the rig's three (RIG_WAVELENGTHS_NM, the paper's recipe) or, with channel_step_nm, the camera's band at that
    step weighted by its sensitivities × CHANNEL_ILLUMINANT (psf.spectral.channel_weights: the bank's channels)."""
    if not config.channel_step_nm:
        return RIG_WAVELENGTHS_NM, None
    lam, weights, _, _ = channel_weights(sensor.camera, CHANNEL_ILLUMINANT, config.channel_step_nm)
    return tuple(float(v) for v in lam), torch.tensor(weights)


class Designer:
    """The objective and one search step; state (the cell, its objective, the record) is what a checkpoint keeps."""

    def __init__(self, config: DesignConfig, sensor: SensorConfig | None = None, device: str = "cpu"):
        self.config, self.sensor, self.device = config, sensor or SensorConfig(), device
        if config.optics == "upc":
            self.grid, self.tiles, size = None, upc.TILES, upc.PSF_PX
        else:
            wavelengths_nm, self.channel_weights = objective_wavelengths(config, self.sensor)
            self.grid = tp.cell_grid(config.cell_px, config.feature_um, Lens(), wavelengths_nm, config.pixel_um,
                                     config.kernel_px, config.pupil_samples)
            self.tiles, size = self.grid.tiles, config.objective_px
        self.rings = ring_index(size)
        variance = (config.contrast * config.mean_level) ** 2
        self.signal = torch.tensor(metrics.natural_spectrum(config.objective_px, variance), device=device)
        self.window = torch.tensor(near_window(config.objective_px, config.crop_px), device=device)
        self.transmission = config.open_squares / config.cell_px ** 2
        self.floor = None if config.upc_floor is None else UpcFloor(
            config.upc_floor, config.floor_channels, config.cell_px, config.cell_um, config.open_fraction,
            config.seed, config.tiling == "turned", config.floor_uncropped, device)
        self.ceiling = None if config.banding_ceiling is None else BandingCeiling(
            config.banding_ceiling, config.cell_px, config.cell_um, config.open_fraction, RIG_WAVELENGTHS_NM,
            config.seed, config.tiling == "turned", device=device,
            period_tiles=config.arrangement if config.tiling == "arranged" else 1)
        self.groups = orbits(config.cell_px, config.symmetry)
        self.arrangement = (tp.tile_transforms(config.arrangement, config.seed, keys=("design", "arrangement"))
                            if config.tiling == "arranged" else None)
        self.best_arrangement = None if self.arrangement is None else self.arrangement.copy()
        self.cell = initial_cell(config)
        self.current = self.search_score(self.cell)
        self.best_cell, self.best = self.cell, self.current
        self.step_done, self.converged, self.evaluations, self.losses, self.kicks_done = 0, False, 1, [], 0

    def transforms(self, which: str, m: int = 0):
        """The search's fixed D4 tiling ('search'; m ≥ 1: its m-th further draw) or the held-out one of the final
        scores ('final')."""
        if self.config.tiling == "repeated":
            return None
        if self.config.tiling == "arranged":
            return tp.arranged(self.arrangement, self.tiles)
        return tp.tile_transforms(self.tiles, self.config.seed, keys=("design", which) + ((m,) if m else ()))

    def objective(self, cell: torch.Tensor, transforms, transmission: float | None = None) -> torch.Tensor:
        """J of a cell of amplitudes (module doc): wiener (crop: its light split by the crop's near_window) at the
        transmission K / c² (the swaps keep it; a grey cell's own Σ|a|² / c² given) × the fraction of the light
        inside the kernel's window."""
        channels = self.config.channel_index
        if self.config.optics == "upc":
            k = upc.psf(cell, transforms)[channels]
        else:
            k, inside = tp.kernels_and_window(cell, self.grid, transforms)
            if self.channel_weights is not None:
                k, inside = tp.channel_sum(k, inside, self.channel_weights)
            k, inside = k[channels], inside[channels]
            k = tp.packed(k) if self.config.packed else k
        if self.config.objective in ("wiener", "crop"):
            near, far = split_kernel(k, self.window.to(k.dtype)) if self.config.objective == "crop" else (k, None)
            h, h_far = spectrum(near), (None if far is None else spectrum(far))
            signal = self.signal.to(cell.dtype)
            kept = (self.transmission if transmission is None else transmission) * inside
            noise = [metrics.noise_variance(self.sensor, self.config.mean_level, t) for t in kept]
            mse = torch.stack([metrics.wiener_mse(h[c], signal, noise[c], t, None if h_far is None else h_far[c])
                               for c, t in enumerate(kept)])
            return (mse + far_veil_mse(inside, self.config.mean_level) if self.config.far_veil else mse).mean()
        if self.config.objective == "rings":
            return -torch.log(mean_ring_minima(k, self.rings)).mean()
        h = spectrum(k)
        w = (h.abs() ** 2 / (h.abs() ** 2 + 0.015)).flatten()
        return -0.01 * torch.topk(w, int(0.3 * w.numel()), largest=False).values.mean()

    def searched(self, cell: torch.Tensor, which: str) -> torch.Tensor:
        """What the search lowers on a tiling: J, times the UPC floor's factor with --upc-floor (floor.UpcFloor) and
        the banding ceiling's with --banding-ceiling (bands.BandingCeiling). The search's J is the mean over its
        search_tilings fixed D4 draws (one draw's J is the cell's on that draw: the search fits it)."""
        n = self.config.search_tilings if which == "search" else 1
        j = sum(self.objective(cell, self.transforms(which, m)) for m in range(n)) / n
        if self.floor is not None:
            j = j * self.floor.factor(cell, which)
        return j if self.ceiling is None else j * self.ceiling.factor(cell, which, self.arrangement)

    def score(self, cell: np.ndarray, which: str = "final") -> dict:
        """The float64 objective J of a binary cell on the held-out ('final') or the search's tiling, with its PSNR
        (wiener: −10 log10 J) and open area; with --upc-floor, the floor's ratios (its channels) on that tiling; with
        --banding-ceiling, the ceiling's ratios (R, G, B) on that tiling's draws."""
        x = torch.tensor(cell, dtype=torch.float64, device=self.device)
        with torch.no_grad():
            j = float(self.objective(x, self.transforms(which)))
            psnr = float(-10 * np.log10(j)) if self.config.objective in ("wiener", "crop") else None
            out = {"objective": j, "psnr_db": psnr, "open_area": float(np.mean(cell))}
            if self.floor is not None:
                out["upc_floor_ratios"] = self.floor.ratios(x, which).tolist()
            if self.ceiling is not None:
                out["banding_ratios"] = self.ceiling.ratios(x, which, self.arrangement).tolist()
        return out

    def search_score(self, cell: np.ndarray) -> float:
        with torch.no_grad():
            return float(self.searched(torch.tensor(cell, dtype=torch.float32, device=self.device), "search"))

    def _predicted(self) -> tuple[list, list, np.ndarray]:
        """(open orbits, opaque orbits, predicted change [open, opaque] of each swap: symmetry.orbit_swaps)."""
        x = torch.tensor(self.cell, dtype=torch.float32, device=self.device, requires_grad=True)
        self.searched(x, "search").backward()
        return orbit_swaps(self.cell, self.groups, x.grad.double().cpu().numpy().ravel())

    def step(self) -> dict:
        """One step (module doc): the first improving swap among the candidates, or converged."""
        opened, closed, predicted = self._predicted()
        order = np.argsort(predicted, axis=None, kind="stable")[: self.config.candidates]
        rec = {"step": self.step_done, "swap": None, "tried": 0}
        for idx in order:
            i, j = np.unravel_index(idx, predicted.shape)
            if not np.isfinite(predicted[i, j]):  # the rest change the open area (symmetry.orbit_swaps)
                break
            trial = self.cell.ravel().copy()
            trial[opened[i]], trial[closed[j]] = 0.0, 1.0
            value = self.search_score(trial.reshape(self.cell.shape))
            rec["tried"] += 1
            if value < self.current - IMPROVE_REL * abs(self.current):
                self.cell, self.current = trial.reshape(self.cell.shape), value
                rec["swap"] = [int(opened[i][0]), int(closed[j][0])]
                break
        self.evaluations += rec["tried"] + 1
        if rec["swap"] is None and self.arrangement is not None:
            rec["tiles_turned"] = self._sweep()
        if self.current < self.best:
            self.best_cell, self.best = self.cell, self.current
            self.best_arrangement = None if self.arrangement is None else self.arrangement.copy()
        if rec["swap"] is None and not rec.get("tiles_turned"):
            self._at_optimum(rec)
        self.step_done += 1
        rec["objective"], rec["best"] = self.current, self.best
        self.losses.append(rec)
        return rec

    def _sweep(self) -> int:
        """One sweep over an arranged tiling's tiles in raster order (coordinate descent, module doc): each tile's
        other seven D4 elements scored exactly and the best taken where it lowers J; the number of tiles turned."""
        turned = 0
        for r, c in np.ndindex(*self.arrangement.shape):
            kept = best = int(self.arrangement[r, c])
            for element in range(8):
                if element == kept:
                    continue
                self.arrangement[r, c] = element
                value = self.search_score(self.cell)
                if value < self.current - IMPROVE_REL * abs(self.current):
                    best, self.current = element, value
            self.arrangement[r, c] = best
            turned += best != kept
            self.evaluations += 7
        return turned

    def _at_optimum(self, rec: dict) -> None:
        """A local optimum: kick the best cell by kick_swaps random swaps while kicks remain (module doc), else stop
        there (converged)."""
        self.arrangement = None if self.best_arrangement is None else self.best_arrangement.copy()
        if self.kicks_done >= self.config.kicks:
            self.cell, self.current, self.converged = self.best_cell, self.best, True
            return
        self.kicks_done += 1
        self.cell = kicked_orbits(self.best_cell, self.groups, self.config.kick_swaps,
                                  stream(self.config.seed, "design", "kick", self.kicks_done))
        self.current = self.search_score(self.cell)
        self.evaluations += 1
        rec["kick"] = self.kicks_done

    @property
    def finished(self) -> bool:
        return self.converged or self.step_done >= self.config.steps

    def state(self) -> dict:
        return {"config": asdict(self.config), "cell": self.cell.copy(), "current": self.current,
                "step": self.step_done, "converged": self.converged, "evaluations": self.evaluations,
                "losses": self.losses, "best_cell": self.best_cell.copy(), "best": self.best,
                "kicks_done": self.kicks_done, "arrangement": _listed(self.arrangement),
                "best_arrangement": _listed(self.best_arrangement)}

    def load(self, state: dict) -> None:
        """Resume a checkpoint of the same settings; its budget (RAISABLE: steps, kicks) may be raised, and a run
        that stopped at its last kick's optimum then kicks again as the longer run would have."""
        saved = {**_LATER_DEFAULTS, **state["config"]}
        changed = sorted(k for k, v in asdict(self.config).items()
                         if saved.get(k) != v and not (k in RAISABLE and v > saved[k]))
        if changed:
            raise tp.DesignError(f"the output folder holds a run with other settings ({', '.join(changed)}); "
                                 "use another --out or the same settings to resume (--steps and --kicks may be "
                                 "raised)")
        self.cell, self.current = np.asarray(state["cell"], np.float64), float(state["current"])
        self.step_done, self.converged = int(state["step"]), bool(state["converged"])
        self.evaluations, self.losses = int(state["evaluations"]), list(state["losses"])
        self.best_cell = np.asarray(state.get("best_cell", self.cell), np.float64)
        self.best, self.kicks_done = float(state.get("best", self.current)), int(state.get("kicks_done", 0))
        if self.arrangement is not None:
            self.arrangement = np.asarray(state["arrangement"], int)
            self.best_arrangement = np.asarray(state["best_arrangement"], int)
        if self.converged and self.kicks_done < self.config.kicks and self.losses:
            self.converged = False
            self._at_optimum(self.losses[-1])
            self.losses[-1]["objective"] = self.current
