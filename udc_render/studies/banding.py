"""Banding study: the bands a display a distance d in front of the lens prints on a flat field (issue 14).

    udc-render study banding --out DIR [--quick]

Rig: the monitor scene (scenes/monitor.toml) showing ``pattern:white`` with framing ``fill``, on a
reduced sensor (FULL: 1024 × 128 px of 1.55 µm). The rendered panel's centre spectrum is extended over
the whole render grid (the margin included), so the frame's edges see no panel edge: a flat field.
Each display (T-OLED, P-OLED presets, gains 6 and 25) is synthesised at every distance d with the
default SynthConfig (spectral form, blend 'source', 4 field phases per axis, its field rank, Poisson and
read noise, the rig's auto exposure: monitor white at 0.8 of the full well through glass), stray light off
(STUDY_BASE: the P-OLED's default haze, a θ⁻² veil of the finite flat field, would shade the frame more than
its bands, and the fit would lock onto it; the T-OLED has none by default); the phase display's
distance runs again at cfg['ranks'] and with every phase kernel (rank 'all'), on the same kernels.

Measured (green Gr sites of the RGGB mosaic, sample every 2 px along x):

- profile(x) = column mean over the Gr rows of clean_dn(display) / clean_dn(glass) (the noise-free
  mosaic; the glass ratio removes any fall-off), divided by its mean;
- period T and first harmonic: least squares of c0 + Σ_{h≤H} [a_h cos(2πhx/T) + b_h sin(2πhx/T)],
  T refined by a bounded scalar search of the residual around the zero-padded FFT peak (no use of
  the expected period); A1 = √(a1² + b1²) / c0 (relative to the mean). Where the fit finds T/n
  (order n = round(z_i p / d / T) > 1), A1 is harmonic n of the fit at n·T with n·H harmonics;
- σ: the per-pixel noise, std(mosaic_dn − clean_dn) over the Gr sites (DN).

Analytic (psf.banding.PowerSeries, exact for a periodic display): the band period on the sensor is
T = z_i · p / d (z_i the lens' image distance, p the display period along x), and the profile is
Σ_k a_k P_k(s) with the mask shift s = (x, y) · d / z_i, a_k = w_Gk · L_k · T_k (camera weight of band
k in green, the panel's white radiance, the stack's transmission; the kernel window's energy outside
is left out), averaged over the same Gr rows and fitted at the known T, harmonic by harmonic.

Expected (psf.banding, exact × the PSF): each band's harmonics times its kernel's OTF at the band
frequency (banding_fit.kernel_otf; blend 'source' smooths the weighted source with the PSF). The blend
takes its power from the exact series at every pixel's shift (optics.field_power), so measured / expected
should be 1 whatever the phase count; the phases run measures it against P, with the exact series and
with the phases' powers interpolated (power 'interpolated': the same kernels without their field_series,
the blend before the series), which keeps sinc²(h/P) of harmonic h (0.81 for h = 1, P = 4) and aliases
harmonics mP ± h onto it. synthesis_cost times the two at the default phases, and the series at the field
ranks of cfg['ranks'] and 'all'.

Visibility: bands are visible per pixel when A1 · mean ≥ σ (first-harmonic amplitude at least the
per-pixel noise at that level); averaged along the bands over the N Gr rows of the frame the criterion
is A1 · mean ≥ σ / √N. A period longer than the frame is a gradient, not bands (not visible as bands);
one below 4 px (the Nyquist limit of a colour channel sampled every 2 px) is not resolved.

Outputs: study_banding.csv (one row per display, distance, field-phase count and power),
study_banding.md (set-up, table, visible ranges, cost) and study_banding.png (period and amplitude
against d with the analytic curves; measured / expected against P; a flat-field example). ``quick``:
512 × 64 px, 3 bands of 100 nm, the default render margin (396 µm: a smaller kernel window would put a
large share of the light into the unbanded far field), one distance per display and P = 2 (CI smoke run),
the cost from 3 syntheses each (5 in the full run). Kernels are computed with the cache off (a d > 0
set of the full run is 250 MB; nothing is written to disk).
"""
from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from psf.engine import DEFAULT_FIELD_PHASES
from udc_render.optics import displays as D
from udc_render.optics.stray import StrayLight
from udc_render.pipeline import SynthConfig, plan_kernels, synthesize
from udc_render.render import render_scene
from udc_render.scene import Bands, load_scene
from udc_render.scene.geometry import psf_lens
from udc_render.studies.banding_fit import (
    AXES,
    COLUMNS,
    DISPLAYS,
    HARMONICS,
    analytic_harmonics,
    band_series,
    fit_period,
    flat_profile,
    green_band_weights,
    green_sites,
    harmonic_fit,
    interpolated_harmonics,
    kernel_otf,
    noise_sigma_dn,
    period_formula_um,
    sinc2,
    site_positions_um,
)
from udc_render.studies.banding_report import markdown, plot
from udc_render.studies.report import write_tables

