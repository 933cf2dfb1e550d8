"""`udc-render study layout-dipole`: a turned tiling's bands, UPC's statistic and the veil objective against the
cell's dipole (issue 48).

Why the dipole (leading order in the tile over the aperture): P(s) = ∫ A(r − s) I(r) dr, I the transmitted intensity
at d (udc_render.design.tiling_power). Taking I as the sum of the tiles' own intensities (cross-tile interference
left out), a tile at c_t turned by the D4 element g_t adds

    ∫ A(r − s) I_0(g_t⁻¹(r − c_t)) dr ≈ P_0 A(c_t − s) + P_0 (g_t μ) · ∇A(c_t − s) + …,

μ the centroid of the tile's intensity about the tile's centre (kept over any d: a real amplitude carries no mean
transverse momentum). The first term is the plain lattice's; the second averages to zero over D4 and adds, tile by
tile along the aperture's rim, a variance (|μ|² / 2) P_0² Σ_t |∇A(c_t − s)|²: over the shifts, sd² ≈ sd_0² + κ |μ|².
The same dipole decorrelates the turned tiles' far fields at low angles: the diffuse light between the diffraction
orders that UPC's ring minima read.

The study moves the preset T-OLED's slit across its cell (starts.toled_cell: the T-OLED on the design's 21 × 21
squares of 8 µm at the open area, `design --init toled`, rolled k = 0 … 10 squares along x from the slit at the
tile's edge: |μ| from 64 to 2 µm) and
reports per framing |μ|; the bands of the turned and the repeated tiling (layout_banding.sampled_banding: the
relative sd of P over the paper sensor's shifts at d = 2 mm; turned, the root mean square over `draws` draws of
`study layout --tile-seed N`); UPC's mean ring minima over the edge-framed T-OLED's (their sampling, turned, the mean
over the same number of draws, job.ratio_over_draws); the veil objective's PSNR (design --objective crop --contrast 1
--far-veil, held-out tiling, and tiled plainly: a framing of a repeated display is a shift of it, which moves its
objective little); and the least-squares fit sd² = a + κ |μ|² of the turned bands.
"""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from psf.lens import Lens
from udc_render.design.tiling_power import sampled_banding
from udc_render.io.files import save_json
from udc_render.studies.report import md_table, pyplot, save_plot, write_tables

__all__ = ["NAME", "FULL", "QUICK", "centroid_um", "framing_rows", "fit_dipole", "run_study"]

NAME = "study_layout_dipole"
FULL = {"rolls": list(range(11)), "draws": 3, "sample_um": 2.0, "kernel_px": 255, "pupil_samples": 1024}
QUICK = {"rolls": [0, 4, 8], "draws": 2, "sample_um": 8.0, "kernel_px": 63, "pupil_samples": 256}
CELL_UM, OPEN, FEATURE_UM = 168.0, 0.20, 8.0


def centroid_um(cell: np.ndarray, cell_um: float = CELL_UM) -> float:
    """|μ|: the distance of the cell's intensity centroid (amplitude², its squares' centres) from the tile's centre."""
    n = cell.shape[0]
    x = (np.arange(n) + 0.5) * cell_um / n - cell_um / 2
    w = np.asarray(cell, np.float64) ** 2
    w = w / w.sum()
    return float(np.hypot((w * x[None, :]).sum(), (w * x[:, None]).sum()))


def _bands(cell: np.ndarray, cfg: dict) -> tuple[list, list]:
    """(turned, repeated) relative sd of P per channel: turned the root mean square over the draws."""
    from udc_render.design.optimise import RIG_WAVELENGTHS_NM
    kw = dict(sample_um=cfg["sample_um"])
    repeated = sampled_banding(cell, FEATURE_UM, Lens(), RIG_WAVELENGTHS_NM, tilings=("repeated",), **kw)
    turned = [sampled_banding(cell, FEATURE_UM, Lens(), RIG_WAVELENGTHS_NM, seed=s, tilings=("turned",), **kw)
              ["turned"]["rms"] for s in range(cfg["draws"])]
    return np.sqrt(np.mean(np.square(turned), axis=0)).tolist(), repeated["repeated"]["rms"]


def framing_rows(cfg: dict, progress=None) -> list[dict]:
    """One row per roll k (module doc): |μ|, the bands and UPC's ratio (R, G, B each), the veil objective's PSNR
    turned and repeated."""
    from udc_render.design.cells import toled_reference
    from udc_render.design.config import DesignConfig
    from udc_render.design.job import ratio_over_draws
    from udc_render.design.optimise import Designer
    from udc_render.design.starts import toled_cell
    ref = toled_reference(CELL_UM, OPEN)
    config = DesignConfig(objective="crop", contrast=1.0, far_veil=True, kernel_px=cfg["kernel_px"],
                          pupil_samples=cfg["pupil_samples"], scatters=1)
    designer, toled = Designer(config), toled_cell(config)
    plain = Designer(replace(config, tiling="repeated"))
    rows = []
    for k in cfg["rolls"]:
        start = time.perf_counter()
        cell = np.roll(toled, k, axis=1)
        turned, repeated = _bands(cell, cfg)
        upc = ratio_over_draws({"design": cell, "toled_edge": ref}, 0, n=cfg["draws"])["mean"]
        rows.append({"roll": k, "centroid_um": centroid_um(cell), "bands_turned": turned, "bands_repeated": repeated,
                     "upc_ratio": upc, "veil_psnr_db": designer.score(cell)["psnr_db"],
                     "veil_psnr_repeated_db": plain.score(cell)["psnr_db"],
                     "seconds": time.perf_counter() - start})
        if progress:
            progress(1)
    return rows


