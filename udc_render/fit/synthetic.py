"""Measurements made with the project itself, from a known display: the round trip's inputs (tests, the
exposure study) and the guide's example.

- psf_image: the noise-free laser PSF of a layout on the sensor, anywhere on the frame and turned by a few
  degrees: the engine's kernel at pixel / OS (OS × OS sub-pixels, each integrated exactly), resampled at the
  turned and shifted sub-pixel centres (cubic spline) and summed back to pixels (exact with no rotation and
  a shift of whole sub-pixels).
- psf_measurement: that PSF exposed (photon and read noise, the full well, a black level, 16-bit DN) at
  several exposures, with optional vignetting (a radial fall-off) and hot pixels.
- flat_measurement: a flat white field through the display at distance d: the transmitted power P(s) of
  psf.banding at the shift s = x d / z_i of every pixel, averaged over a few wavelengths, × vignetting.
- white_pair: the paper's white square through glass and through the display (l.210): mosaics whose levels
  differ by the display's γ per RGGB channel (optics.gamma), each with its own noise.
- noise_frames: repeated frames of a static pattern of grey blocks (Poisson and read noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from psf import Lens, compute_kernels
from psf.banding import PowerSeries, power_lattice
from psf.cache import cached
from udc_render.sensor import SensorConfig, expose, photon_weights, site_colour

OVERSAMPLE = 3  # sub-pixels per pixel and axis of psf_image (odd: the kernel's centre is a sub-pixel's)


@dataclass(frozen=True)
class Camera:
    """The virtual camera of the measurements: 1.55 µm pixels, the project's sensor noise (read 4.87 e⁻,
    full well 15 506 e⁻, 16 bits: a 12-bit camera's frames end at 4095 DN) at `gain`, a black level of 64 DN."""
    pixel_um: float = 1.55
    gain: float = 1.0
    black_level_dn: int = 64
    read_noise_e: float = 4.87
    full_well_e: float = 15506.0
    bit_depth: int = 16

    def sensor(self, gain: float | None = None) -> SensorConfig:
        return SensorConfig(pitch_um=self.pixel_um, gain=self.gain if gain is None else gain,
                            black_level_dn=self.black_level_dn, read_noise_e=self.read_noise_e,
                            full_well_e=self.full_well_e, bit_depth=self.bit_depth)


def psf_image(layout, lens: Lens, wavelength_nm: float, pixel_um: float, shape_hw, centre_px,
              rotation_deg: float = 0.0, window_px: int = 511, oversample: int = OVERSAMPLE,
              use_cache: bool = True) -> np.ndarray:
    """The noise-free PSF [H, W] (energy per pixel, the kernel window's total 1) with its centre at
    centre_px = (x, y) (pixel units, pixel (0, 0)'s centre at 0) and the display's x axis turned by
    rotation_deg from the image's x axis towards +y (module doc). use_cache: through the kernel cache (a
    measurement's display; not a fit's passing trial layouts)."""
    from scipy.ndimage import map_coordinates
    fine, _ = cached(compute_kernels, "mono", layout, lens, use_cache, wavelengths_nm=[wavelength_nm],
                     pixel_um=pixel_um / oversample, size_px=window_px * oversample, precision="float64")
    k = fine.kernels[0]
    c = k.shape[-1] // 2
    h, w = shape_hw
    sub = (np.arange(h * oversample) + 0.5) / oversample - 0.5, (np.arange(w * oversample) + 0.5) / oversample - 0.5
    dy, dx = sub[0][:, None] - centre_px[1], sub[1][None, :] - centre_px[0]
    a = math.radians(rotation_deg)
    u, v = dx * math.cos(a) + dy * math.sin(a), -dx * math.sin(a) + dy * math.cos(a)
    coords = np.stack(np.broadcast_arrays(c + v * oversample, c + u * oversample))
    vals = map_coordinates(k, coords, order=3, mode="constant", cval=0.0)
    return np.clip(vals, 0.0, None).reshape(h, oversample, w, oversample).sum(axis=(1, 3))


def render_window(layout, lens: Lens, wavelength_nm: float, pixel_um: float, size: int, origin, rotation_deg: float):
    """psf_image on a square window [S, S] (its centre pixel at (0, 0)) with the PSF's centre at `origin`
    (window px), from a kernel large enough to cover the whole window; the kernel cache is not used."""
    half = size // 2
    cover = 2 * (half + int(math.ceil(np.max(np.abs(origin)))) + 4) + 1
    return psf_image(layout, lens, wavelength_nm, pixel_um, (size, size), (half + origin[0], half + origin[1]),
                     rotation_deg, cover, use_cache=False)


def vignetting_map(shape_hw, corner_loss: float) -> np.ndarray:
    """1 − corner_loss · r² / r_corner²: a radial fall-off about the frame's centre (the optical axis)."""
    h, w = shape_hw
    y, x = np.mgrid[0:h, 0:w]
    r2 = (x - (w - 1) / 2) ** 2 + (y - (h - 1) / 2) ** 2
    return 1.0 - corner_loss * r2 / r2.max()


def _expose(electrons: np.ndarray, sensor: SensorConfig, rng) -> np.ndarray:
    return expose(electrons, sensor, rng)[0]