FULL = {"sensor": (1024, 128), "step_nm": 20.0, "margin_um": None,
        "distances_mm": {"toled": (0.5, 1.0, 2.0, 4.0, 8.0, 16.0), "poled": (0.5, 1.0, 2.0, 4.0, 8.0, 16.0)},
        "phases": (2, 3, 6), "phase_display": "toled", "phase_distance_mm": 4.0,
        "curve_mm": (0.25, 20.0, 21), "curve_step_nm": 50.0,
        "y_distances_mm": {"toled": (2.0, 4.0, 8.0), "poled": (1.0, 4.0)}, "cost_repeats": 5, "ranks": (2, 3)}
QUICK = {"sensor": (512, 64), "step_nm": 100.0, "margin_um": None,
         "distances_mm": {"toled": (6.0,), "poled": (3.0,)},
         "phases": (2,), "phase_display": "toled", "phase_distance_mm": 6.0,
         "curve_mm": (1.0, 16.0, 5), "curve_step_nm": 100.0, "y_distances_mm": {"toled": (6.0,)}, "cost_repeats": 3,
         "ranks": (2,)}


# ----------------------------------------------------------------------------------------------
# The rig


def flat_field_scene(cfg: dict):
    """The monitor scene showing pattern:white, framing fill, on cfg's sensor, bands and margin."""
    s = load_scene("monitor")
    w, h = cfg["sensor"]
    s = replace(s, sensor=replace(s.sensor, width_px=w, height_px=h), bands=Bands(step_nm=float(cfg["step_nm"])),
                content=replace(s.content, image="pattern:white", framing="fill"))
    return s if cfg["margin_um"] is None else s.with_render(margin_um=float(cfg["margin_um"]))


