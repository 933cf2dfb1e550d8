"""The layout study's outputs: study_layout.json, study_layout.md, study_layout_mtf.png, study_layout_rings.png and,
with a restorer, study_layout_restored_{tiling}.png (udc_render.studies.layout), written atomically
(udc_render.io.files)."""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from udc_render.design import upc
from udc_render.io.files import save_figure, save_json, save_text
from udc_render.io.images import write_png
from udc_render.studies.layout import TILINGS, LayoutScores

__all__ = ["THEIRS", "markdown", "write"]

# Yang & Sankaranarayanan's saved mtf_radial.mat (design/upc_layout_metric.md): means over k = 1…146, R / G / B.
THEIRS = {"repeated": {"mean_of_ring_means": (0.144, 0.156, 0.147), "mean_of_ring_minima": (0.0098, 0.0120, 0.0132)},
          "turned": {"mean_of_ring_means": (0.140, 0.143, 0.146), "mean_of_ring_minima": (0.107, 0.109, 0.113)}}


def _rgb(v) -> str:
    return " / ".join(f"{x:.4f}" for x in v)


def markdown(s: LayoutScores) -> str:
    """The study's tables: ring statistics in both modes (UPC's T-OLED numbers beside them), restorability."""
    lines = [f"# Layout study: {s.name}", "",
             f"Open area {s.open_fraction:.4f}, power transmittance {s.power_transmittance:.4f}, cell "
             f"{s.period_um:.1f} µm; turned tilings: seed {s.seed} (D4 per tile); cell framing: {s.frame}; "
             f"{s.seconds:.1f} s.", "",
             "## Ring statistics of the MTF (R / G / B; means over k = 1…146)", "",
             "| mode | tiling | mean of ring means | mean of ring minima |", "|---|---|---|---|"]
    for mode, table in (("UPC-compatible", s.upc), ("exact kernels, UPC's optics", s.exact)):
        for tiling in TILINGS:
            t = table[tiling]
            lines.append(f"| {mode} | {tiling} | {_rgb(t['mean_of_ring_means'])} | {_rgb(t['mean_of_ring_minima'])} |")
    for tiling in TILINGS:
        t = THEIRS[tiling]
        lines.append(f"| UPC's saved T-OLED | {tiling} | {_rgb(t['mean_of_ring_means'])} | "
                     f"{_rgb(t['mean_of_ring_minima'])} |")
    if "kept" in s.upc["turned"]:  # reports from before the share was recorded lack it
        lines += ["", "UPC-compatible mode: the share of the power inside their 1174² crop (the PSF is normalised "
                  f"after it, raising its MTF by 1 / share): turned {_rgb(s.upc['turned']['kept'])}, repeated "
                  f"{_rgb(s.upc['repeated']['kept'])}."]
    lines += ["", "## Wiener restorability on the paper's rig (PSNR in dB, R / G / B; 640 / 520 / 450 nm)", "",
              "| tiling | Wiener PSNR | light inside the 255-px window | Wiener PSNR, the light outside lost |",
              "|---|---|---|---|"]
    for tiling in TILINGS:
        r = s.restorability[tiling]
        lines.append(f"| {tiling} | {' / '.join(f'{v:.2f}' for v in r['wiener_psnr_db'])} | "
                     f"{' / '.join(f'{v:.3f}' for v in r['window_fraction'])} | "
                     f"{' / '.join(f'{v:.2f}' for v in r['window']['wiener_psnr_db'])} |")
    lines += _restored_lines(s)
    lines += _banding_lines(s.banding)
    r = s.restorability["repeated"]
    lines += ["", f"Scene mean {r['mean_level']} of the full well, RMS contrast {r['rms_contrast']}, power spectrum "
              f"∝ 1/f²; noise: shot + read {r['read_noise_e']} e⁻ at a full well of {r['full_well_e']:.0f} e⁻ "
              f"(variance {r['noise_variance'][0]:.3g} full wells² in R).", ""]
    return "\n".join(lines)


