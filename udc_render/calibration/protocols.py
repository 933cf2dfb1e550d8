"""`udc-render calibrate`: the paper's calibration protocols run on the virtual rig (docs/PHYSICS.md §2).

    udc-render calibrate --display {toled,poled,PATH} [--out DIR] [--quick] [--noise-model M]

The monitor scene (scenes/monitor.toml) is rendered with a reduced sensor and framing 'fill' (the
panel spans the frame's width and overhangs it in height, into the render margin), through glass and
through the display (spectral form: band kernels, T(λ), gain, RGGB sensor), and each protocol
recovers a quantity and compares it with the configured truth:

- γ (per RGGB channel): a white square at code levels 0, 10, …, 250; the mean of a central region
  with the display against the mean through glass, slope of a least-squares line. The rgb_matrix
  render is linear in the drive levels, so one render of the square at full drive is scaled by the
  decoded level (exact); every level gets its own noisy capture. Honest measurement: the square is
  as tall as the panel and the region's side is at most square − (kernel size − 1), so every region
  pixel collects the whole kernel window (light the PSF sends beyond its window is lost, as in the
  truth). Truth: displays.channel_gamma with the kernels' transmittance · (1 − energy outside).
- noise (per channel, display capture): a random pattern of 16 × 9 grey blocks (sRGB code values
  uniform in 0..255), captured `noise_frames` times at exposures geometrically spaced from
  NOISE_SPAN · E_max to E_max (linear scaling of the irradiance; the short exposures give the dark
  pixels that pin λ_read), E_max putting the dimmest channel's brightest
  pixel at NOISE_FILL of white (brighter channels then clip in the upper frames and those pixels are
  left out). Residual noisy − clean in normalised units w = (DN − black)/(white − black), variance
  in quantile bins of the clean w (a censored-Gaussian maximum-likelihood variance: with a black
  level of 0 the noise of dark pixels is clipped), weighted least-squares line var = λ_read +
  λ_shot · w; pixels within CLIP_SIGMAS σ of the black or white clip are left out. λ do not depend on the exposure. Truth: sensor_lambdas at the display's gain
  (photon model; quantisation excluded) or the λ the Gaussian model drew.
- PSF: a virtual collimated 650 nm laser, a delta at the frame centre in one 645–655 nm band (kernel
  at 650 nm), exposure set by a noise-free preview (peak at 0.8 of white), LASER_FRAMES frames
  averaged. Compared on the R sites (3.1 µm lattice; the delta sits on an R site) with the
  configured kernel: normalised cross-correlation (Pearson) and the positions and relative powers
  of the strongest diffraction orders (local maxima of the configured kernel).
- MTF: pattern:sine_x / sine_y at frequencies f (cycles per 1.55 µm sensor pixel); per channel a
  least-squares fit of offset + cos + sin at the known f to the region's profile; modulation
  m = amplitude / offset (the displayed Michelson contrast is 1), display relative to glass.
  Region: the frame, shrunk in x to stay one kernel half-width inside the panel's edges.

Exit status: 0 when every check passes, 1 when any check misses its tolerance (printed as FAIL;
for CI-like use), 2 for bad arguments.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from udc_render.pipeline import SynthError

GAMMA_LEVELS = tuple(range(0, 256, 10))
GAMMA_TOL, NOISE_TOL = 0.02, 0.10
PSF_NCC_MIN = 0.95  # recovered vs configured PSF (noise-limited: faint halo pixels at gain 25)
LASER_NM, LASER_HALF_BAND_NM, LASER_FRAMES, LASER_FILL = 650.0, 5.0, 16, 0.8
NOISE_BINS = 40
NOISE_FILL, NOISE_SPAN = 0.9, 1e-3  # exposure series: brightest frame, and shortest / longest exposure
CLIP_SIGMAS = 0.25  # noise bins this many σ clear of the black and white clips (censored fit below)
TOLED_DIP_BAND = (0.008, 0.03)  # cycles/px where the stripe layout's x-MTF has near-nulls
TOLED_DIP_RATIO = 0.5  # MTF_x / MTF_y must fall below this somewhere in the band
POLED_MIN_MTF = 0.05  # P-OLED relative MTF stays above this (no true nulls; its pentile dip near 0.0075 cyc/px reaches ~0.1, the T-OLED ~3e-4)


@dataclass(frozen=True)
class RigSpec:
    """Reduced virtual rig: sensor frame (px at 1.55 µm), render margin (sets the kernel size
    2·margin + 1), bands, samples per pixel (γ and noise renders; sine renders), γ region, noise
    captures pooled (the paper repeats the noise capture), MTF frequencies (cycles/px)."""
    width_px: int
    height_px: int
    margin_um: float
    bands_nm: str
    spp: int
    pattern_spp: int
    region_px: int
    noise_frames: int
    frequencies: tuple


RIGS = {
    "default": RigSpec(1024, 256, 396.0, "400:700:10", 16, 4, 64, 8,
                       (0.005, 0.0075, 0.01, 0.0125, 0.015, 0.02, 0.025, 0.035, 0.05, 0.08, 0.13, 0.22)),
    "quick": RigSpec(512, 128, 124.0, "400:700:20", 4, 4, 64, 16, (0.01, 0.02, 0.04, 0.12)),
}


class Rig:
    """The scene, the display and glass, the synthesis settings and the kernels of both views
    (planned from the scene at construction); the sensors are set by the first render (their
    exposure follows the rendered white)."""

    def __init__(self, display, quick: bool = False, cfg=None, out: Path | None = None):
        from udc_render.optics.displays import load_display
        from udc_render.scene import load_scene, parse_bands
        from udc_render.pipeline import SynthConfig, plan_kernels
        self.spec = RIGS["quick" if quick else "default"]
        self.display, self.glass = display, load_display("glass")
        self.cfg = cfg or SynthConfig()
        self.out = out
        s = load_scene("monitor")
        self.scene = replace(s, sensor=replace(s.sensor, width_px=self.spec.width_px, height_px=self.spec.height_px,
                                               pitch_um=1.55),
                             content=replace(s.content, framing="fill"),
                             bands=parse_bands(self.spec.bands_nm)).with_render(margin_um=self.spec.margin_um,
                                                                                spp=self.spec.spp, noise=None)
        t0 = time.perf_counter()
        self.kernels = plan_kernels(self.scene, [self.glass, self.display], self.cfg).band
        self.seconds = {"kernels": time.perf_counter() - t0}
        self.sensors = None

    def render(self, image: str, spp: int | None = None):
        """BandImage of the monitor showing `image` (rgb_matrix path); sets up kernels and sensors once."""
        from udc_render.render import render_scene
        from udc_render.pipeline import auto_exposure_s, sensor_for_scene
        scene = replace(self.scene, content=replace(self.scene.content, image=image))
        if spp is not None:
            scene = scene.with_render(spp=spp)
        t0 = time.perf_counter()
        b = render_scene(scene, progress=False)
        self.seconds["render"] = self.seconds.get("render", 0.0) + time.perf_counter() - t0
        if self.sensors is None:
            self.template = b
            optics_sensor = sensor_for_scene(self.cfg.sensor, self.scene)
            exposure = self.cfg.exposure_s or auto_exposure_s(b, optics_sensor)[0]
            base = replace(optics_sensor, exposure_s=float(exposure), form="spectral")
            self.sensors = {d.name: replace(base, gain=d.gain) for d in (self.glass, self.display)}
        return b

    def optics(self, band_image, d) -> np.ndarray:
        """Irradiance bands [K, H, W] on the sensor frame behind `d`."""
        from udc_render.optics import apply_kernels
        t0 = time.perf_counter()
        t = d.transmission.band_means(band_image.edges_nm)
        img = apply_kernels(band_image, self.kernels[d.name], t, self.cfg.precision).images
        self.seconds["optics"] = self.seconds.get("optics", 0.0) + time.perf_counter() - t0
        return img

    def capture(self, images, band_image, d, stream: int):
        from udc_render.sensor import capture
        rng = np.random.default_rng([self.cfg.seed, stream])
        return capture(images, band_image.edges_nm, self.sensors[d.name], rng)

    def monitor_px(self) -> tuple[float, float]:
        """The panel's width and height on the sensor in pixels (thin lens, magnification v/u)."""
        from udc_render.scene.geometry import camera_geometry
        g = camera_geometry(self.scene)
        m = g.image_distance_um / (g.focus_distance_m * 1e6)
        w_m, h_m = self.scene.content.size_m
        return w_m * 1e6 * m / g.pitch_um, h_m * 1e6 * m / g.pitch_um

    def half_kernel(self) -> int:
        return self.kernels[self.glass.name].kernels.shape[-1] // 2

    def pattern_file(self, name: str, code: np.ndarray) -> str:
        """Write an 8-bit RGB PNG (code values [rows, cols]) into out/patterns and return its path."""
        import imageio.v3 as iio
        folder = self.out / "patterns"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / name
        from udc_render.io.files import atomic_path
        with atomic_path(path, ".png") as tmp:
            iio.imwrite(tmp, np.repeat(code.astype(np.uint8)[..., None], 3, -1), extension=".png")
        return str(path.resolve())


