"""One `udc-render design` run in an output folder: resumable (design_state.pt, written atomically every
CHECKPOINT_STEPS steps and at the end), a progress bar, and what it writes:

    design_state.pt   the checkpoint (settings, θ, Adam, losses): the same command resumes it
    cell.png          the designed cell, 0 / 255 (one pixel per feature square)
    design.toml       a display file of the cell repeated ([display.layout] type = "micrograph", gain 1 / open
                      area): every command takes it (psf, synth, dataset, bank, train, study layout)
    design_turned.toml  with --tiling turned: the cell with the engine's random quarter-turns per tile
                      (tile_rotation; the engine turns without mirroring, the optimiser drew the 8 D4 elements)
    design.json       the settings, the final cell's scores, the loss curve
    design_loss.png   the loss curve
"""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch
from tqdm import tqdm

from udc_render.design.optimise import DesignConfig, Designer
from udc_render.io.files import atomic_path, save_figure, save_json, save_text

__all__ = ["CHECKPOINT_STEPS", "run_design"]

CHECKPOINT_STEPS = 10


def _save_state(designer: Designer, path: Path) -> None:
    with atomic_path(path, ".pt") as tmp:
        torch.save(designer.state(), tmp)


def _display_toml(name: str, image: str, pixel_um: float, open_area: float, turned: bool, seed: int) -> str:
    """A display file of the cell; its gain 1 / open area brings the capture's mean level back to glass's."""
    turns = f"tile_rotation = true\ntile_seed = {seed}\n" if turned else ""
    return (f'[display]\nname = "{name}"\ngain = {round(1.0 / open_area, 3)!r}\n\n[display.layout]\n'
            f'type = "micrograph"\nfile = "{image}"\npixel_um = {pixel_um!r}\nvalues = "amplitude"\n{turns}')


def _loss_figure(losses: list, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    steps = [r["step"] for r in losses]
    ax.plot(steps, [r["loss"] for r in losses], label="loss")
    ax.plot(steps, [r["objective"] for r in losses], label="objective")
    ax.set_yscale("symlog", linthresh=1e-4)
    ax.set_xlabel("step")
    ax.legend()
    save_figure(fig, out / "design_loss.png")
    plt.close(fig)


def _write(designer: Designer, out: Path) -> dict:
    cfg = designer.config
    cell = designer.final_cell()
    with torch.no_grad():
        _, scores = designer.objective(torch.tensor(cell, device=designer.device), designer.transforms(None))
    with atomic_path(out / "cell.png") as tmp:
        iio.imwrite(tmp, (cell * 255).astype(np.uint8), extension=".png")
    open_area = float(cell.mean())
    save_text(out / "design.toml", _display_toml("design", "cell.png", cfg.feature_um, open_area, False, cfg.seed))
    if cfg.tiling == "turned":
        save_text(out / "design_turned.toml", _display_toml("design_turned", "cell.png", cfg.feature_um, open_area,
                                                            True, cfg.seed))
    doc = {"config": asdict(cfg), "final": scores, "open_squares": int(cell.sum()), "cell_px": cfg.cell_px,
           "losses": designer.losses}
    save_json(out / "design.json", doc)
    _loss_figure(designer.losses, out)
    return doc


def run_design(config: DesignConfig, out: Path, device: str = "cpu", quiet: bool = False) -> dict:
    """Optimise (resuming design_state.pt when the folder holds this run) and write the module doc's files."""
    designer = Designer(config, device=device)
    state_path = out / "design_state.pt"
    if state_path.is_file():
        designer.load(torch.load(state_path, weights_only=False))
    with tqdm(total=config.steps, initial=designer.step_done, disable=quiet, desc="design") as bar:
        while designer.step_done < config.steps:
            rec = designer.step()
            bar.update(1)
            bar.set_postfix(loss=f"{rec['loss']:.3g}", open=f"{rec['open_area']:.3f}")
            if designer.step_done % CHECKPOINT_STEPS == 0 or designer.step_done == config.steps:
                _save_state(designer, state_path)
    return _write(designer, out)