def _restored_lines(s: LayoutScores) -> list[str]:
    """The restored-PSNR table (udc_render.studies.layout_restore), when the study ran a restorer."""
    if not s.restored:
        return []
    first = s.restored[TILINGS[0]]
    lines = ["", f"## Restored PSNR by DeP ({first['image']}, {len(first['crops'])} crop(s) of "
             f"{first['crop_px']} px; PSNR in dB of the full well, R / G / B)", "",
             "| tiling | DeP PSNR | mean | noisy input y / t | Wiener PSNR, the light outside lost |",
             "|---|---|---|---|---|"]
    for tiling in TILINGS:
        d, w = s.restored[tiling], s.restorability[tiling]["window"]
        lines.append(f"| {tiling} | {' / '.join(f'{v:.2f}' for v in d['psnr_db'])} | {d['mean_psnr_db']:.2f} | "
                     f"{' / '.join(f'{v:.2f}' for v in d['input_psnr_db'])} | "
                     f"{' / '.join(f'{v:.2f}' for v in w['wiener_psnr_db'])} |")
    lines += ["", "y = t (x ⊗ k) + Poisson-Gaussian noise at the restorability's exposure, t the open area × the "
              "light inside the window; DeP: NLM, ÷ t, unsupervised Wiener-Hunt with the same kernel (seeded)."]
    return lines


def _banding_lines(b: dict) -> list[str]:
    """The banding table (udc_render.studies.layout_banding): per channel, the strongest band along x and y."""
    lines = ["", f"## Banding at d = {b['distance_mm']:g} mm, the layout repeated (the rig's lens; bands of "
             f"{b['band_period_um'][0]:.0f} × {b['band_period_um'][1]:.0f} µm / h on the sensor)", "",
             "| λ (nm) | along x: h, amplitude | along y: h, amplitude | peak-to-peak | strongest after the PSF |",
             "|---|---|---|---|---|"]
    for i, wl in enumerate(b["wavelengths_nm"]):
        after = f"{b['after_psf'][i]:.2e}" if "after_psf" in b else ""
        lines.append(f"| {wl:.0f} | {b['order_x'][i]}, {b['amplitude_x'][i]:.2e} | {b['order_y'][i]}, "
                     f"{b['amplitude_y'][i]:.2e} | {b['peak_to_peak'][i]:.2e} | {after} |")
    lines += ["", "Amplitude 2|w_h|/w_0 of the strongest harmonic h of the exact power series P(s) (the banding "
              "study's A1, relative to the mean); peak-to-peak of P over one period of shifts."]
    return lines + (_sampled_lines(b["sampled"]) if "sampled" in b else [])


def _sampled_lines(b: dict) -> list[str]:
    """Both tilings' P(s) sampled in space (layout_banding.sampled_banding), relative to its mean."""
    lines = ["", f"### Both tilings, P(s) sampled on {b['sample_um']:g} µm over the shifts the paper's sensor sees "
             f"(|s| ≤ {b['span_um'][0]:.0f} × {b['span_um'][1]:.0f} µm)", "",
             "| λ (nm) | repeated: peak-to-peak, sd | repeated: sd over its registrations | turned: peak-to-peak, sd "
             "| turned, one period: peak-to-peak, sd |",
             "|---|---|---|---|---|"]
    rep, turn = b["repeated"], b["turned"]
    registered = rep.get("rms_registered", [float("nan")] * len(rep["rms"]))
    for i, wl in enumerate(b.get("wavelengths_nm", [])):
        lines.append(f"| {wl:.0f} | {rep['peak_to_peak'][i]:.2e}, {rep['rms'][i]:.2e} | {registered[i]:.2e} | "
                     f"{turn['peak_to_peak'][i]:.2e}, {turn['rms'][i]:.2e} | "
                     f"{turn['peak_to_peak_one_period'][i]:.2e}, {turn['rms_one_period'][i]:.2e} |")
    return lines + ["", "The repeated tiling's figures are at one registration (a tile's corner on the axis); its sd "
                    "over its registrations is the root mean over every offset of one period "
                    "(udc_render.design.registration). The turned tiling's power is not periodic: over the sensor's "
                    "span it varies more than over one period of shifts, which is all that a model repeating one "
                    "period's power (the engine's field blend for a turned tiling) can print."]