def flat_band_image(band_image):
    """The render with its centre pixel's spectrum over the whole grid (margin included): a flat field
    whose frame edges see no panel edge (the PSF halo of an edge would mimic a gradient)."""
    K, H, W = band_image.bands.shape
    centre = band_image.bands[:, H // 2, W // 2].astype(np.float32)
    return replace(band_image, bands=np.ascontiguousarray(np.broadcast_to(centre[:, None, None], (K, H, W))))


# ----------------------------------------------------------------------------------------------
# The runs


# The study's synthesis: the default but for the stray light (module doc), kernels with the cache off
STUDY_BASE = SynthConfig(use_cache=False, stray_light=StrayLight.off())


class Rig:
    """The scene, its flat field and the glass capture shared by every run; bands measured along `axis` (y:
    the sensor turned to portrait, cfg's height × width); base: the synthesis (None: STUDY_BASE)."""

    def __init__(self, cfg: dict, axis: str = "x", base: SynthConfig | None = None):
        self.cfg, self.axis, self.a = cfg, axis, AXES.index(axis)
        self.scene = flat_field_scene(cfg if axis == "x" else {**cfg, "sensor": cfg["sensor"][::-1]})
        self.band_image = flat_band_image(render_scene(self.scene, progress=False))
        self.lens = psf_lens(self.scene)
        self.z_i_um = float(self.lens.image_distance_um)  # z_i: the lens focused on the panel (the kernels' own)
        self.pitch_um = float(self.scene.sensor.pitch_um)
        self.base = STUDY_BASE if base is None else base
        self._last = (None, None, 0.0)  # (key, kernels, seconds): Rig.kernels' last set
        glass = D.preset("glass")
        res = synthesize(self.band_image, self.scene, [glass], self.base,
                         kernels=plan_kernels(self.scene, [glass], self.base))
        self.glass_dn = res.captures["glass"].clean_dn
        self.exposure_s = float(res.meta["exposure_s"])
        self.x_um, self.y_um = site_positions_um(self.glass_dn.shape, self.pitch_um)
        self.along_um, self.across_um = (self.x_um, self.y_um)[self.a], (self.x_um, self.y_um)[1 - self.a]

    @property
    def frame_size_um(self) -> tuple[float, float]:
        """(width, height) of the frame (µm): what the kernels' field shifts see (pipeline.display_kernels)."""
        return self.scene.sensor.width_px * self.pitch_um, self.scene.sensor.height_px * self.pitch_um

    @property
    def frame_um(self) -> float:
        """The frame's extent along the bands' axis (µm)."""
        return self.frame_size_um[self.a]

    def kernels(self, display, phases: int | None, power: str = "series"):
        """(kernels, seconds to make them) of `display` with `phases` field phases; the last set is kept for
        the next call. power 'interpolated': the display's kernel set without its field_series, so that the
        blend interpolates the phases' powers (the blend before the exact series)."""
        key = (display.name, display.distance_mm, phases)
        if self._last[0] != key:
            t0 = time.perf_counter()
            self._last = (key, plan_kernels(self.scene, [display], replace(self.base, field_phases=phases)),
                          time.perf_counter() - t0)
        _, kernels, seconds = self._last
        if power == "interpolated":
            kernels = replace(kernels, band={**kernels.band,
                                             display.name: replace(kernels.band[display.name], field_series=None)})
        return kernels, seconds

    def synthesis(self, display, phases: int | None, power: str = "series", rank: str | int = "default"):
        """(capture, kernel seconds, synthesis seconds) of `display` with `phases` field phases, the
        blend's power from the exact series ('series') or the phases' powers ('interpolated'), and field
        rank `rank` ('default': the SynthConfig's; 'all': every phase kernel, SynthConfig.field_rank None)."""
        kernels, kernel_s = self.kernels(display, phases, power)
        cfg = replace(self.base, field_phases=phases)
        if rank != "default":
            cfg = replace(cfg, field_rank=None if rank == "all" else int(rank))
        t0 = time.perf_counter()
        res = synthesize(self.band_image, self.scene, [display], cfg, kernels=kernels)
        return res, kernel_s, time.perf_counter() - t0

    def capture(self, display, phases: int | None, power: str = "series", rank: str | int = "default"):
        """(capture, kernel seconds, synthesis seconds, the display's kernel set)."""
        res, kernel_s, synth_s = self.synthesis(display, phases, power, rank)
        return res.captures[display.name], kernel_s, synth_s, self._last[1].band[display.name]

    def series(self, display, distance_mm: float, step_nm: float | None = None):
        """(P_k(s) series, green weights a_k) on the render's bands, or on bands of step_nm."""
        bi = self.band_image
        if step_nm is not None and step_nm != self.cfg["step_nm"]:
            edges = np.asarray(Bands(step_nm=step_nm).edges_nm)
            white = np.interp((edges[:-1] + edges[1:]) / 2, bi.centres_nm, bi.white_bands())
            bi = replace(bi, edges_nm=edges, primaries_matrix=np.stack([white, 0 * white, 0 * white]))
        weights = green_band_weights(bi, display, self.exposure_s)
        return band_series(display, self.lens, bi.centres_nm, distance_mm), weights

    def analytic(self, display, distance_mm: float, step_nm: float | None = None) -> np.ndarray:
        """Analytic relative harmonics (h = 1…H) of the green flat-field profile (analytic_harmonics)."""
        series, w = self.series(display, distance_mm, step_nm)
        return analytic_harmonics(series, w, display, distance_mm, self.across_um, self.z_i_um, self.axis)


def measure(rig: Rig, name: str, distance_mm: float, phases: int | None, power: str = "series",
            rank: str | int = "default") -> tuple[dict, np.ndarray, np.ndarray]:
    """(one row, the flat-field profile, the clean Gr image): the capture of display `name` at distance_mm,
    its measured bands against the analytic (exact; exact × the kernels' OTF, 'expected'; and with the
    synthesis' phase interpolation alone). power: the blend's power ('series' or 'interpolated', Rig.kernels);
    rank: the field rank (Rig.synthesis)."""
    display = D.preset(name).with_distance(distance_mm)
    cap, kernel_s, synth_s, ks = rig.capture(display, phases, power, rank)
    P = phases or DEFAULT_FIELD_PHASES
    T = period_formula_um(rig.z_i_um, display.layout.period_um[rig.a], distance_mm)
    row = {"axis": rig.axis, "display": name, "distance_mm": distance_mm, "field_phases": P, "field_power": power,
           "field_rank": rig.base.field_rank if rank == "default" else rank,
           "period_formula_um": T, "period_formula_px": T / rig.pitch_um, "periods_in_frame": rig.frame_um / T,
           "kernel_s": round(kernel_s, 2), "synth_s": round(synth_s, 2)}
    series, weights = rig.series(display, distance_mm)
    analytic = analytic_harmonics(series, weights, display, distance_mm, rig.across_um, rig.z_i_um, rig.axis)
    expected = analytic_harmonics(series, weights, display, distance_mm, rig.across_um, rig.z_i_um, rig.axis,
                                  otf=kernel_otf(ks.kernels, ks.pixel_um, T, rig.axis))
    prof = flat_profile(cap.clean_dn, rig.glass_dn, rig.axis)
    mean_dn = float(green_sites(cap.clean_dn).mean())
    sigma = noise_sigma_dn(cap)
    n_rows = rig.across_um.size
    row.update(mean_dn=mean_dn, sigma_dn=sigma, rows_averaged=n_rows, sinc2_interp=sinc2(1, P),
               a1_analytic_rel=float(analytic[0]))
    if T > rig.frame_um or T < 4 * rig.pitch_um:
        row.update(regime="gradient (T > frame)" if T > rig.frame_um else "unresolved (T < 4 px)",
                   visible_pixel=False, visible_averaged=False)
        return row, prof, green_sites(cap.clean_dn)
    period, _ = fit_period(rig.along_um, prof)
    order = max(1, int(round(T / period)))
    # harmonic `order` of the fundamental period · order, every harmonic up to order · H fitted with it (a fit
    # at T/order leaves T's other harmonics out, and on a frame of 2.5 periods they leak into it)
    a1 = float(harmonic_fit(rig.along_um, prof, period * order, HARMONICS * order)[0][order])
    a_ref = float(analytic[order - 1]) if order <= analytic.size else math.nan
    a_exp = float(expected[order - 1]) if order <= expected.size else math.nan
    a_interp = interpolated_harmonics(series, weights, display, distance_mm, rig.x_um, rig.y_um, rig.z_i_um, P,
                                      rig.frame_size_um, order, rig.axis)
    row.update(regime="bands", period_fit_um=period, period_error_rel=period * order / T - 1, harmonic_order=order,
               analytic_order=int(np.argmax(analytic)) + 1, a1_measured_rel=a1, a1_analytic_rel=a_ref,
               a1_expected_rel=a_exp, psf_mtf=a_exp / a_ref if a_ref > 0 else math.nan, a1_interpolated_rel=a_interp,
               ratio_measured_analytic=a1 / a_ref if a_ref > 0 else math.nan,
               ratio_measured_expected=a1 / a_exp if a_exp > 0 else math.nan,
               ratio_measured_interpolated=a1 / a_interp if a_interp > 0 else math.nan,
               sinc2_interp=sinc2(order, P), a1_dn=a1 * mean_dn, snr_pixel=a1 * mean_dn / sigma,
               snr_averaged=a1 * mean_dn * math.sqrt(n_rows) / sigma, visible_pixel=bool(a1 * mean_dn >= sigma),
               visible_averaged=bool(a1 * mean_dn * math.sqrt(n_rows) >= sigma))
    return row, prof, green_sites(cap.clean_dn)


def jobs(cfg: dict) -> list[tuple[str, str, float, int | None, str, str]]:
    """(axis, display, distance mm, field phases, power, field rank) in run order: every distance at the
    default phases (the phase display also at the field ranks cfg['ranks'] and with every phase kernel, rank
    'all', on the same kernels), the phase-count runs (the exact series and the interpolated powers, on the
    same kernels), then the bands along y."""
    name, d = cfg["phase_display"], cfg["phase_distance_mm"]
    out = [("x", n, dd, None, "series", rank) for n in DISPLAYS for dd in cfg["distances_mm"][n]
           for rank in (("default", *cfg["ranks"], "all") if n == name else ("default",))]
    out += [("x", name, d, p, power, "default") for p in (*cfg["phases"], DEFAULT_FIELD_PHASES)
            for power in ("series", "interpolated") if (p, power) != (DEFAULT_FIELD_PHASES, "series")]
    return out + [("y", n, dd, None, "series", "default") for n in DISPLAYS for dd in cfg["y_distances_mm"].get(n, ())]


def analytic_curves(rig: Rig, cfg: dict) -> dict:
    """{display: (distances mm [n], analytic relative harmonics [n, H])} on a log grid (bands of curve_step_nm),
    with the distance where the period z_i p / d equals the frame added (the visible range's exact edge)."""
    lo, hi, n = cfg["curve_mm"]
    out = {}
    for name in DISPLAYS:
        edge_mm = rig.z_i_um * D.preset(name).layout.period_um[0] / rig.frame_um / 1000.0 * (1 + 1e-9)
        ds = np.unique(np.concatenate([np.geomspace(lo, hi, int(n)), [edge_mm] if lo < edge_mm < hi else []]))
        out[name] = (ds, np.array([rig.analytic(D.preset(name), d, cfg["curve_step_nm"]) for d in ds]))
    return out


def visible_range(rows: list[dict], name: str, curve: tuple, rig: Rig) -> dict:
    """Where the bands of `name` are visible per pixel and after averaging along them: the strongest analytic
    harmonic h (period T/h) scaled by the median measured/analytic ratio, against σ / mean measured, with
    the period inside [4 px, frame]. Ranges are (first, last) curve distances that pass, or None."""
    rs = [r for r in rows if r["display"] == name and r["axis"] == "x" and is_default(r)]
    ratios = [r["ratio_measured_analytic"] for r in rs if np.isfinite(r.get("ratio_measured_analytic", math.nan))]
    ratio = float(np.median(ratios)) if ratios else 1.0
    noise_rel = float(np.median([r["sigma_dn"] / r["mean_dn"] for r in rs]))
    ds, harmonics = curve
    a1 = harmonics.max(axis=1)
    order = harmonics.argmax(axis=1) + 1
    T = np.array([period_formula_um(rig.z_i_um, D.preset(name).layout.period_um[0], d) for d in ds]) / order
    fits = (T <= rig.frame_um) & (T >= 4 * rig.pitch_um)
    n_rows = rig.across_um.size

    def span(ok):
        d = ds[ok & fits]
        return (float(d.min()), float(d.max())) if d.size else None
    return {"display": name, "ratio_used": ratio, "noise_rel": noise_rel, "a1_max_rel": float(np.max(a1 * ratio)),
            "pixel": span(a1 * ratio >= noise_rel), "averaged": span(a1 * ratio * math.sqrt(n_rows) >= noise_rel)}


def is_default(row: dict) -> bool:
    """A row at the default synthesis: the default field phases and rank, the power from the exact series."""
    return (row["field_phases"] == DEFAULT_FIELD_PHASES and row["field_power"] == "series"
            and row["field_rank"] == SynthConfig().field_rank)


def synthesis_cost(rig: Rig, cfg: dict) -> dict:
    """Median seconds of cfg['cost_repeats'] syntheses (kernels made beforehand) of the phase display at the
    phase distance, default phases, in turn: the default (exact series, default rank), the interpolated powers,
    and the exact series at each field rank of cfg['ranks'] and 'all' ({'rank_s': {rank: s}})."""
    display = D.preset(cfg["phase_display"]).with_distance(cfg["phase_distance_mm"])
    runs = [("series", "default"), ("interpolated", "default")] + [("series", r) for r in (*cfg["ranks"], "all")]
    seconds = {run: [] for run in runs}
    for _ in range(cfg["cost_repeats"]):
        for (power, rank), times in seconds.items():
            times.append(rig.synthesis(display, DEFAULT_FIELD_PHASES, power, rank)[2])
    med = {run: float(np.median(times)) for run, times in seconds.items()}
    series, interp = med[("series", "default")], med[("interpolated", "default")]
    return {"series_s": series, "interpolated_s": interp, "ratio": series / interp, "repeats": cfg["cost_repeats"],
            "rank_s": {rank: med[("series", rank)] for _, rank in runs[2:]}}


def run_study(out: Path, quick: bool = False, progress: bool = True) -> list[dict]:
    """Run every (display, distance, phases) capture, write study_banding.{csv,md,png} into out, return the rows."""
    cfg = QUICK if quick else FULL
    out = Path(out)
    t0 = time.perf_counter()
    rigs: dict[str, Rig] = {}
    rows, images = [], {}
    for axis, name, d, p, power, rank in tqdm(jobs(cfg), desc="study banding", unit="capture", disable=not progress):
        rig = rigs.get(axis) or rigs.setdefault(axis, Rig(cfg, axis))
        row, prof, img = measure(rig, name, d, p, power, rank)
        rows.append(row)
        if axis == "x" and name == "toled" and p is None and rank == "default":
            images[d] = (prof, img)
    rig = rigs["x"]
    cost = synthesis_cost(rig, cfg)
    example = example_profile(rig, rows, images)
    curves = analytic_curves(rig, cfg)
    ranges = [visible_range(rows, n, curves[n], rig) for n in DISPLAYS]
    out.mkdir(parents=True, exist_ok=True)
    write_tables(out, "study_banding", rows, COLUMNS,
                 markdown(rows, ranges, rig, cfg, cost, time.perf_counter() - t0))
    plot(rows, curves, rig, example, out / "study_banding.png")
    return rows


def example_profile(rig: Rig, rows: list[dict], images: dict):
    """(display, d, x µm, profile, clean Gr image) of the T-OLED run (bands along x) nearest to 3 periods
    in the frame; images: {d: (profile, clean Gr image)} of those runs."""
    rs = [r for r in rows if r["display"] == "toled" and is_default(r) and r["regime"] == "bands" and r["axis"] == "x"]
    if not rs:
        return None
    pick = min(rs, key=lambda r: abs(r["periods_in_frame"] - 3))
    prof, img = images[pick["distance_mm"]]
    return "toled", pick["distance_mm"], rig.x_um, prof, img
