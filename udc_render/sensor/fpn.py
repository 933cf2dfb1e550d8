"""Fixed-pattern noise (FPN): the sensor's per-pixel gain and offset maps, and its dark current.

EMVA 1288 (Release 3.1, 2016, §4 "Spatial Nonuniformity and Defect Pixels") separates what stays the same from
frame to frame from the temporal noise: the photo-response nonuniformity PRNU (the spatial σ of the pixels' gains,
relative to the mean signal) and the dark-signal nonuniformity DSNU (the spatial σ of the dark signal,
in e⁻), with their row and column parts; and the mean dark current (e⁻/s). Here, per pixel (i, j) in
the sensor's electron stage (sensor.noise.expose):

    q_ij = e_ij · (1 + PRNU · z_ij) + D · t                       mean charge: signal × gain map + dark charge
    n_ij = Poisson(q_ij) + N(0, σ_read²)                          shot noise of both (the dark charge's too)
    o_ij = DSNU · u_ij + σ_row · r_i + σ_col · c_j                offset map (e⁻), zero mean
    DN_ij = black + g · min(n_ij + o_ij, FW), rounded, clipped to [0, white]

with z, u, r, c independent standard normals (z clipped so that 1 + PRNU · z ≥ 0), D the dark current,
t the exposure, g = gain × conversion gain (DN/e⁻: the offsets are input-referred electrons, amplified
like the signal, as EMVA quotes DSNU) and the full well capping the read-out charge as before (a
saturated pixel still reads black + g · FW). The Gaussian noise model takes q for its mean (its λ_shot
term gives the dark charge its shot noise) and o / (R/g) before its cap; noise 'none' reads
black + g · min(q + o, FW). Not modelled: a dark current that varies from pixel to pixel (its spread
sits in DSNU at the rig's short exposures), its temperature dependence, per-channel PRNU, temporal row
noise.

The maps are a property of the sensor, like the defect map (sensor.defects): drawn from
``FpnConfig.seed`` alone (SeedSequence(seed).spawn(4): PRNU, DSNU, rows, columns; independent of the
noise seeds), the same in every capture of a run (glass and every display, every item), never in the
ground truth, and a parameter scales a fixed standard-normal map. The clean mosaic (Capture.clean_dn)
stays FPN-free: black + g · min(e, FW), the noise-free mean of an ideal sensor.

Defaults: the paper's camera and what is published for its family
-----------------------------------------------------------------
The paper's camera is a Point Grey (FLIR) machine-vision camera with a Sony CMOS sensor of 1.55 µm
pixels, likely the Flea3 FL3-U3-88S2C (Sony IMX121, rolling shutter, 12-bit ADC). No EMVA 1288 sheet
with PRNU, DSNU, dark current or row/column figures was found for it, for the IMX121, or for any
FLIR/Point Grey camera with a 1.55 µm Sony sensor (FLIR's published EMVA summaries, e.g. the Blackfly S
spec pages at softwareservices.flir.com, list QE, temporal dark noise, saturation capacity, dynamic range
and gain, not the nonuniformities). The values below are therefore chosen:

- **prnu = 0.007** (0.7 %): the PRNU of the Sony IMX363 model (1.4 µm Exmor RS stacked pixels, the
  nearest published sibling: Google Pixel 4a) in ISETCam, ``sensor/models/sensorIMX363.m``
  (github.com/ISET/isetcam: 'prnu' 0.7, stored as a percentage), whose defaults its comment attributes
  to Lyu, Kripakaran, Furth, Tang, Wandell & Farrell's validation against real captures ("Validation of
  image systems simulation technology using a Cornell Box", IS&T Electronic Imaging 2021,
  arXiv:2105.04106). Recent Sony sensors have PRNU of 0.3–1 % (docs/PHYSICS.md §9): the range.
- **dsnu_e = 1.0 e⁻**: the same ISETCam model sets DSNU to 0 (a non-zero value is left commented out);
  with correlated double sampling the pixel offsets of a 4T pixel are small against its temporal dark
  noise (4.87 e⁻ here). A choice of about a fifth of the read noise; range 0.3–3 e⁻.
- **row_offset_e = 0.3 e⁻, column_offset_e = 0.5 e⁻**: Sony's column-parallel ADCs share one ramp
  reference and calibrate their columns, leaving much smaller column irregularity than multi-ADC
  designs (dark frames of Nikon's Sony-sensor DSLRs, landingfield.wordpress.com, "The Dark Side of
  Image Sensors"); machine-vision Sony CMOS shows "no visible fixed pattern noise" (Imperx Cheetah
  Pregius manual, §Image Sensor Technology). Columns are set larger than rows because each column has
  its own amplifier and comparator. Choices; range 0–2 e⁻ each.
- **dark_current_e_per_s = 5 e⁻/s**: the order of magnitude of uncooled Sony CMOS at room temperature
  (a user's measurement of a FLIR IMX249 camera, quoted in huggingface.co/datasets/nvidia/Nemotron-CC-Math-v1
  "Calculation of Dark Current using the SharpCap Method", gives about 1.5 e⁻/s; dark current doubles
  every 5–8 °C, adimec.com's note on dark shot noise). Range
  0.5–50 e⁻/s. At the default rig's exposure (31 ms) it gives 0.16 e⁻ (0.6 e⁻ at the paper's 125 ms):
  negligible against the read noise anywhere in the range.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np

from udc_render.sensor import readout
from udc_render.sensor.config import SensorConfig, SensorError

PRNU = 0.007
DSNU_E = 1.0
ROW_OFFSET_E = 0.3
COLUMN_OFFSET_E = 0.5
DARK_CURRENT_E_PER_S = 5.0
FPN_SEED = 0


class FpnError(SensorError):
    """A bad fixed-pattern-noise setting; one line naming the key, the value and what is allowed."""


def _check(name: str, v, lo: float, hi: float, integer: bool = False) -> None:
    kind = "an integer" if integer else "a number"
    ok = isinstance(v, (int, np.integer)) if integer else isinstance(v, (int, float, np.integer, np.floating))
    if isinstance(v, bool) or not ok or not math.isfinite(v) or not lo <= v <= hi:
        raise FpnError(f"fpn.{name} = {v!r}: expected {kind} in [{lo:g}, {hi:g}]")


@dataclass(frozen=True)
class FpnConfig:
    """Fixed-pattern noise of the sensor (module doc: model, defaults and their evidence).

    prnu: relative σ of the per-pixel gain (0.007 = 0.7 %); dsnu_e, row_offset_e, column_offset_e: σ of
    the per-pixel, per-row and per-column offsets (e⁻, input-referred); dark_current_e_per_s: the mean
    dark current (e⁻ per second of exposure, with its shot noise); seed: the maps' own seed."""
    prnu: float = PRNU
    dsnu_e: float = DSNU_E
    row_offset_e: float = ROW_OFFSET_E
    column_offset_e: float = COLUMN_OFFSET_E
    dark_current_e_per_s: float = DARK_CURRENT_E_PER_S
    seed: int = FPN_SEED

    def __post_init__(self):
        _check("prnu", self.prnu, 0.0, 0.25)
        for name in ("dsnu_e", "row_offset_e", "column_offset_e"):
            _check(name, getattr(self, name), 0.0, 1e4)
        _check("dark_current_e_per_s", self.dark_current_e_per_s, 0.0, 1e6)
        _check("seed", self.seed, 0, 2 ** 63 - 1, integer=True)

    def dark_charge_e(self, exposure_s: float) -> float:
        """Mean dark charge over one exposure, D · t (e⁻)."""
        return self.dark_current_e_per_s * float(exposure_s)


