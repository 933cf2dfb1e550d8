"""The capture observables of `udc-render study realism` for one display (a preset, or a Display with
any layout, gain, T(λ) and display-to-lens distance): ours beside the paper's, with a verdict per row.
studies.realism calls capture_rows per display and merges the rows into its table (same COLUMNS).

a. γ per RGGB channel by the paper's protocol (l.261): a white square at monitor levels 0, 10, …,
   250 captured through glass and through the display on the virtual rig (calibration.rig: the
   spectral physics — band kernels, T(λ), gain, RGGB sensor, noise — never the paper's γ), the slope
   of the display means against the glass means per channel (calibration.gamma). The default rig
   (1024 × 256 px, 511-px kernels, 10-nm bands) is used in quick runs too: the quick rig's 161-px
   kernels leave 3 % (T-OLED) to 11 % (P-OLED) more light outside their window, and γ counts only
   the light inside (optics.gamma), so its γ reads that much low. Verdict: "within 1 %" of the
   paper's (T-OLED 0.97 × 4; P-OLED 0.34/0.34/0.34/0.20 for R, Gr, Gb, B), else "**off by x %**".
b. Input and DeP PSNR/SSIM under the 'paper' protocol (udc_render.metrics; restore.metrics
   paper_metrics: linear, [0, 1] of the white level, the input on its packed RAW against the ground
   truth's RGGB samples) on fixed built-in images (IMAGES; QUICK_IMAGES) shown on the default monitor
   scene at the paper's 2048 × 1024 framing, spectral form, default sensor. Each image is rendered
   once per process (render cache, shared by every display) and synthesised through the display
   (pipeline.synthesize, kernels from the on-disk cache). DeP (restore.dep) gets what restore.known
   gives it, in memory: the channel kernels at d = 0 at the packed pitch (half the synthesis
   kernel's size) and the γ that made the capture (optics.gamma from the synthesis's band kernels and
   the rendered white). The paper's DeP (Table "Pipeline Comparison", l.380): T-OLED 28.50 dB /
   0.9117, P-OLED 16.97 dB / 0.7084; verdict "at or above the paper (our DeP knows the PSF)" or
   "**below the paper by x**". dep_order_row compares the two displays ("P-OLED harder").
c. Banding at the display's own distance d (Display.distance_mm; 0: "no bands at d = 0"), from the
   analytic transmitted-power series of psf.banding (no captures): P(x) = Σ_k W_Gk T_k P_k(x d / z_i)
   over the scene's bands, weighted to the G channel by the monitor white's G electrons W_Gk and the
   display's T(λ_k), evaluated over the sensor field (x: the sensor position from the axis). The
   bands are taken BAND_GROUP at a time (the middle centre, the group's summed weight): the contrast
   hardly depends on λ (T-OLED 317 µm at d = 1 mm: 1.278 % at 405 nm, 1.266 % at 675 nm; grouping by
   3 changes the weighted contrast by 1e-4 of itself, P-OLED by 1 %) and each wavelength costs
   ~1.7 s for the 317 µm stripe. Reported: the band period along x and y in pixels, z_i p / (d k)
   for the strongest harmonic k of the profile through the centre (k = 1 for a stripe; the P-OLED's
   pentile cell has its strongest at k = 2 or 4), and the Michelson contrast
   C = (max − min) / (max + min) of P over the whole 2D field (over one period cell where the field
   holds more). Noise: the sensor model's (udc_render.sensor expose, the capture's settings and the
   display's gain) relative RMS per pixel in G at mid-grey (monitor code 128, linear 0.216 of white,
   the auto exposure putting white at pipeline.EXPOSURE_FILL of the full well through glass, × the
   display's G-weighted T τ). Visibility V = C / (per-pixel relative noise RMS) — per pixel, not
   averaged over a band (a band spans 10⁴–10⁶ pixels, whose mean would show any C > 0). Verdict
   (VISIBILITY): V < 0.1 "invisible" (the bands' amplitude is under a tenth of one pixel's noise),
   0.1 ≤ V < 0.5 "low", 0.5 ≤ V < 2 "moderate", V ≥ 2 "strong" (the bands stand above the noise).
   The paper: "low to moderate visibility" in its real data (l.498), where d > 0.

Cost (2 cores, kernel caches warm): a render ~11 s per image (once), per display and image a
synthesis ~8 s and DeP ~8 s, γ ~9 s per display, banding at d > 0 ~11 s for the 317 µm stripe, ~1 s
for 60–64 µm cells (0 at d = 0). Measured for the T-OLED and P-OLED presets: quick (1 image) 63 s,
full (3 images) 153 s, in one process each. A cold kernel cache adds, once, ~4 min for the T-OLED's
channel kernels (DeP), ~40 s for its band kernels and ~40 s for the rig's. A display at d > 0 also
needs field-dependent band kernels (16 phases) for its captures and for the rig: many minutes
uncached; banding_row alone needs none.
"""
from __future__ import annotations