def psf_measurement(layout, lens: Lens | None = None, wavelength_nm: float = 650.0, camera: Camera = Camera(),
                    shape_hw=(384, 512), offset_px=(0.0, 0.0), rotation_deg: float = 0.0,
                    peaks_fw=(0.8, 40.0), vignetting: float = 0.0, hot_pixels: int = 0, seed: int = 0,
                    window_px: int = 511, cfa: bool = False, camera_name: str = "Nikon 5100 (NPL)") -> list[np.ndarray]:
    """One uint16 frame per exposure of a collimated laser through `layout` (module doc). peaks_fw: the
    brightest pixel's electrons per exposure in units of the full well (above 1 it saturates); offset_px:
    the spot's centre from the frame's centre (x, y); vignetting: the fall-off at the frame's corners;
    hot_pixels: that many pixels at 0.3–1 of the range in every frame; cfa: an RGGB mosaic, each site
    weighted by its colour's response at the wavelength (camera_name's sensitivities)."""
    lens = lens or Lens()
    rng = np.random.default_rng(seed)
    h, w = shape_hw
    centre = ((w - 1) / 2 + offset_px[0], (h - 1) / 2 + offset_px[1])
    img = psf_image(layout, lens, wavelength_nm, camera.pixel_um, shape_hw, centre, rotation_deg, window_px)
    if vignetting:
        img = img * vignetting_map(shape_hw, vignetting)
    if cfa:
        resp = photon_weights([wavelength_nm - 5.0, wavelength_nm + 5.0], camera_name)[:, 0]
        img = img * (resp / resp.max())[np.array([0, 1, 1, 2])[site_colour(h, w)]]
    sensor = camera.sensor()
    frames = [_expose(img * (p * sensor.full_well_e / img.max()), sensor, rng) for p in peaks_fw]
    if hot_pixels:
        ys, xs = rng.integers(0, h, hot_pixels), rng.integers(0, w, hot_pixels)
        level = rng.uniform(0.3, 1.0, hot_pixels) * sensor.white_level_dn
        for f in frames:
            f[ys, xs] = level.astype(np.uint16)
    return frames


def flat_power(layout, lens: Lens, distance_mm: float, shape_hw, pixel_um: float,
               wavelengths_nm=(450.0, 550.0, 650.0)) -> np.ndarray:
    """P(s) / its mean at every pixel, s = x d / z_i from the frame's centre, averaged over the wavelengths
    (psf.banding.PowerSeries, each truncated to 1e-5 of its mean power)."""
    h, w = shape_hw
    z = lens.image_distance_um
    step = pixel_um * distance_mm * 1000.0 / z
    x0, y0 = -(w - 1) / 2 * step, -(h - 1) / 2 * step
    out = np.zeros(shape_hw)
    for wl in wavelengths_nm:
        series = PowerSeries(layout, lens, wl * 1e-3, distance_mm * 1000.0)
        p = power_lattice(series.truncated(), layout.period_um, x0, step, w, y0, step, h)
        out += p / p.mean()
    return out / len(wavelengths_nm)


def flat_measurement(layout, distance_mm: float, lens: Lens | None = None, camera: Camera = Camera(),
                     shape_hw=(256, 1024), level_fw: float = 0.5, vignetting: float = 0.2, seed: int = 0,
                     wavelengths_nm=(450.0, 550.0, 650.0)) -> np.ndarray:
    """A flat white field through `layout` at distance_mm (module doc), its mean at level_fw of the full
    well, as a uint16 frame."""
    lens = lens or Lens()
    p = flat_power(layout, lens, distance_mm, shape_hw, camera.pixel_um, wavelengths_nm)
    sensor = camera.sensor()
    e = p * vignetting_map(shape_hw, vignetting) * level_fw * sensor.full_well_e
    return _expose(e, sensor, np.random.default_rng(seed))


def white_pair(gamma_rggb, camera: Camera = Camera(), display_gain: float = 1.0, shape_hw=(256, 256),
               square_px: int = 128, level_fw: float = 0.6, channel_levels=(0.55, 1.0, 1.0, 0.7),
               seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(glass, display) RGGB mosaics of a white square (square_px, centred) on black: through glass at
    gain 1 the sites read level_fw × channel_levels of the full well, through the display γ_c times that
    (γ includes the display capture's gain, as the paper's: its electrons are γ_c / display_gain of the
    glass's, read at display_gain)."""
    h, w = shape_hw
    rng = np.random.default_rng(seed)
    sq = np.zeros(shape_hw)
    t = (h - square_px) // 2, (w - square_px) // 2
    sq[t[0]:t[0] + square_px, t[1]:t[1] + square_px] = 1.0
    site = site_colour(h, w)
    base = sq * level_fw * camera.full_well_e * np.asarray(channel_levels)[site]
    glass = _expose(base, camera.sensor(1.0), rng)
    disp = _expose(base * np.asarray(gamma_rggb, float)[site] / display_gain, camera.sensor(display_gain), rng)
    return glass, disp


def noise_frames(n_frames: int, camera: Camera = Camera(), shape_hw=(128, 128), block_px: int = 8,
                 max_fw: float = 0.9, seed: int = 0) -> list[np.ndarray]:
    """n_frames uint16 RGGB frames of one static pattern of grey blocks (electrons uniform in
    0 … max_fw of the full well, block_px square), each with its own noise at camera.gain."""
    h, w = shape_hw
    rng = np.random.default_rng(seed)
    blocks = rng.uniform(0.0, max_fw, (h // block_px + 1, w // block_px + 1))
    e = np.kron(blocks, np.ones((block_px, block_px)))[:h, :w] * camera.full_well_e / camera.gain
    sensor = camera.sensor()
    return [_expose(e, sensor, rng) for _ in range(n_frames)]


def with_gain(camera: Camera, gain: float) -> Camera:
    return replace(camera, gain=gain)
