"""`udc-render study realism`: the observables the paper gives for its real displays, ours beside the
paper's with a verdict per row, over the parameters no micrograph fixes (docs/PHYSICS.md §8).

Swept: the T-OLED pitch and slit shape (the slit's height fraction), the P-OLED pitch, opening
arrangement (small-to-large radius) and fabrication disorder (a jittered supercell), and, for the
capture rows, the display-to-lens distance d. For each layout, kernels at 450, 550 and 650 nm on the
paper's 1.55 µm pixels, d = 0, averaged over the three wavelengths, give:

- transmittance τ: propagating power through display and aperture / through the bare aperture, and
  the whole stack's τ · mean T(λ) over 400–700 nm beside the paper's spectrophotometer (T-OLED 20 %,
  P-OLED 2.9 %, l.114; the paper's own γ and gains contradict its 2.9 %, see optics.displays);
- the T-OLED's x contrast: the ratio MTF_x / MTF_y, where it first drops below LOSS_RATIO, and its
  mean over the lowest decade of the band against the middle third. The paper: "contrasts along the
  horizontal direction are mostly lost in the mid-band frequency" (l.125). Verdict 'mid-band' when
  the lowest decade keeps at least LOW_OVER_MID × the middle third's ratio (low frequencies, where
  images carry most energy, keep their contrast; it is lost above);
- the P-OLED's lowest MTF relative to glass below 0.45 cycles/px: "nulls have not been observed"
  (l.125); verdict 'no null' above NULL_LEVEL;
- the share of the kernel's energy within ±k pixels of its centre (k = 1, 5, 25);
- the pitch order: "the P-OLED has a finer pixel pitch" (l.116);
- the P-OLED T(λ) (full run): the polyimide × cathode fit at several Urbach widths, the four γ
  against 0.34/0.34/0.34/0.20 (30 bands, 511-px kernels, the default rig);
- the capture observables (studies.realism_capture): γ per RGGB channel by the paper's protocol,
  input and DeP PSNR/SSIM under the paper protocol at 2048 × 1024, banding visibility over d.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from psf import Lens, compute_kernels, layouts
from udc_render.calibration.fit_gains import FIT_EDGES_NM, fit_gains
from udc_render.io.plots import mtf_lines, pyplot
from udc_render.optics import displays as D, gamma as G
from udc_render.sensor import rgb_to_rggb
from udc_render.studies import realism_capture as rc
from udc_render.studies.realism_banding import banding_row
from udc_render.studies.realism_paper import dep_order_row
from udc_render.studies.report import md_table, save_plot, write_tables

WAVELENGTHS_NM = (450.0, 550.0, 650.0)
PIXEL_UM = 1.55  # the paper's sensor
LOSS_RATIO = 0.5
LOW_DECADE, MID_THIRD = (0.0, 0.1), (1 / 3, 2 / 3)  # fractions of Nyquist
LOW_OVER_MID = 1.5
NULL_LEVEL = 0.05
ENERGY_RADII_PX = (1, 5, 25)
PAPER = {"toled": {"transmission": 0.20, "x_loss": "mostly lost in the mid-band frequency"},
         "poled": {"transmission": 0.029, "min_mtf": "no null observed"}}
COLUMNS = ["display", "pitch_um", "observable", "ours", "paper", "verdict"]


@dataclass(frozen=True)
class Config:
    """One layout of the sweep: a preset's factory with some knobs changed, optionally disordered."""
    kind: str  # glass | toled | poled
    knobs: tuple = ()  # ((name, value), …) for layouts.toled / layouts.poled
    disorder: tuple | None = None  # (cells, position_sd_um, size_sd) for layouts.disordered

    @property
    def pitch_um(self) -> float | None:
        return None if self.kind == "glass" else self.layout().pitch_x_um / (self.disorder or (1,))[0]

    @property
    def label(self) -> str:
        parts = [self.kind] + [f"{k}={v:g}" for k, v in self.knobs]
        if self.disorder:
            parts.append(f"disorder σ={self.disorder[1]:g} µm/{self.disorder[2]:.0%}")
        return " ".join(parts)

    def layout(self):
        if self.kind == "glass":
            return None
        base = getattr(layouts, self.kind)(**dict(self.knobs))
        return base if self.disorder is None else layouts.disordered(base, *self.disorder)

    def display(self) -> D.Display:
        """The preset with this layout (its T(λ) and gain)."""
        return replace(D.preset(self.kind), layout=self.layout(), source=f"study realism: {self.label}")