def _check(name, recovered, truth, tol) -> dict:
    err = abs(recovered - truth) / abs(truth)
    return {"quantity": name, "recovered": float(recovered), "truth": float(truth), "error": float(err),
            "tolerance": tol, "pass": bool(err <= tol)}


# ---------------------------------------------------------------- γ


def true_gamma(rig: Rig, band_image) -> np.ndarray:
    """Analytic γ (R, Gr, Gb, B) of the display relative to glass for the monitor's white (flat field)."""
    from udc_render.optics.displays import channel_gamma
    from udc_render.sensor import band_electron_weights
    w = band_electron_weights(band_image.edges_nm, replace(rig.sensors[rig.glass.name], exposure_s=1.0))
    w = w * band_image.white_bands()[None, :]
    kd, kg = rig.kernels[rig.display.name], rig.kernels[rig.glass.name]
    g = channel_gamma(w, rig.display, kd.transmittance * (1 - kd.energy_outside),
                      kg.transmittance * (1 - kg.energy_outside), band_image.edges_nm)
    return np.array([g[0], g[1], g[1], g[2]])


def calibrate_gamma(rig: Rig) -> dict:
    """γ per RGGB channel from the white-square protocol (module doc)."""
    from udc_render.content.monitor_image import decode
    from udc_render.sensor import pack_rggb
    code = np.zeros((270, 480))
    code[:, 105:375] = 255  # 270 × 270: a square as tall as the panel
    b = rig.render(rig.pattern_file("gamma_square.png", code))
    w_mon, h_mon = rig.monitor_px()
    side = min(w_mon, h_mon)
    # a multiple of 4: the region starts on an R site (even row and column)
    region = int(min(rig.spec.region_px, side - 2 * rig.half_kernel() - 2, rig.spec.height_px)) // 4 * 4
    if region < 8:
        raise SynthError(f"calibration rig: a {side:.0f}-px square leaves no {2 * rig.half_kernel() + 1}-px kernel room")
    H, W = rig.spec.height_px, rig.spec.width_px
    rows = slice(H // 2 - region // 2, H // 2 + region // 2)
    cols = slice(W // 2 - region // 2, W // 2 + region // 2)
    views = {d.name: rig.optics(b, d) for d in (rig.glass, rig.display)}
    means = {name: [] for name in views}
    clipped = np.zeros((len(GAMMA_LEVELS), 4), bool)
    for i, level in enumerate(GAMMA_LEVELS):
        drive = float(decode(np.array(level / 255.0), rig.scene.content.transfer))
        for j, d in enumerate((rig.glass, rig.display)):
            cap = rig.capture(views[d.name] * np.float32(drive), b, d, 1000 + 2 * i + j)
            s = rig.sensors[d.name]
            raw = pack_rggb(cap.mosaic_dn[rows, cols]).reshape(4, -1)
            clipped[i] |= ((raw <= s.black_level_dn) | (raw >= s.white_level_dn)).any(axis=1)
            means[d.name].append((raw.mean(axis=1) - s.black_level_dn) / s.range_dn)
    x, y = np.array(means[rig.glass.name]), np.array(means[rig.display.name])  # [levels, 4]
    used = ~clipped
    slope = np.array([np.polyfit(x[used[:, c], c], y[used[:, c], c], 1)[0] for c in range(4)])
    truth = true_gamma(rig, b)
    return {"levels": list(GAMMA_LEVELS), "region_px": region, "square_px": side,
            "kernel_px": 2 * rig.half_kernel() + 1, "glass_mean_w": x, "display_mean_w": y, "used": used,
            "gamma": slope, "truth": truth,
            "checks": [_check(f"gamma {c}", slope[k], truth[k], GAMMA_TOL) for k, c in enumerate(_CH)]}


_CH = ("R", "Gr", "Gb", "B")


# ---------------------------------------------------------------- noise


def censored_variance(r: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """Maximum-likelihood variance of zero-mean Gaussian residuals r, where r ≤ low (a pixel read at
    the black clip) or r ≥ high (at the white clip) is only known to lie beyond the clip (Tobit)."""
    from scipy.optimize import minimize_scalar
    from scipy.special import log_ndtr
    lo, hi = r <= low, r >= high
    mid = r[~lo & ~hi]

    def nll(log_s):
        sd = math.exp(log_s)
        return (mid.size * log_s + float(np.sum(mid ** 2)) / (2 * sd * sd)
                - float(np.sum(log_ndtr(low[lo] / sd))) - float(np.sum(log_ndtr(-high[hi] / sd))))
    s0 = math.log(max(float(np.std(r)), 1e-12))
    return math.exp(2 * minimize_scalar(nll, bounds=(s0 - 3, s0 + 3), method="bounded").x)


def noise_fit(w: np.ndarray, resid: np.ndarray, bins: int = NOISE_BINS) -> dict:
    """var = λ_read + λ_shot · w from residuals `resid` = noisy − clean at clean intensities `w`
    (normalised units; the clips at w + r = 0 and 1 are treated as censoring, censored_variance).

    Pixels whose clean w lies within CLIP_SIGMAS σ of the black (0) or white (1) clip are left out,
    with σ(w) from 200 fine quantile bins; the rest go into `bins` quantile bins, and a weighted
    least-squares line is fitted to the bin variances (weights n_b / var_b², var_b from the
    previous line; first pass unweighted)."""
    def binned(sel, n):
        groups = np.array_split(sel[np.argsort(w[sel])], n)
        return (np.array([w[g].mean() for g in groups]),
                np.array([censored_variance(resid[g], -w[g], 1 - w[g]) for g in groups]),
                np.array([g.size for g in groups]))
    wf, vf, _ = binned(np.arange(w.size), 200)
    ok = (wf > CLIP_SIGMAS * np.sqrt(vf)) & (wf + CLIP_SIGMAS * np.sqrt(vf) < 1)
    if ok.sum() < 3:
        raise SynthError("noise calibration: fewer than 3 intensity bins clear of the black and white clips")
    sel = np.nonzero((w >= wf[ok].min()) & (w <= wf[ok].max()))[0]
    wb, vb, nb = binned(sel, bins)
    A = np.stack([np.ones_like(wb), wb], 1)
    coef = np.linalg.lstsq(A, vb, rcond=None)[0]
    for _ in range(2):
        sw = np.sqrt(nb) / np.maximum(A @ coef, 1e-30)
        coef = np.linalg.lstsq(A * sw[:, None], vb * sw, rcond=None)[0]
    return {"w": wb, "var": vb, "w_range": [float(wf[ok].min()), float(wf[ok].max())],
            "lambda_read": float(coef[0]), "lambda_shot": float(coef[1])}


def calibrate_noise(rig: Rig) -> dict:
    """(λ_read, λ_shot) per RGGB channel of the display capture (module doc)."""
    from udc_render.sensor import pack_rggb, sensor_lambdas
    if rig.cfg.sensor.noise == "none":
        return {"skipped": "noise model 'none': no noise to calibrate", "checks": []}
    rng = np.random.default_rng([rig.cfg.seed, 7])
    code = np.kron(rng.integers(0, 256, (9, 16)), np.ones((30, 30)))
    b = rig.render(rig.pattern_file("noise_blocks.png", code))
    s = rig.sensors[rig.display.name]
    img = rig.optics(b, rig.display)
    preview = pack_rggb(rig.capture(img, b, rig.display, 1999).clean_dn - s.black_level_dn).reshape(4, -1).max(axis=1)
    top = NOISE_FILL * s.range_dn / preview.min()  # exposure scale: the dimmest channel's brightest pixel at NOISE_FILL
    w, r = [], []
    for i, scale in enumerate(np.geomspace(NOISE_SPAN * top, top, rig.spec.noise_frames)):
        cap = rig.capture(img * np.float32(scale), b, rig.display, 2000 + i)
        w.append(pack_rggb((cap.clean_dn.astype(np.float64) - s.black_level_dn) / s.range_dn).reshape(4, -1))
        r.append(pack_rggb((cap.mosaic_dn.astype(np.float64) - cap.clean_dn) / s.range_dn).reshape(4, -1))
    w, r = np.concatenate(w, 1), np.concatenate(r, 1)
    fits = [noise_fit(w[c], r[c]) for c in range(4)]
    if s.noise == "poisson":
        lr, ls = sensor_lambdas(s)
        truth_r, truth_s, how = [lr] * 4, [ls] * 4, f"sensor_lambdas at gain {s.gain:g} (photon model)"
    else:
        truth_r, truth_s = cap.params["lambda_read"], cap.params["lambda_shot"]
        how = f"the Gaussian model's λ ({s.lambda_source})"
    checks = [_check(f"lambda_read {c}", f["lambda_read"], truth_r[k], NOISE_TOL) for k, (c, f) in enumerate(zip(_CH, fits))]
    checks += [_check(f"lambda_shot {c}", f["lambda_shot"], truth_s[k], NOISE_TOL) for k, (c, f) in enumerate(zip(_CH, fits))]
    return {"model": s.noise, "gain": s.gain, "frames": rig.spec.noise_frames, "exposure_scale_max": float(top), "truth_from": how, "fits": fits, "truth_read": truth_r,
            "truth_shot": truth_s, "checks": checks}


# ---------------------------------------------------------------- PSF


def calibrate_psf(rig: Rig) -> dict:
    """The display's PSF at LASER_NM from a virtual collimated laser (module doc)."""
    from scipy.ndimage import maximum_filter
    from udc_render.render import BandImage
    from udc_render.optics import apply_kernels
    from udc_render.pipeline import display_kernels
    from udc_render.scene.geometry import RenderGrid
    if rig.sensors is None:
        rig.render("pattern:white", spp=1)
    template = rig.template
    H, W, m = rig.spec.height_px, rig.spec.width_px, template.margin_px
    bands = np.zeros((1, H + 2 * m, W + 2 * m), np.float32)
    bands[0, m + H // 2, m + W // 2] = 1.0
    laser = BandImage(bands, np.array([LASER_NM - LASER_HALF_BAND_NM, LASER_NM + LASER_HALF_BAND_NM]),
                      template.pitch_um, m, None, {})
    d = rig.display
    ks = display_kernels(d, rig.scene, RenderGrid(laser.pitch_um, m, tuple(laser.edges_nm)), rig.cfg)
    img = apply_kernels(laser, ks, d.transmission.band_means(laser.edges_nm), rig.cfg.precision).images
    s = rig.sensors[d.name]
    preview = rig.capture(img, laser, d, 3000).electrons.max() * s.dn_per_electron
    img = img * np.float32(LASER_FILL * s.range_dn / preview)
    frames = np.mean([rig.capture(img, laser, d, 3001 + i).mosaic_dn.astype(np.float64) - s.black_level_dn
                      for i in range(LASER_FRAMES)], axis=0)
    r_plane = frames[0::2, 0::2]  # the delta at (H/2, W/2), both even: an R site
    c, half = ks.kernels.shape[-1] // 2, ks.kernels.shape[-1] // 2
    hy, hx = min(H // 4 - 1, half // 2), min(W // 4 - 1, half // 2)
    rec = r_plane[H // 4 - hy:H // 4 + hy + 1, W // 4 - hx:W // 4 + hx + 1]
    conf = ks.kernels[0][c - 2 * hy:c + 2 * hy + 1:2, c - 2 * hx:c + 2 * hx + 1:2].astype(np.float64)
    rec, conf = rec / rec.sum(), conf / conf.sum()
    ncc = float(np.corrcoef(rec.ravel(), conf.ravel())[0, 1])
    peaks = np.argwhere((conf == maximum_filter(conf, size=5)) & (conf > 1e-3 * conf.max()))
    peaks = peaks[np.argsort(conf[tuple(peaks.T)])[::-1][:9]]
    orders = []
    for py, px in peaks:
        y0, x0 = max(py - 2, 0), max(px - 2, 0)
        win = rec[y0:py + 3, x0:px + 3]
        ry, rx = np.unravel_index(np.argmax(win), win.shape)
        orders.append({"configured_um": [float((px - hx) * 2 * s.pitch_um), float((py - hy) * 2 * s.pitch_um)],
                       "recovered_um": [float((x0 + rx - hx) * 2 * s.pitch_um), float((y0 + ry - hy) * 2 * s.pitch_um)],
                       "configured_power": float(conf[py, px] / conf.max()),
                       "recovered_power": float(rec[y0 + ry, x0 + rx] / rec.max())})
    shift = max(math.hypot(o["recovered_um"][0] - o["configured_um"][0], o["recovered_um"][1] - o["configured_um"][1])
                for o in orders)
    check = {"quantity": f"PSF {LASER_NM:g} nm NCC", "recovered": ncc, "truth": 1.0, "error": 1 - ncc,
             "tolerance": 1 - PSF_NCC_MIN, "pass": bool(ncc >= PSF_NCC_MIN)}
    check_pos = {"quantity": "PSF order shift (um)", "recovered": shift, "truth": 0.0, "error": shift,
                 "tolerance": 2 * s.pitch_um, "pass": bool(shift <= 2 * s.pitch_um)}
    return {"wavelength_nm": LASER_NM, "band_nm": laser.edges_nm, "frames": LASER_FRAMES, "sites": "R (3.1 um lattice)",
            "ncc": ncc, "orders": orders, "max_order_shift_um": shift, "recovered": rec, "configured": conf,
            "window_um": [float((2 * hx + 1) * 2 * s.pitch_um), float((2 * hy + 1) * 2 * s.pitch_um)],
            "checks": [check, check_pos]}


# ---------------------------------------------------------------- MTF


def modulation(profile: np.ndarray, x: np.ndarray, f: float) -> float:
    """amplitude / offset of the least-squares fit offset + a cos(2π f x) + b sin(2π f x)."""
    A = np.stack([np.ones_like(x), np.cos(2 * np.pi * f * x), np.sin(2 * np.pi * f * x)], 1)
    c = np.linalg.lstsq(A, profile, rcond=None)[0]
    return float(math.hypot(c[1], c[2]) / c[0])


def calibrate_mtf(rig: Rig) -> dict:
    """Modulation of glass and display captures of sine gratings along x and y (module doc)."""
    W = rig.spec.width_px
    w_mon, h_mon = rig.monitor_px()
    out = {"frequencies": list(rig.spec.frequencies), "unit": "cycles per sensor pixel (1.55 um)"}
    for axis, extent in (("x", w_mon), ("y", h_mon)):
        res = {"glass": [], "display": []}
        for i, f in enumerate(rig.spec.frequencies):
            b = rig.render(f"pattern:sine_{axis}:{f * extent:.6g}", spp=rig.spec.pattern_spp)
            half = rig.half_kernel()
            cx = max(int(min(W / 2, w_mon / 2 - half - 2)), 8) // 2 * 2  # even: column 0 is an R/Gb site
            cols = slice(W // 2 - cx, W // 2 + cx)
            for j, (key, d) in enumerate((("glass", rig.glass), ("display", rig.display))):
                cap = rig.capture(rig.optics(b, d), b, d, 4000 + 100 * (axis == "y") + 2 * i + j)
                s = rig.sensors[d.name]
                img = (cap.mosaic_dn[:, cols].astype(np.float64) - s.black_level_dn) / s.range_dn
                per_ch = []
                for (oy, ox) in ((0, 0), (0, 1), (1, 0), (1, 1)):
                    plane = img[oy::2, ox::2]
                    if axis == "x":
                        prof, pos = plane.mean(axis=0), np.arange(plane.shape[1]) * 2 + ox
                    else:
                        prof, pos = plane.mean(axis=1), np.arange(plane.shape[0]) * 2 + oy
                    per_ch.append(modulation(prof, pos.astype(np.float64), f))
                res[key].append(per_ch)
        g, dsp = np.array(res["glass"]), np.array(res["display"])  # [F, 4]
        out[axis] = {"glass": g, "display": dsp, "relative": dsp / g,
                     "relative_G": (dsp[:, 1] + dsp[:, 2]) / (g[:, 1] + g[:, 2])}
    out["checks"] = mtf_checks(rig.display, out)
    return out


def mtf_checks(display, mtf: dict) -> list:
    """The expected physics of the presets (docs/PHYSICS.md §2): T-OLED near-nulls along x, P-OLED none."""
    f = np.array(mtf["frequencies"])
    if display.name == "toled" and display.source == "preset":
        band = (f >= TOLED_DIP_BAND[0]) & (f <= TOLED_DIP_BAND[1])
        ratio = float(np.min(mtf["x"]["relative_G"][band] / mtf["y"]["relative_G"][band]))
        return [{"quantity": f"T-OLED min MTF_x/MTF_y, {TOLED_DIP_BAND[0]:g}-{TOLED_DIP_BAND[1]:g} cyc/px",
                 "recovered": ratio, "truth": None, "error": None, "tolerance": f"< {TOLED_DIP_RATIO:g}",
                 "pass": bool(ratio < TOLED_DIP_RATIO)}]
    if display.name == "poled" and display.source == "preset":
        low = float(min(mtf["x"]["relative_G"].min(), mtf["y"]["relative_G"].min()))
        return [{"quantity": "P-OLED min relative MTF (x, y)", "recovered": low, "truth": None, "error": None,
                 "tolerance": f"> {POLED_MIN_MTF:g}", "pass": bool(low > POLED_MIN_MTF)}]
    return []


# ---------------------------------------------------------------- plots


def plot_all(result: dict, out: Path) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from udc_render.io.files import save_figure
    written = []
    g = result["gamma"]
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.8))
    for k, ax in enumerate(axes):
        x, y = np.asarray(g["glass_mean_w"])[:, k], np.asarray(g["display_mean_w"])[:, k]
        used = np.asarray(g["used"])[:, k]
        ax.plot(x[used], y[used], "o", ms=3, label="levels used")
        ax.plot(x[~used], y[~used], "x", ms=4, label="levels touching a clip")
        ax.plot(x, g["gamma"][k] * x, "-", label=f"fit γ = {g['gamma'][k]:.4f}")
        ax.plot(x, g["truth"][k] * x, "--", label=f"truth {g['truth'][k]:.4f}")
        ax.set(title=f"γ {_CH[k]}", xlabel="glass mean (w)", ylabel="display mean (w)")
        ax.legend(fontsize=7)
    save_figure(fig, out / "gamma.png")
    plt.close(fig)
    written.append("gamma.png")
    n = result["noise"]
    if "fits" in n:
        fig, axes = plt.subplots(1, 4, figsize=(16, 3.8))
        for k, (ax, f) in enumerate(zip(axes, n["fits"])):
            w, v = np.asarray(f["w"]), np.asarray(f["var"])
            ax.plot(w, v, "o", ms=3, label="bins (clear of the clips)")
            ax.plot(w, f["lambda_read"] + f["lambda_shot"] * w, "-", label="fit")
            ax.plot(w, n["truth_read"][k] + n["truth_shot"][k] * w, "--", label="truth")
            ax.set(title=f"noise {_CH[k]}", xlabel="intensity w", ylabel="variance (w²)")
            ax.legend(fontsize=7)
        save_figure(fig, out / "noise.png")
        plt.close(fig)
        written.append("noise.png")
    p = result["psf"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    wx, wy = p["window_um"]
    ext = (-wx / 2, wx / 2, wy / 2, -wy / 2)
    for ax, key in zip(axes[:2], ("recovered", "configured")):
        a = np.asarray(p[key])
        im = ax.imshow(np.log10(np.maximum(a / a.max(), 1e-5)), extent=ext, cmap="magma", vmin=-5, vmax=0)
        ax.set(title=f"{key} PSF, {p['wavelength_nm']:g} nm (log10)", xlabel="x (µm)", ylabel="y (µm)")
    fig.colorbar(im, ax=axes[1], fraction=0.046)
    rec, conf = np.asarray(p["recovered"]), np.asarray(p["configured"])
    xs = np.linspace(-wx / 2, wx / 2, rec.shape[1])
    axes[2].semilogy(xs, np.maximum(rec[rec.shape[0] // 2], 1e-9), label="recovered")
    axes[2].semilogy(xs, np.maximum(conf[conf.shape[0] // 2], 1e-9), "--", label="configured")
    axes[2].set(title=f"central row, NCC {p['ncc']:.4f}", xlabel="x (µm)")
    axes[2].legend()
    save_figure(fig, out / "psf.png")
    plt.close(fig)
    m = result["mtf"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for ax, axis in zip(axes, ("x", "y")):
        f, r = np.asarray(m["frequencies"]), m[axis]
        ax.plot(f, np.asarray(r["glass"])[:, 1:3].mean(1), "o-", label="glass (G)")
        ax.plot(f, np.asarray(r["display"])[:, 1:3].mean(1), "s-", label=f"{result['display']} (G)")
        ax.plot(f, r["relative_G"], "^--", label=f"{result['display']} / glass (G)")
        ax.set(title=f"MTF along {axis}", xlabel="cycles / pixel (1.55 µm)", ylabel="modulation", xscale="log",
               ylim=(0, 1.05))
        ax.legend(fontsize=8)
    written += ["psf.png", "mtf.png"]
    save_figure(fig, out / "mtf.png")
    plt.close(fig)
    return written


# ---------------------------------------------------------------- driver and CLI


def calibrate(display, out: Path, quick: bool = False, cfg=None) -> dict:
    """Every protocol for `display` (a displays.Display at d = 0); returns the results (arrays as numpy)."""
    t0 = time.perf_counter()
    rig = Rig(display, quick, cfg, out)
    gamma = calibrate_gamma(rig)
    noise = calibrate_noise(rig)
    psf = calibrate_psf(rig)
    mtf = calibrate_mtf(rig)
    spec = rig.spec
    return {"display": display.name, "display_description": display.describe(), "mode": "quick" if quick else "default",
            "rig": {"sensor_px": [spec.width_px, spec.height_px], "pitch_um": 1.55, "framing": "fill",
                    "margin_um": spec.margin_um, "kernel_px": 2 * rig.half_kernel() + 1, "bands_nm": spec.bands_nm,
                    "spp": spec.spp, "pattern_spp": spec.pattern_spp, "monitor_px": list(rig.monitor_px()),
                    "exposure_s": rig.sensors[display.name].exposure_s, "gain": display.gain,
                    "noise": rig.sensors[display.name].noise, "form": "spectral"},
            "gamma": gamma, "noise": noise, "psf": psf, "mtf": mtf,
            "checks": gamma["checks"] + noise["checks"] + psf["checks"] + mtf["checks"],
            "seconds": {**{k: round(v, 1) for k, v in rig.seconds.items()},
                        "total": round(time.perf_counter() - t0, 1)}}


def format_table(checks: list) -> str:
    lines = [f"{'quantity':<34} {'recovered':>11} {'truth':>11} {'error':>8} {'tolerance':>9}  result"]
    for c in checks:
        truth = "" if c["truth"] is None else f"{c['truth']:.4g}"
        err = "" if c["error"] is None else f"{c['error']:.2%}"
        tol = c["tolerance"] if isinstance(c["tolerance"], str) else (
            f"{c['tolerance']:.2%}" if c["tolerance"] < 1 else f"{c['tolerance']:.3g}")
        lines.append(f"{c['quantity']:<34} {c['recovered']:>11.4g} {truth:>11} {err:>8} {tol:>9}  "
                     f"{'pass' if c['pass'] else 'FAIL'}")
    return "\n".join(lines)
