"""One `udc-render design` run in an output folder: resumable (design_state.pt, written atomically every
CHECKPOINT_STEPS steps, after any step that ends CHECKPOINT_S or more after the last write, and at the end), a
progress bar, and what it writes:

    design_state.pt   the checkpoint (settings, the cell, its objective, the record): the same command resumes it
    cell.png          the designed cell, 0 / 255 (one pixel per feature square)
    design.toml       a display file of the cell repeated ([display.layout] type = "micrograph", gain 1 / open
                      area): every command takes it (psf, synth, dataset, bank, train, study layout); with --tiling
                      arranged, of supercell.png repeated: the cell in its arrangement's D4 elements, K c × K c
    design_turned.toml  with --tiling turned: the cell with the engine's random quarter-turns per tile
                      (tile_rotation; the engine turns without mirroring, the search's tilings draw the 8 D4 elements)
    design.json       the settings, the record, and in the same run on the held-out tiling: the designed cell's and
                      the initial scatter's scores, N random scatters at the same open area (their spread, the best,
                      the margin of the design over it), and UPC's mean ring minima of the designed cell and of the
                      T-OLED at the same open area in the same cell (slit at the tile's edge), turned and repeated;
                      with --banding-ceiling or arranged, the banding of both on `study layout`'s raster and draws
                      (a periodic display's over its registrations: banding_comparison); with wiener or crop, turned
                      or arranged, the design on more held-out draws (arranged: on its one tiling) paired with the
                      simulator's turned T-OLED and the T-OLED on the squares (held_out); arranged, its
                      arrangement (K × K D4 elements, torch_psf.transform_tile)
    design_loss.png   the objective's PSNR against the step, the scatters' spread beside it
"""
from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch
from tqdm import tqdm

from psf.lens import Lens
from udc_render.design.config import DesignConfig
from udc_render.design.held_out import HELD_OUT_TILINGS, applies, held_out_comparison
from udc_render.design.optimise import RIG_WAVELENGTHS_NM, Designer
from udc_render.design.starts import initial_cell, scatter
from udc_render.design.tiling_power import (
    DEFAULT_DISTANCE_MM,
    SAMPLE_UM,
    registered_variance,
    sampled_banding,
    shift_span_um,
    tiled_cell,
)
from udc_render.io.files import atomic_path, save_figure, save_json, save_text

__all__ = ["CHECKPOINT_S", "CHECKPOINT_STEPS", "UPC_DRAWS", "BANDING_SEEDS", "run_design", "display_toml", "write_png",
           "supercell", "scatter_baseline", "upc_comparison", "ratio_over_draws", "toled_banding_cell", "banding_sd",
           "registered_variances", "ratio_summary", "banding_comparison"]

CHECKPOINT_STEPS = 10
CHECKPOINT_S = 60.0  # an arranged search's step (swaps, then a sweep of 7 K² scores) can take 15 min on a core
UPC_DRAWS = 8  # more D4 tilings for UPC's ratio (ratio_over_draws): the mean's sd to about a third of one draw's
BANDING_SEEDS = (0, 1, 2, 3, 4)  # banding_comparison's draws: `study layout --tile-seed N`'s, held out from the search
WIENER_OBJECTIVES = ("wiener", "crop")  # scored as a PSNR in dB (higher is better); the others as the objective


def _save_state(designer: Designer, path: Path) -> None:
    with atomic_path(path, ".pt") as tmp:
        torch.save(designer.state(), tmp)