def _figures(s: LayoutScores, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 2, figsize=(9, 8.5))
    for i, tiling in enumerate(TILINGS):
        for j, mode in enumerate(("upc", "exact")):
            m = s.mtf_maps[tiling][mode]
            im = axes[i, j].imshow(np.log10(np.maximum(m, 1e-4)), vmin=-3, vmax=0, cmap="magma")
            axes[i, j].set_title(f"{'UPC mode' if mode == 'upc' else 'exact kernels'}, {tiling} (G)")
            axes[i, j].set_xticks([])
            axes[i, j].set_yticks([])
    fig.colorbar(im, ax=axes, shrink=0.6, label="log10 MTF")
    save_figure(fig, out / "study_layout_mtf.png")
    plt.close(fig)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, (mode, table) in zip(axes, (("UPC mode", s.upc), ("exact kernels", s.exact))):
        for tiling, colour in zip(TILINGS, ("C0", "C3")):
            t = table[tiling]
            k = np.arange(len(t["ring_means"][1]))
            ax.plot(k[1:], t["ring_means"][1][1:], colour, label=f"{tiling}: ring mean")
            ax.plot(k[1:], t["ring_minima"][1][1:], colour, ls="--", label=f"{tiling}: ring minimum")
        ax.set_yscale("log")
        ax.set_xlabel("ring radius k (FFT bins)")
        ax.set_title(f"{s.name}, {mode} (G)")
        ax.legend(fontsize=8)
    save_figure(fig, out / "study_layout_rings.png")
    plt.close(fig)


def write(s: LayoutScores, out: Path) -> list[str]:
    """Write the JSON (every figure and curve, without the MTF maps), the Markdown and the figures."""
    doc = {k: v for k, v in asdict(s).items() if k != "mtf_maps"}
    doc["restored"] = {t: {k: v for k, v in d.items() if k != "first_crop"} for t, d in s.restored.items()}
    doc["upc_parameters"] = {"cell_px": upc.CELL_PX, "pupil_um": upc.PUPIL_UM, "focal_um": upc.FOCAL_UM,
                             "aperture_um": upc.APERTURE_UM, "wavelengths_nm": upc.WAVELENGTHS_NM,
                             "grid_sizes": upc.grid_sizes(), "crop_px": upc.CROP_PX, "box_px": upc.BOX_PX}
    doc["theirs_toled"] = THEIRS
    save_json(out / "study_layout.json", doc)
    save_text(out / "study_layout.md", markdown(s))
    _figures(s, out)
    return ["study_layout.json", "study_layout.md", "study_layout_mtf.png", "study_layout_rings.png"] + [
        _restored_figure(s.restored[t], out / f"study_layout_restored_{t}.png") for t in s.restored]


def restored_panels(first_crop: np.ndarray) -> np.ndarray:
    """The first crop's truth, input y / t and estimate [3, 3, h, w] side by side as 8-bit RGB [h, 3w, 3]: the
    crops were sRGB code values taken as linear, shown as code values again, divided by the truth's maximum."""
    x = np.clip(np.asarray(first_crop) / first_crop[0].max(), 0.0, 1.0)
    return np.round(255 * np.concatenate(list(x), axis=-1).transpose(1, 2, 0)).astype(np.uint8)


def _restored_figure(d: dict, path: Path) -> str:
    """study_layout_restored_{tiling}.png: restored_panels of the first crop (truth | input | DeP)."""
    write_png(path, restored_panels(d["first_crop"]))
    return path.name
