"""`udc-render design`: optimise a display cell for restorability (issue 48), through the differentiable PSF.

The cell is c × c squares of the minimum feature size (c = cell_um / feature_um), each with transmission
a = sigmoid(β θ), β annealed geometrically from 1 to BETA_MAX so that the cell ends binary; the last step
projects it: the round(open_fraction · c²) most open squares open, the rest opaque (the open area exact to one
square). Every open or opaque feature is then a union of whole squares: none is smaller than feature_um.

Objective, on the exact kernels of the paper's rig (psf.Lens(), 3.1 µm pixels, 640 / 520 / 450 nm) with the
cell tiled plainly or, each step, by a fresh random D4 tiling (udc_render.streams):
- 'wiener' (default): the mean over channels of the Wiener estimate's expected error under a 1/f² scene and the
  sensor's shot and read noise at the cell's own transmission (udc_render.design.metrics);
- 'upc': UPC's first term, −0.01 × the mean of the lowest 30 % of |H|² / (|H|² + 0.015) (their image L2 term,
  which needs an image set, is left out);
plus OPEN_WEIGHT (open area − target)² (UPC's weight 10).

Minimum feature size: DEFAULT_FEATURE_UM = 8 µm, UPC's pupil sampling (so the design is scored in their mode),
5× the 1.5 µm that LTPS backplane lithography patterns (Azores Corp., "Flat Panel Display Applications": LTPS
feature sizes down to 1.5 µm, amorphous silicon 3 to 5 µm). Smaller features down to LITHOGRAPHY_UM are taken.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import torch

from psf.lens import Lens
from udc_render.design import metrics, torch_psf as tp
from udc_render.design.options import DEFAULT_FEATURE_UM, LITHOGRAPHY_UM, OBJECTIVES, TILINGS
from udc_render.sensor.config import SensorConfig
from udc_render.streams import stream

__all__ = ["LITHOGRAPHY_UM", "DEFAULT_FEATURE_UM", "DesignConfig", "Designer", "project"]

BETA_MAX = 32.0
OPEN_WEIGHT = 10.0
ADAM_BETAS = (0.9, 0.999)
RIG_WAVELENGTHS_NM = (640.0, 520.0, 450.0)


@dataclass(frozen=True)
class DesignConfig:
    """Every setting of one design run (the checkpoint keeps it: a resumed run must match)."""
    cell_um: float = 168.0
    feature_um: float = DEFAULT_FEATURE_UM
    open_fraction: float = 0.20
    tiling: str = "turned"
    objective: str = "wiener"
    steps: int = 150
    lr: float = 0.1
    seed: int = 0
    pupil_samples: int = 512
    kernel_px: int = 127

    def __post_init__(self):
        if not 0 < self.open_fraction < 1:
            raise tp.DesignError(f"--open-area {self.open_fraction}: expected a fraction in (0, 1)")
        if not self.feature_um >= LITHOGRAPHY_UM:
            raise tp.DesignError(f"--feature-um {self.feature_um}: below the {LITHOGRAPHY_UM} µm that backplane "
                                 "lithography patterns (LTPS); expected ≥ 1.5")
        n = self.cell_um / self.feature_um
        if not (self.cell_um > 0 and abs(n - round(n)) < 1e-9 and round(n) >= 3):
            raise tp.DesignError(f"--cell-um {self.cell_um}: the minimum feature size {self.feature_um} µm cannot "
                                 f"tile it; expected a multiple (≥ 3 ×) of the feature size")
        if round(self.open_fraction * self.cell_px ** 2) < 1:
            raise tp.DesignError(f"--open-area {self.open_fraction}: less than one {self.feature_um} µm square of "
                                 f"the {self.cell_px} × {self.cell_px} cell")
        for key, allowed in (("tiling", TILINGS), ("objective", OBJECTIVES)):
            if getattr(self, key) not in allowed:
                raise tp.DesignError(f"--{key} {getattr(self, key)}: expected one of {', '.join(allowed)}")
        if not (isinstance(self.steps, int) and self.steps >= 1 and self.lr > 0):
            raise tp.DesignError(f"--steps {self.steps} / --lr {self.lr}: expected ≥ 1 step and a rate > 0")

    @property
    def cell_px(self) -> int:
        return round(self.cell_um / self.feature_um)


def project(a: np.ndarray, open_fraction: float) -> np.ndarray:
    """The binary cell with the round(open_fraction · c²) largest transmissions open (ties by position)."""
    flat = np.asarray(a, np.float64).ravel()
    keep = np.argsort(-flat, kind="stable")[: round(open_fraction * flat.size)]
    out = np.zeros(flat.size)
    out[keep] = 1.0
    return out.reshape(np.shape(a))


class Designer:
    """The objective and one optimisation step; state (θ, Adam, the losses) is what a checkpoint keeps."""

    def __init__(self, config: DesignConfig, sensor: SensorConfig | None = None, device: str = "cpu"):
        self.config, self.sensor, self.device = config, sensor or SensorConfig(), device
        self.grid = tp.cell_grid(config.cell_px, config.feature_um, Lens(), RIG_WAVELENGTHS_NM, 3.1,
                                 config.kernel_px, config.pupil_samples)
        variance = (metrics.RMS_CONTRAST * metrics.MEAN_LEVEL) ** 2
        self.signal = torch.tensor(metrics.natural_spectrum(config.kernel_px, variance), device=device)
        root = math.sqrt(config.open_fraction)  # mean a² ≈ the open area at the start (β = 1)
        target = math.log(root / (1 - root))
        init = stream(config.seed, "design", "init").normal(0.0, 0.5, (config.cell_px,) * 2) + target
        self.theta = torch.tensor(init, device=device, requires_grad=True)
        self.moments = [torch.zeros_like(self.theta), torch.zeros_like(self.theta)]
        self.step_done, self.losses = 0, []

    def beta(self, step: int) -> float:
        return BETA_MAX ** (step / max(self.config.steps - 1, 1))

    def transforms(self, step: int | None):
        """A fresh D4 tiling per step (turned), the final one for the evaluation (step None)."""
        if self.config.tiling == "repeated":
            return None
        return tp.tile_transforms(self.grid.tiles, self.config.seed, keys=("design", "final" if step is None else step))

    def objective(self, cell: torch.Tensor, transforms) -> tuple[torch.Tensor, dict]:
        """(loss, its parts as floats) of a cell of transmissions (module doc)."""
        k = tp.kernels(cell, self.grid, transforms)
        h = torch.fft.fft2(torch.fft.ifftshift(k, dim=(-2, -1)))
        t = (cell ** 2).mean()
        if self.config.objective == "wiener":
            noise = metrics.noise_variance(self.sensor, metrics.MEAN_LEVEL, t)
            main = torch.stack([metrics.wiener_mse(hc, self.signal, noise, t) for hc in h]).mean()
        else:
            w = (h.abs() ** 2 / (h.abs() ** 2 + 0.015)).flatten()
            main = -0.01 * torch.topk(w, int(0.3 * w.numel()), largest=False).values.mean()
        penalty = OPEN_WEIGHT * (t - self.config.open_fraction) ** 2
        return main + penalty, {"objective": float(main.detach()), "open_penalty": float(penalty.detach()),
                                "open_area": float(t.detach())}

    def step(self) -> dict:
        s = self.step_done
        self.theta.grad = None
        loss, parts = self.objective(torch.sigmoid(self.beta(s) * self.theta), self.transforms(s))
        loss.backward()
        self._adam(self.theta.grad, s + 1)
        self.step_done += 1
        self.losses.append({"step": s, "loss": float(loss.detach()), **parts})
        return self.losses[-1]

    def _adam(self, grad: torch.Tensor, t: int) -> None:
        """Adam (Kingma & Ba 2015, Algorithm 1; β = 0.9, 0.999, ε = 1e-8): written out, so that neither the run
        nor its tests pay torch.optim's first-use import of torch._dynamo (seconds)."""
        m, v = self.moments
        m.mul_(ADAM_BETAS[0]).add_(grad, alpha=1 - ADAM_BETAS[0])
        v.mul_(ADAM_BETAS[1]).addcmul_(grad, grad, value=1 - ADAM_BETAS[1])
        m_hat, v_hat = m / (1 - ADAM_BETAS[0] ** t), v / (1 - ADAM_BETAS[1] ** t)
        with torch.no_grad():
            self.theta.sub_(self.config.lr * m_hat / (v_hat.sqrt() + 1e-8))

    def final_cell(self) -> np.ndarray:
        a = torch.sigmoid(BETA_MAX * self.theta).detach().cpu().numpy()
        return project(a, self.config.open_fraction)

    def state(self) -> dict:
        return {"config": asdict(self.config), "theta": self.theta.detach().cpu(),
                "moments": [t.cpu() for t in self.moments],
                "step": self.step_done, "losses": self.losses}

    def load(self, state: dict) -> None:
        if state["config"] != asdict(self.config):
            changed = sorted(k for k, v in asdict(self.config).items() if state["config"].get(k) != v)
            raise tp.DesignError(f"the output folder holds a run with other settings ({', '.join(changed)}); "
                                 "use another --out or the same settings to resume")
        with torch.no_grad():
            self.theta.copy_(state["theta"].to(self.device))
            for t, saved in zip(self.moments, state["moments"]):
                t.copy_(saved.to(self.device))
        self.step_done, self.losses = int(state["step"]), list(state["losses"])