def display_toml(name: str, image: str, pixel_um: float, open_area: float, turned: bool, seed: int,
                 flip: bool = False, arrangement: np.ndarray | None = None) -> str:
    """A display file of the cell; its gain 1 / open area brings the capture's mean level back to glass's; turned:
    the engine's random quarter-turns, and with flip their mirror images too (D4, the search's tilings); with an
    arrangement, the cell's tiles turned by it, repeated (psf.MicrographLayout's tile_arrangement)."""
    flips = "tile_flip = true\n" if flip else ""
    turns = f"tile_rotation = true\n{flips}tile_seed = {seed}\n" if turned else ""
    if arrangement is not None:
        rows = ",\n".join(f"    {list(map(int, r))}" for r in arrangement)
        turns += f"tile_arrangement = [\n{rows},\n]\n"
    return (f'[display]\nname = "{name}"\ngain = {round(1.0 / open_area, 3)!r}\n\n[display.layout]\n'
            f'type = "micrograph"\nfile = "{image}"\npixel_um = {pixel_um!r}\nvalues = "amplitude"\n{turns}')


def scatter_baseline(designer: Designer, design: dict) -> dict:
    """N random scatters of the same open squares (streams 'design', 'scatter', k), scored as the design is (held-
    out tiling, float64): their objectives, mean, standard deviation, best, and the design's margin over the best
    (in dB for 'wiener' and 'crop', in the objective's units for 'upc' and 'rings'; positive: the design is better)."""
    scores = [designer.score(scatter(designer.config, "scatter", k)) for k in range(designer.config.scatters)]
    key = "psnr_db" if designer.config.objective in WIENER_OBJECTIVES else "objective"
    values = np.array([s[key] for s in scores])
    best = float(values.max() if key == "psnr_db" else values.min())
    margin = design[key] - best if key == "psnr_db" else best - design[key]
    return {"n": len(scores), "key": key, "values": values.tolist(), "mean": float(values.mean()),
            "std": float(values.std(ddof=1)) if len(values) > 1 else 0.0, "best": best, "margin": float(margin)}


def _upc_scores(cells: dict, turns: np.ndarray) -> tuple[dict, dict]:
    """({name: metrics.ring_summary of UPC's PSF}, {name: the share inside UPC's crop}) of 21 × 21 cells on a
    tiling, from one pass of upc.psf_and_kept each."""
    from udc_render.design import metrics, upc
    from udc_render.design.cells import RINGS
    with torch.no_grad():
        both = {name: upc.psf_and_kept(torch.tensor(c), turns) for name, c in cells.items()}
    return ({name: metrics.ring_summary(p.numpy(), RINGS) for name, (p, _) in both.items()},
            {name: k.tolist() for name, (_, k) in both.items()})


def upc_comparison(cell: np.ndarray, config: DesignConfig, arrangement: np.ndarray | None = None) -> dict:
    """UPC's mean ring minima (R / G / B, their sampling) of the designed cell and of the preset T-OLED at the same
    open area in the same cell, its slit at the tile's edge (the framing that reproduces their turned baseline),
    turned (D4 tiles, seed config.seed) and repeated, each cell taken to 21 × 21 as `study layout` takes it; the
    designed / T-OLED ratios; beside them the mean ring means and the share of the power inside UPC's crop
    (upc.kept_fraction) and the ratio of the PSFs normalised before the crop (ratio × the shares' ratio: what UPC's
    crop does not inflate); turned, the ratio over UPC_DRAWS more tilings (ratio_over_draws); with an arrangement,
    also the cell arranged so (torch_psf.arranged) against the T-OLED turned, the issue's reference."""
    from udc_render.design import torch_psf as tp, upc
    from udc_render.design.cells import toled_reference, upc_cell
    cells = {"design": upc_cell(cell), "toled_edge": toled_reference(config.cell_um, config.open_fraction)}
    scores = {tiling: _upc_scores(cells, tp.tile_transforms(upc.TILES, seed))
              for tiling, seed in (("turned", config.seed), ("repeated", None))}
    if arrangement is not None:  # the design arranged, beside the T-OLED turned
        rings, kept = _upc_scores({"design": cells["design"]}, tp.arranged(arrangement, upc.TILES))
        turned_rings, turned_kept = scores["turned"]
        scores["arranged"] = ({**rings, "toled_edge": turned_rings["toled_edge"]},
                              {**kept, "toled_edge": turned_kept["toled_edge"]})
    out = {tiling: _upc_row(rings, kept) for tiling, (rings, kept) in scores.items()}
    out["turned"]["draws"] = ratio_over_draws(cells, config.seed)
    return out