import tempfile
import time
from functools import lru_cache
from pathlib import Path

import numpy as np
from tqdm import tqdm

from restore.dep import dep_restore
from restore.metrics import paper_metrics
from udc_render.io.plots import pyplot, save_plot
from udc_render.optics.displays import Display
from udc_render.optics.gamma import display_gamma
from udc_render.scene.geometry import psf_lens
from udc_render.scene.overrides import with_overrides
from udc_render.sensor import rgb_to_rggb
from udc_render.studies.realism_banding import banding_row
from udc_render.studies.realism_paper import (
    PAPER_DEP,
    default_scene,
    dep_verdict,
    display_label,
    display_pitch_um,
    gamma_verdict,
    paper_gamma_rggb,
)

IMAGES = ("builtin:astronaut", "builtin:coffee", "builtin:chelsea")
QUICK_IMAGES = IMAGES[:1]
CHANNELS = ("R", "Gr", "Gb", "B")


@lru_cache(maxsize=len(IMAGES))
def _render(scene):
    """One render per scene (image) per process: every display's synthesis reuses it."""
    from udc_render.render import render_scene
    return render_scene(scene, progress=False)


def clear_render_cache() -> None:
    """Drop the cached renders (~0.5 GB each at 2048 × 1024, 30 bands)."""
    _render.cache_clear()


# ---------------------------------------------------------------------------------------------- a. γ


def measure_gamma(display: Display, quick_rig: bool = False) -> dict:
    """calibration.gamma's white-square protocol on the virtual rig (module doc, a): its result dict
    (gamma [4], truth [4], glass_mean_w / display_mean_w [levels, 4], used, levels, …)."""
    from udc_render.calibration.gamma import calibrate_gamma
    from udc_render.calibration.rig import Rig
    with tempfile.TemporaryDirectory(prefix="udc-realism-gamma-") as tmp:
        return calibrate_gamma(Rig(display, quick_rig, out=Path(tmp)))


def gamma_rows(display: Display, gamma: dict, base: dict) -> list[dict]:
    paper = paper_gamma_rggb(display)
    rows = []
    for c, name in enumerate(CHANNELS):
        g = float(gamma["gamma"][c])
        rows.append(dict(base, observable=f"γ {name} (white-square regression, l.261)", ours=f"{g:.3f}",
                         paper="" if paper is None else f"{paper[c]:.2f}",
                         verdict="" if paper is None else gamma_verdict(g, paper[c]), key=f"gamma_{name}", value=g))
    return rows


# ---------------------------------------------------------------------------------------------- b. PSNR / SSIM


