"""The virtual calibration rig: the monitor scene on a reduced sensor with framing 'fill' (the panel
spans the frame's width and overhangs it in height, into the render margin), rendered once per
pattern and seen through glass and through the display (spectral form: band kernels, T(λ), gain,
RGGB sensor)."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from udc_render.io.files import atomic_path
from udc_render.optics import apply_kernels
from udc_render.optics.displays import load_display
from udc_render.pipeline import SynthConfig, auto_exposure_s, plan_kernels, sensor_for_scene
from udc_render.render import render_scene
from udc_render.scene import load_scene, parse_bands
from udc_render.scene.geometry import camera_geometry
from udc_render.sensor import capture as sensor_capture

CHANNELS = ("R", "Gr", "Gb", "B")  # the RGGB sites, in pack_rggb order


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
        planned = plan_kernels(self.scene, [self.glass, self.display], self.cfg)
        self.kernels, self.far = planned.band, planned.far  # far: the light past the window (SynthConfig)
        self.seconds = {"kernels": time.perf_counter() - t0}
        self.sensors = None

    def render(self, image: str, spp: int | None = None):
        """BandImage of the monitor showing `image` (rgb_matrix path); sets up kernels and sensors once."""
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
        t0 = time.perf_counter()
        t = d.transmission.band_means(band_image.edges_nm)
        img = apply_kernels(band_image, self.kernels[d.name], t, self.cfg.precision,
                            far_field=self.far.get(d.name)).images
        self.seconds["optics"] = self.seconds.get("optics", 0.0) + time.perf_counter() - t0
        return img

    def rng(self, stream: int) -> np.random.Generator:
        """Random stream `stream` of the rig's seed: default_rng([seed, stream]). The protocols' streams are
        nonzero and distinct (7: the noise pattern; gamma 1000 + 2·level + view; noise 1999, 2000 + frame; PSF
        3000, 3001 + frame; MTF 4000 + 100·(y axis) + 2·frequency + view; tests/udc_render/test_calibrate.py),
        so numpy's zero padding (default_rng([seed, 0]) is default_rng(seed)) makes no two of them one stream.
        Kept, not a streams.stream: the calibrations' noise, and their recorded figures, stay."""
        return np.random.default_rng([self.cfg.seed, stream])

    def capture(self, images, band_image, d, stream: int):
        """The sensor capture of irradiance `images` behind `d`, noise from random stream `stream` (rng)."""
        return sensor_capture(images, band_image.edges_nm, self.sensors[d.name], self.rng(stream))

    def monitor_px(self) -> tuple[float, float]:
        """The panel's width and height on the sensor in pixels (thin lens, magnification v/u)."""
        g = camera_geometry(self.scene)
        m = g.image_distance_um / (g.focus_distance_m * 1e6)
        w_m, h_m = self.scene.content.size_m
        return w_m * 1e6 * m / g.pitch_um, h_m * 1e6 * m / g.pitch_um

    def half_kernel(self) -> int:
        """Half the kernel side: kernels are 2 · half_kernel + 1 px."""
        return self.kernels[self.glass.name].kernels.shape[-1] // 2

    def pattern_file(self, name: str, code: np.ndarray) -> str:
        """Write an 8-bit RGB PNG (code values [rows, cols]) into out/patterns and return its path."""
        folder = self.out / "patterns"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / name
        with atomic_path(path, ".png") as tmp:
            iio.imwrite(tmp, np.repeat(code.astype(np.uint8)[..., None], 3, -1), extension=".png")
        return str(path.resolve())


def check(name: str, recovered, truth, tol: float) -> dict:
    """A relative check: error = |recovered − truth| / |truth|, passing when error ≤ tol."""
    err = abs(recovered - truth) / abs(truth)
    return {"quantity": name, "recovered": float(recovered), "truth": float(truth), "error": float(err),
            "tolerance": tol, "pass": bool(err <= tol)}