def _sweep(kind, name, values):
    return [Config(kind, ((name, v),)) for v in values]


FULL = {"kernel_px": 511, "images": 3,
        "configs": [Config("glass")] + _sweep("toled", "pitch_um", (60.0, 168.0, 240.0, 317.0))
        + [Config("toled", (("slit_height_fraction", h),)) for h in (0.6, 1.0)]
        + _sweep("poled", "pitch_um", (45.0, 64.0, 90.0))
        + [Config("poled", (("small_to_large", k),)) for k in (0.5, 1.0)]
        + [Config("poled", (), (2, 2.0, 0.1))],
        "capture_configs": [Config("toled"), Config("poled"), Config("toled", (("pitch_um", 60.0),)),
                            Config("toled", (("pitch_um", 168.0),)), Config("poled", (("pitch_um", 45.0),))],
        "distances_mm": (0.0, 0.25, 0.5, 1.0, 2.0), "urbach_widths_nm": (8.0, 20.0, 30.0)}
QUICK = {"kernel_px": 255, "images": 1,
         "configs": [Config("glass"), Config("toled"), Config("toled", (("pitch_um", 168.0),)), Config("poled")],
         "capture_configs": [Config("toled"), Config("poled")], "distances_mm": (0.0, 1.0), "urbach_widths_nm": ()}


def observe(c: Config, kernel_px: int) -> dict:
    """Kernels of one configuration ──► transmittance, the MTF lines and the energy shares."""
    ks = compute_kernels(c.layout(), Lens(), WAVELENGTHS_NM, pixel_um=PIXEL_UM, size_px=kernel_px)
    kernel = ks.kernels.astype(np.float64).mean(axis=0)
    f, mx, my = mtf_lines(kernel)
    h = kernel_px // 2
    share = {k: float(kernel[h - k:h + k + 1, h - k:h + k + 1].sum() * (1 - ks.energy_outside.mean()))
             for k in ENERGY_RADII_PX}
    return {"f": f, "mtf_x": mx, "mtf_y": my, "transmittance": float(ks.transmittance.mean()), "share": share}


def x_loss_band(obs: dict) -> tuple[float, float] | None:
    """(first, last) frequency in cycles/px where MTF_x / MTF_y < LOSS_RATIO, or None."""
    ratio = obs["mtf_x"] / np.maximum(obs["mtf_y"], 1e-12)
    lost = np.nonzero(ratio < LOSS_RATIO)[0]
    return None if lost.size == 0 else (float(obs["f"][lost[0]]), float(obs["f"][lost[-1]]))


def band_ratio(obs: dict, band: tuple[float, float]) -> float:
    """Mean MTF_x / MTF_y over a band given in fractions of Nyquist (0.5 cycles/px)."""
    f = obs["f"] / 0.5
    keep = (f >= band[0]) & (f <= band[1])
    return float(np.mean(obs["mtf_x"][keep] / np.maximum(obs["mtf_y"][keep], 1e-12)))


def min_relative_mtf(obs: dict, glass: dict) -> float:
    """Lowest MTF (x and y) relative to glass below Nyquist (0.5 cycles/px excluded: glass ~ 0 there)."""
    keep = obs["f"] < 0.45
    return float(min((obs[a][keep] / np.maximum(glass[a][keep], 1e-12)).min() for a in ("mtf_x", "mtf_y")))


def stack_transmission(c: Config, obs: dict) -> float:
    """τ × the mean of the preset's T(λ) over 400–700 nm (a flat white through the whole stack)."""
    return obs["transmittance"] * float(D.preset(c.kind).transmission(np.arange(400.0, 701.0, 1.0)).mean())