def fit_dipole(rows: list[dict], channel: int = 1) -> dict:
    """The least-squares sd² = a + κ |μ|² of the turned bands in one channel, with its largest relative misfit."""
    mu2 = np.array([r["centroid_um"] ** 2 for r in rows])
    sd2 = np.array([r["bands_turned"][channel] ** 2 for r in rows])
    (a, kappa), *_ = np.linalg.lstsq(np.stack([np.ones_like(mu2), mu2], 1), sd2, rcond=None)
    misfit = np.sqrt(np.clip(a + kappa * mu2, 0, None) / sd2) - 1
    return {"channel": "RGB"[channel], "a": float(a), "kappa_per_um2": float(kappa),
            "sd0": float(np.sqrt(max(a, 0.0))), "max_rel_misfit_sd": float(np.max(np.abs(misfit)))}


def _figure(doc: dict, out: Path) -> None:
    plt = pyplot()
    rows = doc["rows"]
    mu = [r["centroid_um"] for r in rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    a.plot(mu, [1e3 * r["bands_turned"][1] for r in rows], "o", label="turned (G)")
    a.plot(mu, [1e3 * r["bands_repeated"][1] for r in rows], "s", label="repeated (G)")
    fit = doc["fit"]
    grid = np.linspace(0, max(mu), 100)
    a.plot(grid, 1e3 * np.sqrt(fit["a"] + fit["kappa_per_um2"] * grid ** 2), "-", lw=1,
           label=f"sd² = a + κ|μ|², κ = {fit['kappa_per_um2']:.2e} /µm²")
    a.set_xlabel("|μ|: the cell's centroid from the tile's centre (µm)")
    a.set_ylabel("bands at d = 2 mm: sd of P / mean (×10⁻³)")
    a.legend(fontsize=8)
    a.grid(alpha=0.3)
    b.plot(mu, [r["upc_ratio"][1] for r in rows], "o-", label="UPC's mean ring minima ÷ edge T-OLED's (G)")
    b.set_xlabel("|μ| (µm)")
    b.set_ylabel("UPC ratio (G)")
    c = b.twinx()
    c.plot(mu, [r["veil_psnr_db"] for r in rows], "s-", color="C3", label="veil objective (dB)")
    c.set_ylabel("veil objective PSNR (dB)", color="C3")
    handles = b.get_legend_handles_labels()[0] + c.get_legend_handles_labels()[0]
    b.legend(handles, [h.get_label() for h in handles], fontsize=8, loc="upper left")
    b.grid(alpha=0.3)
    fig.suptitle("The T-OLED's slit moved across its 168 µm cell: bands, UPC's statistic and the veil objective")
    save_plot(fig, out / f"{NAME}.png")


def _markdown(doc: dict) -> str:
    rows = [{**r, "mu": r["centroid_um"], "t": 1e3 * r["bands_turned"][1], "p": 1e3 * r["bands_repeated"][1],
             "u": r["upc_ratio"][1], "v": r["veil_psnr_db"], "w": r["veil_psnr_repeated_db"]} for r in doc["rows"]]
    fit = doc["fit"]
    f2 = lambda v: f"{v:.2f}"  # noqa: E731
    lines = ["# Layout study: the cell's dipole", "",
             f"The preset T-OLED at {OPEN:.0%} open area on a {CELL_UM:g} µm cell's {FEATURE_UM:g} µm squares "
             "(`design --init toled`), its slit rolled along x from the tile's edge; bands at d = 2 mm over the paper "
             "sensor's shifts "
             f"({doc['config']['sample_um']:g} µm raster; turned: root mean square over {doc['config']['draws']} "
             "draws); UPC's ratio to design.json's edge-framed T-OLED (area-weighted, not on the squares), turned, "
             "mean over as many draws; the veil objective "
             "(design --objective crop --contrast 1 --far-veil) on the held-out tiling. Green shown; the JSON holds "
             "R, G, B.", "",
             *md_table(rows, [("roll", "roll (squares)"), ("mu", "centroid offset (µm)"), ("t", "turned sd (×10⁻³)"),
                              ("p", "repeated sd (×10⁻³)"), ("u", "UPC ratio"), ("v", "veil objective (dB)"),
                              ("w", "veil objective, repeated (dB)")],
                       {"roll": str, "mu": lambda v: f"{v:.1f}", "t": f2, "p": f2, "u": lambda v: f"{v:.3f}",
                        "v": f2, "w": f2}), "",
             f"Fit of the turned bands (G): sd² = a + κ |μ|², sd₀ = {1e3 * fit['sd0']:.2f} × 10⁻³, κ = "
             f"{fit['kappa_per_um2']:.3g} per µm²; the largest misfit {fit['max_rel_misfit_sd']:.1%} of sd.", ""]
    return "\n".join(lines)


def run_study(out: Path, quick: bool = False) -> dict:
    """The module doc's rows, the fit, and out/study_layout_dipole.{json,csv,md,png}."""
    cfg = QUICK if quick else FULL
    start = time.perf_counter()
    with tqdm(total=len(cfg["rolls"]), desc="study layout-dipole") as bar:
        rows = framing_rows(cfg, bar.update)
    doc = {"config": json.loads(json.dumps(cfg)), "rows": rows, "fit": fit_dipole(rows),
           "seconds": time.perf_counter() - start}
    save_json(out / f"{NAME}.json", doc)
    flat = [{"roll": r["roll"], "centroid_um": r["centroid_um"], **{f"{key}_{c}": r[key][i] for key in
            ("bands_turned", "bands_repeated", "upc_ratio") for i, c in enumerate("RGB")},
             "veil_psnr_db": r["veil_psnr_db"], "veil_psnr_repeated_db": r["veil_psnr_repeated_db"]} for r in rows]
    write_tables(out, NAME, flat, list(flat[0]), _markdown(doc))
    _figure(doc, out)
    return doc