def display_models(display: Display, scene, cfg=None) -> tuple:
    """(the synthesis kernels, DeP's RGGB kernels) of `display` for `scene`'s lens and frame: the same for
    every image the scene shows, so planned once per display (restore.known's DeP kernels: channel
    kernels at the packed pitch, half the synthesis kernel's size)."""
    from restore.known import packed_channel_kernels, rggb_kernels
    from udc_render.pipeline import SynthConfig, plan_kernels
    cfg = cfg or SynthConfig()
    kernels = plan_kernels(scene, [display], cfg)
    size = (kernels.grid.kernel_size_px // 2) | 1  # restore.known's default: the synthesis kernel's field of view
    dep_kernels = rggb_kernels(packed_channel_kernels(display.layout, psf_lens(scene), cfg.sensor.camera,
                                                      float(scene.sensor.pitch_um), size, cfg.use_cache))
    return kernels, dep_kernels


def score_image(display: Display, scene, models: tuple, item: int = 0, cfg=None) -> dict:
    """One image: synthesise the capture through `display` from the (cached) render with `models`
    (display_models), score the input, restore with DeP (known kernels and γ) and score it (paper
    protocol)."""
    from udc_render.pipeline import SynthConfig, synthesize
    cfg = cfg or SynthConfig()
    kernels, dep_kernels = models
    t0 = time.perf_counter()
    band_image = _render(scene)
    t1 = time.perf_counter()
    res = synthesize(band_image, scene, [display], cfg, item=item, kernels=kernels)
    cap = res.captures[display.name]
    s = cap.params["sensor"]
    packed = ((cap.packed_dn.astype(np.float32) - s["black_level_dn"])
              / (s["white_level_dn"] - s["black_level_dn"])).astype(np.float32)
    t2 = time.perf_counter()
    gamma = np.array(rgb_to_rggb(display_gamma(display, kernels.band[display.name], kernels.band["glass"],
                                               band_image.edges_nm, cfg.sensor.camera, band_image.white_bands())))
    dep = dep_restore(packed, gamma, dep_kernels, rng=np.random.default_rng(item))
    t3 = time.perf_counter()
    inp, out = paper_metrics(None, res.gt, packed), paper_metrics(dep.rgb, res.gt)
    return {"input_psnr_db": inp["psnr_db_paper"], "input_ssim": inp["ssim_paper"],
            "dep_psnr_db": out["psnr_db_paper"], "dep_ssim": out["ssim_paper"], "dep_gamma_rggb": gamma,
            "dep_kernel_px": dep_kernels.shape[-1], "seconds": {"render": t1 - t0, "synth": t2 - t1, "dep": t3 - t2,
                                                              "metrics": time.perf_counter() - t3}}


def score_rows(display: Display, scores: list[dict], base: dict) -> list[dict]:
    n = len(scores)
    mean = {k: float(np.mean([s[k] for s in scores])) for k in ("input_psnr_db", "input_ssim", "dep_psnr_db",
                                                                  "dep_ssim")}
    paper = PAPER_DEP.get(display.name)
    of = f"mean of {n} image{'s' if n > 1 else ''}"
    rows = [dict(base, observable=f"input PSNR, paper protocol (packed RAW vs GT; {of})",
                 ours=f"{mean['input_psnr_db']:.2f} dB", paper="", verdict="", key="input_psnr_db",
                 value=mean["input_psnr_db"]),
            dict(base, observable=f"input SSIM, paper protocol ({of})", ours=f"{mean['input_ssim']:.4f}", paper="",
                 verdict="", key="input_ssim", value=mean["input_ssim"]),
            dict(base, observable=f"DeP PSNR, paper protocol (known kernels and γ; {of})",
                 ours=f"{mean['dep_psnr_db']:.2f} dB", paper="" if paper is None else f"{paper[0]:.2f} dB",
                 verdict="" if paper is None else dep_verdict(mean["dep_psnr_db"], paper[0]), key="dep_psnr_db",
                 value=mean["dep_psnr_db"]),
            dict(base, observable=f"DeP SSIM, paper protocol ({of})", ours=f"{mean['dep_ssim']:.4f}",
                 paper="" if paper is None else f"{paper[1]:.4f}",
                 verdict="" if paper is None else dep_verdict(mean["dep_ssim"], paper[1], unit=""), key="dep_ssim",
                 value=mean["dep_ssim"])]
    return rows


# ---------------------------------------------------------------------------------------------- all rows


def capture_rows(display: Display, images: tuple[str, ...] | None = None, quick: bool = False,
                 progress: bool = True, *, label: str | None = None, pitch_um: float | None = None, scene=None,
                 quick_rig: bool = False) -> tuple[list[dict], dict]:
    """The capture rows of one display (module doc: γ per RGGB channel, input and DeP PSNR/SSIM,
    banding) in realism.COLUMNS (display, pitch_um, observable, ours, paper, verdict; plus 'key' and
    the numeric 'value', which the table writers ignore), and the arrays for plot_capture.

    images: builtin:NAME / files (None: QUICK_IMAGES when quick, else IMAGES). label: the display
    column (default: the display's name, with d when d > 0). pitch_um: the pitch_um column (default:
    the layout's period along x; a disordered supercell's is cells × the pitch). scene: the base scene
    (default: the monitor at 2048 × 1024; tests pass a small one). quick_rig: γ on the quick rig
    (biased low, module doc; for tests)."""
    if display.is_glass:
        raise ValueError("capture_rows: the display is glass (γ = 1, nothing to restore): give a display")
    images = tuple(images or (QUICK_IMAGES if quick else IMAGES))
    scene = scene or default_scene()
    base = {"display": label or display_label(display),
            "pitch_um": display_pitch_um(display) if pitch_um is None else pitch_um}
    bar = tqdm(total=len(images) + 2, desc=f"realism capture {base['display']}", unit="step", disable=not progress)
    t0 = time.perf_counter()
    gamma = measure_gamma(display, quick_rig)
    seconds = {"gamma": time.perf_counter() - t0}
    bar.update()
    models = display_models(display, scene)  # the same for every image: once per display
    scores = []
    for i, image in enumerate(images):
        scores.append(score_image(display, with_overrides(scene, image=image), models, item=i))
        bar.update()
    t1 = time.perf_counter()
    band_row, band = banding_row(display, base, scene)
    bar.update()
    bar.close()
    seconds.update({"banding": time.perf_counter() - t1, **{k: sum(s["seconds"][k] for s in scores)
                                                             for k in scores[0]["seconds"]}})
    rows = gamma_rows(display, gamma, base) + score_rows(display, scores, base) + [band_row]
    data = {"label": base["display"], "display": display.name, "distance_mm": display.distance_mm,
            "gamma": gamma, "paper_gamma": paper_gamma_rggb(display), "images": images,
            **{k: np.array([s[k] for s in scores]) for k in ("input_psnr_db", "input_ssim", "dep_psnr_db", "dep_ssim")},
            "dep_gamma_rggb": scores[0]["dep_gamma_rggb"], "dep_kernel_px": scores[0]["dep_kernel_px"],
            "paper_dep": PAPER_DEP.get(display.name), "banding": band,
            "seconds": {k: round(v, 2) for k, v in seconds.items()}}
    return rows, data


def plot_capture(results: list[dict], path: Path, bandings: list[tuple[str, dict]] = ()) -> None:
    """One figure of capture_rows' data dicts: γ regressions, input vs DeP PSNR, banding profiles (of the
    results and of `bandings`, (label, banding() dict) pairs, e.g. a sweep over d)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.4))
    markers = dict(zip(CHANNELS, "o^vs"))
    for j, r in enumerate(results):
        g, colour = r["gamma"], f"C{j % 10}"
        x, y = np.asarray(g["glass_mean_w"]), np.asarray(g["display_mean_w"])
        for c, name in enumerate(CHANNELS):
            axes[0].plot(x[:, c], y[:, c], markers[name], ms=3, color=colour, alpha=0.7,
                         label=f"{r['label']} {name}: γ = {g['gamma'][c]:.3f}")
        if r.get("paper_gamma"):
            xs = np.array([0.0, x.max()])
            for pg in sorted(set(r["paper_gamma"])):
                axes[0].plot(xs, pg * xs, ":", color=colour, lw=0.8)
    axes[0].set(xlabel="glass mean (fraction of white)", ylabel="display mean (fraction of white)",
                title="γ: white-square regression per RGGB channel (dotted: the paper's)")
    labels = [r["label"] for r in results]
    pos = np.arange(len(results))
    axes[1].bar(pos - 0.2, [np.mean(r["input_psnr_db"]) for r in results], 0.4, label="input (packed RAW)")
    axes[1].bar(pos + 0.2, [np.mean(r["dep_psnr_db"]) for r in results], 0.4, label="DeP (known PSF and γ)")
    for p, r in zip(pos, results):
        if r.get("paper_dep"):
            axes[1].plot([p + 0.0, p + 0.4], [r["paper_dep"][0]] * 2, "k-", lw=2)
    axes[1].plot([], [], "k-", lw=2, label="the paper's DeP")
    axes[1].set_xticks(pos, labels, rotation=20, fontsize=7)
    axes[1].set(ylabel="PSNR (dB), paper protocol", title="input and DeP against the ground truth")
    any_bands = False
    for name, b in [(r["label"], r["banding"]) for r in results] + list(bandings):
        if b.get("bands"):
            any_bands = True
            line, = axes[2].plot(b["profile_x_px"], 100 * (np.asarray(b["profile_rel"]) - 1), lw=1,
                                 label=f"{name} d = {b['distance_mm']:g} mm: V = {b['visibility']:.2f} "
                                       f"({b['verdict']})")
            axes[2].axhspan(-100 * b["noise_rel"], 100 * b["noise_rel"], color=line.get_color(), alpha=0.08)
    if not any_bands:
        axes[2].text(0.5, 0.5, "no bands: every display at d = 0", ha="center", transform=axes[2].transAxes)
    axes[2].set(xlabel="sensor x from the axis (px)", ylabel="G transmitted power − mean (%)",
                title="bands through the centre (shaded: ±1σ noise per pixel at mid-grey)")
    for ax in axes:
        ax.title.set_fontsize(9)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    save_plot(fig, path)