def x_contrast_rows(base: dict, obs: dict) -> list[dict]:
    band = x_loss_band(obs)
    start = "none" if band is None else f"{band[0]:.3f} cyc/px ({band[0] / 0.5:.0%} of Nyquist)"
    low, mid = band_ratio(obs, LOW_DECADE), band_ratio(obs, MID_THIRD)
    verdict = "mid-band" if low >= LOW_OVER_MID * mid else "**lost from low frequencies on**"
    return [dict(base, observable=f"x contrast loss starts (MTF_x/MTF_y < {LOSS_RATIO})", ours=start, paper="",
                 verdict=""),
            dict(base, observable="MTF_x/MTF_y: lowest decade / middle third of the band",
                 ours=f"{low:.2f} / {mid:.2f}", paper=PAPER["toled"]["x_loss"], verdict=verdict)]


def rows_for(c: Config, obs: dict, glass: dict) -> list[dict]:
    """The table rows of one configuration, with the paper's value and a verdict where one applies."""
    base = {"display": c.label, "pitch_um": c.pitch_um}
    paper_t = PAPER[c.kind]["transmission"]
    t = stack_transmission(c, obs)
    rows = [dict(base, observable="transmittance τ (display grid × aperture)", ours=f"{obs['transmittance']:.3f}",
                 paper="", verdict=""),
            dict(base, observable="stack transmission τ · mean T(λ), 400–700 nm", ours=f"{t:.2%}",
                 paper=f"{paper_t:.1%}", verdict=f"{t / paper_t:.2f} × the paper's (γ fixed instead, see README)")]
    rows += [dict(base, observable=f"share of the transmitted energy within ±{k} px", ours=f"{v:.3f}", paper="",
                  verdict="")
             for k, v in obs["share"].items()]
    if c.kind == "toled":
        rows += x_contrast_rows(base, obs)
    if c.kind == "poled":
        m = min_relative_mtf(obs, glass)
        rows.append(dict(base, observable="lowest MTF relative to glass", ours=f"{m:.3f}",
                         paper=PAPER["poled"]["min_mtf"], verdict="no null" if m > NULL_LEVEL else "**null**"))
    return rows


def pitch_order_row() -> dict:
    preset_t, preset_p = layouts.toled().pitch_x_um, layouts.poled().pitch_x_um
    return {"display": "toled vs poled", "pitch_um": None, "observable": "pitch order (the presets)",
            "ours": f"T-OLED {preset_t:g} µm, P-OLED {preset_p:g} µm", "paper": "P-OLED finer (l.116)",
            "verdict": "holds" if preset_t > preset_p else "**fails**"}


def transmission_fit_rows(widths_nm) -> list[dict]:
    """The P-OLED polyimide × cathode fit at each Urbach width on the default rig: γ and T(λ)."""
    edges = FIT_EDGES_NM
    gains = {name: fit_gains(lay) for name, lay in (("glass", None), ("poled", layouts.poled()))}
    w, rows = G.white_weights(edges, "Nikon 5100 (NPL)"), []
    for width in widths_nm:
        scale, edge, cathode = D.fit_poled_transmission(gains["poled"], gains["glass"], edges, urbach_width_nm=width)
        disp = D.Display("p", layouts.poled(), D.poled_transmission(scale, edge, cathode, width), D.PAPER_GAIN["poled"])
        g = np.array(rgb_to_rggb(G.channel_gamma(w, disp, gains["poled"], gains["glass"], edges)))
        off = np.abs(g / np.array(rgb_to_rggb(D.PAPER_GAMMA["poled"])) - 1).max()
        t = disp.transmission(np.array([450.0, 550.0, 650.0]))
        chosen = " (the preset)" if width == D.POLED_URBACH_WIDTH_NM else ""
        rows.append({"display": "poled", "pitch_um": layouts.poled().pitch_x_um,
                     "observable": f"T(λ) fit, Urbach width {width:g} nm{chosen}: γ R/Gr/Gb/B; cathode; T(450/550/650)",
                     "ours": f"{'/'.join(f'{x:.3f}' for x in g)}; {cathode:.1f} nm; "
                             f"{'/'.join(f'{x:.2%}' for x in t)}",
                     "paper": "0.34/0.34/0.34/0.20", "verdict": "within 1 %" if off < 0.01 else f"**off {off:.1%}**"})
    return rows