@dataclass(frozen=True)
class FpnMaps:
    """The sensor's maps for one frame size: gain [H, W] (1 + PRNU · z, ≥ 0), dsnu_e [H, W], row_e [H],
    column_e [W] (e⁻)."""
    gain: np.ndarray
    dsnu_e: np.ndarray
    row_e: np.ndarray
    column_e: np.ndarray

    @property
    def offset_e(self) -> np.ndarray:
        """o_ij = DSNU · u_ij + σ_row · r_i + σ_col · c_j (e⁻), [H, W] float64."""
        return self.dsnu_e + self.row_e[:, None] + self.column_e[None, :]


def fpn_normals(height_px: int, width_px: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(z [H, W], u [H, W], r [H], c [W]): the standard normals of the PRNU, DSNU, row and column maps, drawn from
    SeedSequence(seed).spawn(4) in that order (module doc); the maps scale them (fpn_maps)."""
    h, w = int(height_px), int(width_px)
    prnu_rng, dsnu_rng, row_rng, col_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4))
    return (prnu_rng.standard_normal((h, w)), dsnu_rng.standard_normal((h, w)), row_rng.standard_normal(h),
            col_rng.standard_normal(w))


@lru_cache(maxsize=2)
def fpn_maps(height_px: int, width_px: int, fpn: FpnConfig) -> FpnMaps:
    """The maps of an H × W sensor: a function of (shape, fpn) alone (module doc; sensor.readout.fpn_gain), made
    once per process and shape (every capture of a job draws the same), read-only."""
    z, u, r, c = fpn_normals(height_px, width_px, fpn.seed)
    maps = (readout.fpn_gain(z, fpn.prnu), fpn.dsnu_e * u, fpn.row_offset_e * r, fpn.column_offset_e * c)
    for a in maps:
        a.setflags(write=False)
    return FpnMaps(*maps)


def mean_charge_e(electrons: np.ndarray, maps: FpnMaps, fpn: FpnConfig, exposure_s: float) -> np.ndarray:
    """q = e · (1 + PRNU · z) + D · t: the mean charge the shot noise is drawn around (e⁻, float64;
    sensor.readout.mean_charge_e)."""
    return readout.mean_charge_e(np.asarray(electrons, np.float64), maps.gain, fpn.dark_charge_e(exposure_s))


def fpn_record(fpn: FpnConfig, maps: FpnMaps, sensor: SensorConfig) -> dict:
    """The capture's record: the settings, the dark charge, and the maps' measured spatial σ."""
    g = sensor.dn_per_electron
    return {**asdict(fpn), "dark_charge_e": fpn.dark_charge_e(sensor.exposure_s),
            "dark_charge_dn": g * fpn.dark_charge_e(sensor.exposure_s),
            "map_std": {"prnu": float(maps.gain.std()), "dsnu_e": float(maps.dsnu_e.std()),
                        "row_e": float(maps.row_e.std()), "column_e": float(maps.column_e.std())},
            "model": "q = e (1 + PRNU z) + dark_current x exposure (shot noise on q); DN = black + g min(n + DSNU u + "
                     "row_i + column_j, FW); maps from fpn.seed alone, the same in every capture, none in the gt "
                     "or the clean mosaic"}