def _upc_row(rings: dict, kept: dict) -> dict:
    """One tiling's figures of upc_comparison: the mean ring minima, the design / T-OLED ratios, the ring means and
    the shares inside UPC's crop."""
    minima = {name: r["mean_of_ring_minima"] for name, r in rings.items()}
    ratio = np.divide(minima["design"], minima["toled_edge"])
    uncropped = ratio * np.divide(kept["design"], kept["toled_edge"])
    return {**minima, "ratio": ratio.tolist(), "ratio_mean": float(ratio.mean()), "ratio_uncropped": uncropped.tolist(),
            "ring_means": {name: r["mean_of_ring_means"] for name, r in rings.items()}, "kept": kept}


def ratio_over_draws(cells: dict, seed: int, n: int = UPC_DRAWS) -> dict:
    """The design / T-OLED ratio of UPC's mean ring minima over n more D4 tilings (stream keys 'upc', k: neither the
    search's nor the held-out one): per channel its mean, sample sd and minimum. One random tiling's ratio varies
    by about 1 % (sd); a target of 1.26 × is judged on the draws, not on one."""
    from udc_render.design import torch_psf as tp, upc
    ratios = []
    for k in range(n):
        rings, _ = _upc_scores(cells, tp.tile_transforms(upc.TILES, seed, keys=("upc", k)))
        ratios.append(np.divide(rings["design"]["mean_of_ring_minima"], rings["toled_edge"]["mean_of_ring_minima"]))
    r = np.array(ratios)
    return {"n": n, "mean": r.mean(0).tolist(), "sd": r.std(0, ddof=1).tolist(), "min": r.min(0).tolist()}


def toled_banding_cell(cell_um: float, open_fraction: float, pixel_um: float = SAMPLE_UM) -> tuple[np.ndarray, float]:
    """(amplitude cell, its pixel in µm): the bands' reference, the preset T-OLED at the open area in the cell, its
    slit at the tile's edge, area-weighted on ≈ pixel_um squares (84 × 84 at 2 µm for 168 µm: grey where an edge
    falls inside a square)."""
    from psf import layouts
    from udc_render.design.cells import frame_cell, layout_cell
    toled, toled_um = layout_cell(layouts.toled(pitch_um=cell_um, open_fraction=open_fraction), pixel_um)
    return frame_cell(toled, "edge"), toled_um


def banding_sd(cell: np.ndarray, pixel_um: float, tiling: str, seeds, sample_um: float = SAMPLE_UM) -> list:
    """[draw][R, G, B]: the relative sd of the power at d = 2 mm over the paper sensor's shifts
    (tiling_power.sampled_banding on its raster of sample_um) of the cell tiled so, on `study layout --tile-seed N`'s
    draws N in seeds; repeated, the root mean over its registrations (one figure)."""
    if tiling == "repeated":
        return [[float(np.sqrt(v.mean())) for v in registered_variances(cell, pixel_um, sample_um)]]
    return [sampled_banding(cell, pixel_um, Lens(), RIG_WAVELENGTHS_NM, seed=seed, sample_um=sample_um,
                            tilings=(tiling,))[tiling]["rms"] for seed in seeds]


def registered_variances(cell: np.ndarray, pixel_um: float, sample_um: float = SAMPLE_UM) -> list:
    """[R, G, B] of [p, p]: var / mean² of the power at d = 2 mm over the paper sensor's shifts at every
    registration of the cell repeated (tiling_power.registered_variance); banding_sd's repeated figure is the root
    mean of each."""
    lens, d_um = Lens(), DEFAULT_DISTANCE_MM * 1000.0
    span = shift_span_um(lens, d_um)
    return [registered_variance(cell, pixel_um, lens, wl, d_um, span, sample_um) for wl in RIG_WAVELENGTHS_NM]