def plot(observed: dict, path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.2))
    glass = next(o for c, o in observed.items() if c.kind == "glass")
    for c, obs in observed.items():
        lpmm = obs["f"] / (PIXEL_UM * 1e-3)
        if c.kind != "poled":
            axes[0].plot(lpmm, obs["mtf_x"] / np.maximum(obs["mtf_y"], 1e-12), label=c.label)
        axes[1].plot(lpmm, obs["mtf_x"], label=c.label)
        if c.kind == "poled":
            keep = obs["f"] < 0.45
            axes[2].plot(lpmm[keep], (obs["mtf_x"] / np.maximum(glass["mtf_x"], 1e-12))[keep], label=c.label)
    titles = ("T-OLED x contrast: MTF_x / MTF_y", "MTF along x", "P-OLED MTF_x relative to glass")
    for ax, title in zip(axes, titles):
        ax.set_xlabel("spatial frequency (lp/mm at the sensor)")
        ax.set_title(f"{title} (450/550/650 nm, d = 0)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    save_plot(fig, path)


def psf_rows(cfg: dict, progress: bool) -> tuple[list[dict], dict]:
    observed = {c: observe(c, cfg["kernel_px"]) for c in tqdm(cfg["configs"], desc="realism: kernels",
                                                               disable=not progress)}
    glass = next(o for c, o in observed.items() if c.kind == "glass")
    rows = [r for c, o in observed.items() if c.kind != "glass" for r in rows_for(c, o, glass)]
    return rows + [pitch_order_row()], observed


def capture_part(cfg: dict, quick: bool, progress: bool) -> tuple[list[dict], list[dict], list]:
    """(rows, per-display data, banding sweep) of the capture observables (studies.realism_capture):
    γ, input/DeP PSNR/SSIM and banding for cfg's capture configurations, DeP's display order, and the
    presets' banding over the distances d."""
    rows, data = [], []
    for c in cfg["capture_configs"]:
        r, d = rc.capture_rows(c.display(), quick=quick, progress=progress, label=c.label, pitch_um=c.pitch_um)
        rows, data = rows + r, data + [d]
    presets = {c.kind: [row for row in rows if row["display"] == c.label]
               for c in cfg["capture_configs"] if not c.knobs and not c.disorder}
    if "toled" in presets and "poled" in presets:
        rows.append(dep_order_row(presets["toled"], presets["poled"]))
    sweep = []
    for kind in ("toled", "poled"):
        for d_mm in cfg["distances_mm"]:
            if d_mm > 0:
                row, b = banding_row(D.preset(kind).with_distance(d_mm))
                rows.append(row)
                sweep.append((f"{kind}", b))
    rc.clear_render_cache()
    return rows, data, sweep


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Write study_realism.csv, .md, .png and study_realism_capture.png into out_dir; returns the rows."""
    cfg, out = (QUICK if quick else FULL), Path(out_dir)
    rows, observed = psf_rows(cfg, progress)
    rows += transmission_fit_rows(cfg["urbach_widths_nm"]) if cfg["urbach_widths_nm"] else []
    capture, data, sweep = capture_part(cfg, quick, progress)
    rows += capture
    md = ("# Realism: observables against the paper\n\n"
          f"{'Quick grid. ' if quick else ''}PSF rows: kernels {cfg['kernel_px']} px of {PIXEL_UM} µm, d = 0, "
          f"mean of {', '.join(f'{w:g}' for w in WAVELENGTHS_NM)} nm. Capture rows: the default monitor scene at "
          "2048 × 1024, the paper protocol (linear, [0, 1] of the white level; the input on its packed RAW). "
          "Verdicts: udc_render/studies/realism.py and realism_capture.py.\n\n"
          + "\n".join(md_table(rows, [(k, k.replace("_", " ")) for k in COLUMNS])) + "\n")
    write_tables(out, "study_realism", rows, COLUMNS, md)
    plot(observed, out / "study_realism.png")
    rc.plot_capture(data, out / "study_realism_capture.png", sweep)
    return rows
