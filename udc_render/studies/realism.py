"""`udc-render study realism` (first part): the PSF observables the paper gives for its real displays,
ours beside the paper's with a verdict per row, over the uncertain layout parameters.

For each display configuration (the presets and a sweep of pitch, the one unknown no micrograph
fixes; docs/PHYSICS.md §8), kernels at 450, 550 and 650 nm on the paper's 1.55 µm pixels, d = 0,
averaged over the three wavelengths, give:

- transmittance τ: propagating power through display and aperture / through the bare aperture
  (the paper's spectrophotometer: T-OLED 20 %, P-OLED 2.9 %, l.114; it includes the stack's T(λ),
  which τ does not: reported beside, not judged);
- MTF along x and y of the kernel window, and the T-OLED's x contrast loss: the band of
  frequencies where MTF_x / MTF_y < LOSS_RATIO. The paper: "contrasts along the horizontal direction
  are mostly lost in the mid-band frequency" (l.125). Verdict 'mid-band' when the loss starts above
  LOW_BAND of Nyquist (the low frequencies, where images carry most energy, keep their contrast);
- the P-OLED's lowest MTF relative to glass below Nyquist: "nulls have not been observed" (l.125);
  verdict 'no null' above NULL_LEVEL;
- the share of the kernel's energy within ±k pixels of its centre (k = 1, 5, 25);
- the pitch order: "the P-OLED has a finer pixel pitch" (l.116).

The capture observables (γ per RGGB channel, input and DeP PSNR under the paper protocol, banding
visibility) are not in this first part.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from psf import Lens, compute_kernels, layouts
from udc_render.io.plots import mtf_lines, pyplot
from udc_render.studies.report import md_table, save_plot, write_tables

WAVELENGTHS_NM = (450.0, 550.0, 650.0)
PIXEL_UM = 1.55  # the paper's sensor
LOSS_RATIO = 0.5
LOW_BAND = 0.1  # fraction of Nyquist below which an image's contrast must survive for 'mid-band'
NULL_LEVEL = 0.05
ENERGY_RADII_PX = (1, 5, 25)
PAPER = {"toled": {"transmission": "20 %", "x_loss": "mostly lost in the mid-band frequency"},
         "poled": {"transmission": "2.9 %", "min_mtf": "no null observed"}}
FULL = {"kernel_px": 255, "toled_pitch_um": (60.0, 168.0, 317.0), "poled_pitch_um": (32.0, 64.0)}
QUICK = {"kernel_px": 127, "toled_pitch_um": (60.0, 168.0), "poled_pitch_um": (64.0,)}
COLUMNS = ["display", "pitch_um", "observable", "ours", "paper", "verdict"]


@dataclass(frozen=True)
class Config:
    kind: str  # toled | poled | glass
    pitch_um: float | None

    @property
    def label(self) -> str:
        return self.kind if self.pitch_um is None else f"{self.kind} {self.pitch_um:g} µm"

    def layout(self):
        return None if self.kind == "glass" else getattr(layouts, self.kind)(pitch_um=self.pitch_um)


def configs(cfg: dict) -> list[Config]:
    return ([Config("glass", None)] + [Config("toled", p) for p in cfg["toled_pitch_um"]]
            + [Config("poled", p) for p in cfg["poled_pitch_um"]])


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


def min_relative_mtf(obs: dict, glass: dict) -> float:
    """Lowest MTF (x and y) relative to glass below Nyquist (0.5 cycles/px excluded: glass ~ 0 there)."""
    keep = obs["f"] < 0.45
    return float(min((obs[a][keep] / np.maximum(glass[a][keep], 1e-12)).min() for a in ("mtf_x", "mtf_y")))


def rows_for(c: Config, obs: dict, glass: dict) -> list[dict]:
    """The table rows of one configuration, with the paper's value and a verdict where one applies."""
    base = {"display": c.kind, "pitch_um": c.pitch_um}
    rows = [dict(base, observable="transmittance τ (display grid × aperture)", ours=f"{obs['transmittance']:.3f}",
                 paper=PAPER.get(c.kind, {}).get("transmission", ""), verdict="reported (T(λ) not included)")]
    rows += [dict(base, observable=f"share of the transmitted energy within ±{k} px", ours=f"{v:.3f}", paper="",
                  verdict="")
             for k, v in obs["share"].items()]
    if c.kind == "toled":
        band = x_loss_band(obs)
        ours = "none" if band is None else f"{band[0]:.3f}–{band[1]:.3f} cyc/px ({band[0] / 0.5:.0%}–{band[1] / 0.5:.0%} of Nyquist)"
        mid = band is not None and band[0] >= LOW_BAND * 0.5
        rows.append(dict(base, observable=f"x contrast loss (MTF_x/MTF_y < {LOSS_RATIO})", ours=ours,
                         paper=PAPER["toled"]["x_loss"], verdict="mid-band" if mid else "**starts at low frequency**"))
    if c.kind == "poled":
        m = min_relative_mtf(obs, glass)
        rows.append(dict(base, observable="lowest MTF relative to glass", ours=f"{m:.3f}",
                         paper=PAPER["poled"]["min_mtf"], verdict="no null" if m > NULL_LEVEL else "**null**"))
    return rows


def pitch_order_row(cfg: dict) -> dict:
    t, p = min(cfg["toled_pitch_um"]), max(cfg["poled_pitch_um"])
    return {"display": "toled vs poled", "pitch_um": None, "observable": "pitch order (swept ranges)",
            "ours": f"T-OLED ≥ {t:g} µm, P-OLED ≤ {p:g} µm", "paper": "P-OLED finer (l.116)",
            "verdict": "holds for every pair" if t > p else "**fails for some pairs**"}


def plot(observed: dict, path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for c, obs in observed.items():
        lpmm = obs["f"] / (PIXEL_UM * 1e-3)
        axes[0].plot(lpmm, obs["mtf_x"], label=c.label)
        axes[1].plot(lpmm, obs["mtf_y"], label=c.label)
    for ax, axis in zip(axes, "xy"):
        ax.set_xlabel("spatial frequency (lp/mm at the sensor)")
        ax.set_title(f"MTF along {axis} (mean of 450/550/650 nm, d = 0)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("MTF of the kernel window")
    axes[1].legend(fontsize=8)
    save_plot(fig, path)


def run_study(out_dir, quick: bool = False, progress: bool = True) -> list[dict]:
    """Write study_realism.csv, .md and .png into out_dir; returns the rows."""
    from tqdm import tqdm
    cfg, out = (QUICK if quick else FULL), Path(out_dir)
    observed = {c: observe(c, cfg["kernel_px"]) for c in tqdm(configs(cfg), desc="realism", disable=not progress)}
    glass = next(o for c, o in observed.items() if c.kind == "glass")
    rows = [r for c, o in observed.items() if c.kind != "glass" for r in rows_for(c, o, glass)]
    rows.append(pitch_order_row(cfg))
    md = ("# Realism: PSF observables against the paper (first part)\n\n"
          f"{'Quick grid. ' if quick else ''}Kernels {cfg['kernel_px']} px of {PIXEL_UM} µm, d = 0, "
          f"mean of {', '.join(f'{w:g}' for w in WAVELENGTHS_NM)} nm. Verdicts: see udc_render/studies/realism.py.\n\n"
          + "\n".join(md_table(rows, [(k, k.replace("_", " ")) for k in COLUMNS])) + "\n")
    write_tables(out, "study_realism", rows, COLUMNS, md)
    plot(observed, out / "study_realism.png")
    return rows