def ratio_summary(design_sd: list, toled_sd: list) -> dict:
    """The per-draw ratio design / T-OLED [draw][R, G, B] and per channel its mean, sample sd, largest and the draws
    below 1."""
    r = np.divide(design_sd, toled_sd)
    return {"ratio": r.tolist(), "mean": r.mean(0).tolist(),
            "sd_of_ratio": (r.std(0, ddof=1) if len(r) > 1 else np.zeros(r.shape[1])).tolist(),
            "max": r.max(0).tolist(), "below": (r < 1).sum(0).tolist()}


def banding_comparison(cell: np.ndarray, config: DesignConfig, seeds=None, arrangement: np.ndarray | None = None
                       ) -> dict:
    """The bands (banding_sd, R / G / B) of the designed cell and of the preset T-OLED at the open area
    (toled_banding_cell), tiled as the design is, on `study layout --tile-seed N`'s draws: per draw, and
    ratio_summary's figures (seeds: BANDING_SEEDS by default); repeated, or arranged (its arrangement given: its
    super-cell, supercell, repeated), against the T-OLED repeated: one figure each, both periodic, over their
    registrations (banding_sd)."""
    tiling, seeds = config.tiling, BANDING_SEEDS if seeds is None else seeds
    if arrangement is not None:
        cell, tiling = supercell(cell, arrangement), "repeated"
    if tiling == "repeated":
        seeds = [0]
    toled, toled_um = toled_banding_cell(config.cell_um, config.open_fraction)
    sd = {"design": banding_sd(cell, config.feature_um, tiling, seeds),
          "toled_edge": banding_sd(toled, toled_um, tiling, seeds)}
    return {"tiling": config.tiling, "seeds": list(seeds), "sd": sd, **ratio_summary(sd["design"], sd["toled_edge"])}


def supercell(cell: np.ndarray, arrangement: np.ndarray) -> np.ndarray:
    """The K c × K c period of an arranged tiling: the cell in each tile's D4 element (torch_psf.tile)."""
    return tiled_cell(cell, arrangement, 1)


