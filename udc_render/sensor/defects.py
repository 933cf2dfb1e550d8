"""Sensor defect pixels: the impulse noise of real captures (dead and hot pixels).

The paper names "impulse noise caused by dead pixels or over-exposure in the camera sensors" as one
of the gaps between its synthetic and its real data (Zhou et al. 2021, l.412). This module adds it
to a capture's RAW mosaic, in DN, after noise, full well and quantisation (sensor.noise.expose) and
before packing, so ``raw.dng`` and the packed RAW both carry it (sensor.capture):

- a **dead** pixel reads the black level, whatever light it receives;
- a **hot** pixel collects an extra dark charge q = hot_dark_e_per_s × exposure_s (a dark-current
  spike) on top of its signal, read out through the same analogue gain as the signal:
  DN = min(DN_signal + g · q, black + g · FW, white), g = gain × conversion gain (DN per e⁻). At the
  default rig's auto exposure (31.04 ms) the default rate gives q = 931 e⁻: +6 % of the range at
  gain 1 (glass: visible, below white), +36 % at gain 6 (T-OLED), saturated at gain 25 (P-OLED:
  the paper's "over-exposed" pixels).

The defect map is a property of the sensor: the same pixels in every capture of a run (glass and
every display, every item), drawn from ``DefectConfig.seed`` alone (numpy default_rng, one uniform
number u per pixel: dead where u < dead_fraction, hot where dead_fraction ≤ u < dead_fraction +
hot_fraction), independent of the noise seeds. Each pixel is defective independently, so the count
is binomial, and raising a fraction keeps the pixels already drawn. The clean mosaic
(Capture.clean_dn) and the ground truth (pipeline: noise-free, mosaic-free) stay defect-free: the
ground truth is the ideal clean view, and every capture, the glass one included, carries the
sensor's defects.

Not modelled: the dark charge's own shot noise (√q), a spread of dark currents among hot pixels
(real ones span orders of magnitude; one rate stands for all), temperature, clusters (none are
observed: defects fall at independent random positions, Chapman et al. 2012), stuck-at-mid-level
pixels.

Default densities (order-of-magnitude choices, not measurements of the paper's camera)
--------------------------------------------------------------------------------------
- **hot_fraction = 1e-4** (210 of the 2048 × 1024 pixels). Hot pixels develop in the field at a
  constant rate, at random, unclustered positions, attributed to cosmic rays (Chapman, Koren &
  Koren, "Do more camera pixels result in a better picture?", IEEE IOLTS 2012). Their rate per mm²
  per year grows as the pixel size to the power −2.5 over DSLRs, compact and 11 cell-phone cameras
  (−3.3 for CMOS alone) and with the ISO; more than 40 % are "partially stuck" (an offset
  independent of the exposure time) and a higher ISO makes defects both more numerous and more
  visible, some saturating (Chapman, Leung, Namburete, Koren & Koren, "Predicting pixel defect
  rates based on image sensor parameters", IEEE DFT 2011, pp. 408–416). The fitted formula
  (defects/year/mm² ∝ pixel size^−≈3 × ISO^0.5) is Chapman et al., "Empirical formula for rates of
  hot pixel defects based on pixel size, sensor area, and ISO", Proc. SPIE 8659 (2013); its
  coefficients are not reproduced here. The one absolute number used is from the abstract of
  Chapman, Meneses, Koren & Koren, "Image degradation due to interacting adjacent hot pixels",
  IEEE DFT 2022: a 20 Mpixel DSLR with 4 µm pixels gathers 128 hot pixels in 1.4 years at ISO 6400
  (6.4e-6 of its pixels). Scaled to 1.55 µm pixels by the power law (× (4/1.55)³ per mm², ×
  (1.55/4)² per pixel: × 2.6) that is ≈ 1.7e-5 per 1.4 years at ISO 6400, ≈ 0.7e-5 per year at ISO
  2500 (× √(2500/6400); ISO 2500 if the paper's gain 25 is a linear factor on a base ISO of 100,
  itself an assumption). A sensor some years old, factory defects that a research camera's RAW may
  not map out, and the paper's remark that impulse noise "widely exist[s]" in its real data make a
  higher density plausible; how many hot pixels count also depends on the threshold (and exposure)
  they are detected at. We take 1e-4, between ≈ 1e-5 and 1e-3, uncertain by a factor of ten either
  way.
- **dead_fraction = 1e-5**: no measured rate for this class of sensor was found; in-field defects
  are mainly hot pixels (Chapman et al. 2012), so dead pixels are set ten times rarer. A choice.
- **hot_dark_e_per_s = 3e4**: the least-known number. Chosen so that, at the default rig's exposure,
  hot pixels reproduce what the paper reports (saturated behind the P-OLED at gain 25) while staying
  below white through glass; it stands for both true dark-current spikes and the partially stuck
  pixels' offsets. At the paper's own 125 ms shutter it would be 3750 e⁻ (24 % of the range at gain 1).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np

from udc_render.sensor import readout
from udc_render.sensor.bayer import check_even
from udc_render.sensor.config import SensorConfig, SensorError
from udc_render.sensor.readout import DEAD, HOT

DEAD_FRACTION = 1e-5
HOT_FRACTION = 1e-4
HOT_DARK_E_PER_S = 3.0e4
DEFECT_SEED = 0


class DefectError(SensorError):
    """A bad defect setting; one line naming the key, the value and what is allowed."""


def _check(name: str, v, lo: float, hi: float, integer: bool = False) -> None:
    kind = "an integer" if integer else "a number"
    ok = isinstance(v, (int, np.integer)) if integer else isinstance(v, (int, float, np.integer, np.floating))
    if isinstance(v, bool) or not ok or not math.isfinite(v) or not lo <= v <= hi:
        raise DefectError(f"defects.{name} = {v!r}: expected {kind} in [{lo:g}, {hi:g}]")


@dataclass(frozen=True)
class DefectConfig:
    """Dead and hot pixels of the sensor (module doc: model, defaults and their evidence).

    dead_fraction, hot_fraction: share of all pixels (each pixel independently), their sum ≤ 1;
    hot_dark_e_per_s: dark current of a hot pixel (e⁻ per second of exposure), amplified by the
    capture's gain; seed: the defect map's own seed (not the noise seed)."""
    dead_fraction: float = DEAD_FRACTION
    hot_fraction: float = HOT_FRACTION
    hot_dark_e_per_s: float = HOT_DARK_E_PER_S
    seed: int = DEFECT_SEED

    def __post_init__(self):
        _check("dead_fraction", self.dead_fraction, 0.0, 1.0)
        _check("hot_fraction", self.hot_fraction, 0.0, 1.0 - self.dead_fraction)
        _check("hot_dark_e_per_s", self.hot_dark_e_per_s, 0.0, 1e12)
        _check("seed", self.seed, 0, 2 ** 63 - 1, integer=True)

    def hot_charge_e(self, exposure_s: float) -> float:
        """Extra dark charge of a hot pixel over one exposure (e⁻)."""
        return self.hot_dark_e_per_s * float(exposure_s)


@lru_cache(maxsize=2)
def defect_map(height_px: int, width_px: int, defects: DefectConfig) -> np.ndarray:
    """[H, W] int8: 0 good, 1 (DEAD) dead, 2 (HOT) hot; a function of (shape, defects) alone (module doc;
    sensor.readout.defect_classes of default_rng(seed).random((H, W))), made once per process and shape, read-only."""
    u = np.random.default_rng(defects.seed).random((int(height_px), int(width_px)))
    kind = readout.defect_classes(u, defects.dead_fraction, defects.hot_fraction)
    kind.setflags(write=False)
    return kind


def defect_levels(sensor: SensorConfig, defects: DefectConfig) -> tuple[float, float]:
    """(hot_dn, top_dn): what a hot pixel adds, g · hot_dark_e_per_s · t, and its cap, min(white, black + g FW)."""
    g = sensor.dn_per_electron
    return (g * defects.hot_charge_e(sensor.exposure_s),
            min(float(sensor.white_level_dn), sensor.black_level_dn + g * sensor.full_well_e))


def apply_defects(mosaic_dn: np.ndarray, sensor: SensorConfig, defects: DefectConfig) -> tuple[np.ndarray, dict]:
    """(a copy of the uint16 RGGB mosaic [H, W] with dead and hot pixels, their record for the
    capture's params). The sensor gives the black and white levels, the full well, the gain and
    the exposure (module doc; the arithmetic: sensor.readout.with_defects)."""
    mosaic = np.asarray(mosaic_dn)
    if mosaic.ndim != 2 or mosaic.dtype != np.uint16:
        raise SensorError(f"mosaic: {mosaic.dtype} array of shape {mosaic.shape}: expected a uint16 [H, W] mosaic")
    check_even(mosaic.shape, "mosaic")
    kind = defect_map(*mosaic.shape, defects)
    hot_dn, top = defect_levels(sensor, defects)
    out = readout.with_defects(mosaic.astype(np.float64), kind, sensor.black_level_dn, hot_dn, top,
                               sensor.white_level_dn).astype(np.uint16)
    hot = kind == HOT
    info = {**asdict(defects), "dead_pixels": int((kind == DEAD).sum()), "hot_pixels": int(hot.sum()),
            "hot_charge_e": defects.hot_charge_e(sensor.exposure_s), "hot_dn_added": hot_dn,
            "hot_saturated": int((out[hot] >= sensor.white_level_dn).sum()),
            "model": "dead: black level; hot: + gain x conversion gain x hot_dark_e_per_s x exposure_s, "
                     "capped at black + g FW and the white level; after noise and quantisation"}
    return out, info