def _loss_figure(doc: dict, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    wiener = doc["config"]["objective"] in WIENER_OBJECTIVES
    values = [doc["initial"]["search_objective"]] + [r["objective"] for r in doc["losses"]]
    factors = [name for key, name in (("upc_floor", "the UPC floor's"), ("banding_ceiling", "the banding ceiling's"))
               if doc["config"].get(key)]
    floored = f"; J × {' and '.join(factors)} factor" if factors else ""
    ax.plot(np.arange(len(values)), -10 * np.log10(values) if wiener else values,
            label=f"the search (its tiling{floored})")
    kicks = [i + 1 for i, r in enumerate(doc["losses"]) if "kick" in r]
    if kicks:
        best = np.array([doc["initial"]["search_objective"]] + [r["best"] for r in doc["losses"]])
        ax.plot(np.arange(len(best)), -10 * np.log10(best) if wiener else best, "k--", lw=1, label="the best so far")
        for k in kicks:
            ax.axvline(k, color="0.7", lw=0.5)
        ax.plot([], [], color="0.7", lw=0.5, label=f"{len(kicks)} kicks of {doc['config']['kick_swaps']} random swaps")
    base = doc["scatters"]
    ax.axhspan(base["mean"] - base["std"], base["mean"] + base["std"], color="C3", alpha=0.2,
               label=f"{base['n']} random scatters: mean ± sd (held-out tiling)")
    ax.axhline(base["best"], color="C3", label="the best scatter")
    ax.plot([len(values) - 1], [doc["final"]["psnr_db" if wiener else "objective"]], "ko", label="the design, held out")
    ax.set_xlabel("step (an accepted swap, or a local optimum and its kick)" if kicks else "step (accepted swaps)")
    ax.set_ylabel({"wiener": "Wiener PSNR (dB)", "crop": "Wiener PSNR on the crop (dB)",
                   "rings": "−mean log of the mean ring minimum"}.get(doc["config"]["objective"], "UPC objective"))
    ax.legend(fontsize=8)
    save_figure(fig, out / "design_loss.png")
    plt.close(fig)


def _held_out(designer: Designer, cell: np.ndarray, n: int) -> dict | None:
    """held_out.held_out_comparison of the design (n draws) where it applies (the rig's wiener or crop, turned)."""
    if n < 1 or not applies(designer.config):
        return None
    return held_out_comparison(designer, {"design": cell}, n)


def write_png(path: Path, cell: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, (cell * 255).astype(np.uint8), extension=".png")


def _write(designer: Designer, out: Path, compare: bool, held_out_tilings: int) -> dict:
    cfg = designer.config
    cell, arrangement = designer.best_cell, designer.best_arrangement
    designer.arrangement = arrangement  # a run stopped by --steps scores its best cell on the best arrangement
    write_png(out / "cell.png", cell)
    open_area = float(cell.mean())
    image = "cell.png"
    if arrangement is not None:
        image = "supercell.png"
        write_png(out / image, supercell(cell, arrangement))
    save_text(out / "design.toml", display_toml("design", image, cfg.feature_um, open_area, False, cfg.seed))
    if cfg.tiling == "turned":
        save_text(out / "design_turned.toml", display_toml("design_turned", "cell.png", cfg.feature_um, open_area,
                                                           True, cfg.seed, flip=cfg.tile_flips))
    initial = initial_cell(cfg)
    final = designer.score(cell)
    doc = {"config": asdict(cfg), "final": final, "search_objective": designer.best,
           "initial": {**designer.score(initial), "search_objective": designer.search_score(initial),
                       "squares_moved": int(np.sum(initial != cell) // 2)},
           "arrangement": None if arrangement is None else arrangement.tolist(),
           "scatters": scatter_baseline(designer, final),
           "upc": upc_comparison(cell, cfg, arrangement) if compare else None,
           "banding": banding_comparison(cell, cfg, arrangement=arrangement)
           if compare and (cfg.banding_ceiling or arrangement is not None) else None,
           "held_out": _held_out(designer, cell, held_out_tilings) if compare else None,
           "open_squares": int(cell.sum()), "cell_px": cfg.cell_px, "steps_done": designer.step_done,
           "converged": designer.converged, "evaluations": designer.evaluations, "kicks_done": designer.kicks_done,
           "losses": designer.losses}
    save_json(out / "design.json", doc)
    _loss_figure(doc, out)
    return doc


def run_design(config: DesignConfig, out: Path, device: str = "cpu", quiet: bool = False, compare: bool = True,
               held_out_tilings: int = HELD_OUT_TILINGS) -> dict:
    """Search (resuming design_state.pt when the folder holds this run) and write the module doc's files (compare:
    False leaves out UPC's comparison and the held-out draws; held_out_tilings: their number, 0 none)."""
    designer = Designer(config, device=device)
    state_path = out / "design_state.pt"
    if state_path.is_file():
        designer.load(torch.load(state_path, weights_only=False))
    saved = time.monotonic()
    with tqdm(total=config.steps, initial=designer.step_done, disable=quiet, desc="design") as bar:
        while not designer.finished:
            rec = designer.step()
            bar.update(1)
            bar.set_postfix(objective=f"{rec['objective']:.4g}", tried=rec["tried"])
            if (designer.finished or designer.step_done % CHECKPOINT_STEPS == 0
                    or time.monotonic() - saved >= CHECKPOINT_S):
                _save_state(designer, state_path)
                saved = time.monotonic()
    return _write(designer, out, compare, held_out_tilings)
