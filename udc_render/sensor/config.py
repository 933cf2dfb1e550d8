"""SensorConfig: every setting of the virtual sensor, validated on construction."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from udc_render.errors import UdcError
from udc_render.io.files import read_toml


class SensorError(UdcError):
    """A bad sensor setting or input array; one line naming the field or array, value and range."""


def _cameras() -> tuple[str, ...]:
    from psf.spectral import CAMERAS
    return CAMERAS


def _fail(name: str, value, allowed: str):
    raise SensorError(f"sensor.{name} = {value!r}: expected {allowed}")


def _num(name, v, lo, hi, lo_open=False, integer=False):
    kind = "an integer" if integer else "a number"
    ok = isinstance(v, (int, np.integer)) if integer else isinstance(v, (int, float, np.integer, np.floating))
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
    if isinstance(v, bool) or not ok or not math.isfinite(v) or not ((v > lo) if lo_open else (v >= lo)) or v > hi:
        _fail(name, v, f"{kind} in {rng}")


# Defect settings of an earlier version, now sensor.defects.DefectConfig (SynthConfig.defects).
MOVED_DEFECT_KEYS = ("dead_fraction", "hot_fraction", "defect_seed")

# Optical settings with one source, the scene: the pipeline fills them (pipeline.sensor_for_scene).
SCENE_OPTICS = {"pitch_um": "[sensor] pitch_um", "f_number": "[lens] f_number",
                "focal_length_um": "[lens] focal_length_mm"}


@dataclass(frozen=True)
class SensorConfig:
    """Every setting of the virtual sensor (defaults: the paper's rig, docs/PHYSICS.md §2, §5).

    Optical/radiometric: pitch_um (1.55), f_number (1.8), exposure_s (0.125 = 8 fps), peak_qe,
    camera (colour-science name or CSV path: header row, wavelength_nm, r, g, b), cos4_falloff and
    focal_length_um (field angle for cos⁴), form ('spectral' or 'per_channel'), gamma_rggb (per-
    channel form only). Electronic: gain (the paper's 1 / 6 / 25), conversion_gain_dn_per_e (None:
    R / full_well_e, so the full well fills the range at gain 1), noise ('poisson', 'gaussian',
    'none'), read_noise_e, full_well_e, lambda_source ('fixed', 'brooks', 'sensor': the Gaussian λ
    equivalent to the photon model), lambda_read / lambda_shot (scalar or per R, Gr, Gb, B),
    brooks_per_channel, bit_depth, black_level_dn, white_level_dn (None: 2^bits − 1). Dead and hot
    pixels are not here: sensor.defects.DefectConfig, set by the synthesis (SynthConfig.defects).
    """
    pitch_um: float = 1.55
    f_number: float = 1.8
    exposure_s: float = 0.125
    peak_qe: float = 0.6
    camera: str = "Nikon 5100 (NPL)"
    cos4_falloff: bool = False
    focal_length_um: float = 6000.0
    form: Literal["spectral", "per_channel"] = "spectral"
    gamma_rggb: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    gain: float = 1.0
    conversion_gain_dn_per_e: float | None = None
    noise: Literal["poisson", "gaussian", "none"] = "poisson"
    read_noise_e: float = 4.87
    full_well_e: float = 15506.0
    lambda_source: Literal["fixed", "brooks", "sensor"] = "fixed"
    lambda_read: float | tuple[float, float, float, float] = 1e-6
    lambda_shot: float | tuple[float, float, float, float] = 1e-3
    brooks_per_channel: bool = False
    bit_depth: int = 16
    black_level_dn: int = 0
    white_level_dn: int | None = None

    def __post_init__(self):
        _num("pitch_um", self.pitch_um, 0, 1000, lo_open=True)
        _num("f_number", self.f_number, 0.5, 128)
        _num("exposure_s", self.exposure_s, 0, 3600, lo_open=True)
        _num("peak_qe", self.peak_qe, 0, 1, lo_open=True)
        if not isinstance(self.camera, str) or not (self.camera in _cameras() or Path(self.camera).is_file()):
            _fail("camera", self.camera, f"one of {', '.join(_cameras())} or an existing CSV file")
        for b in ("cos4_falloff", "brooks_per_channel"):
            if not isinstance(getattr(self, b), bool):
                _fail(b, getattr(self, b), "true or false")
        _num("focal_length_um", self.focal_length_um, 0, 1e7, lo_open=True)
        for name, choices in (("form", ("spectral", "per_channel")), ("noise", ("poisson", "gaussian", "none")),
                              ("lambda_source", ("fixed", "brooks", "sensor"))):
            if getattr(self, name) not in choices:
                _fail(name, getattr(self, name), "one of " + ", ".join(choices))
        object.__setattr__(self, "gamma_rggb", self._four("gamma_rggb", self.gamma_rggb, 0, 1e3))
        _num("gain", self.gain, 0, 1e6, lo_open=True)
        if self.conversion_gain_dn_per_e is not None:
            _num("conversion_gain_dn_per_e", self.conversion_gain_dn_per_e, 0, 65535, lo_open=True)
        _num("read_noise_e", self.read_noise_e, 0, 1e5)
        _num("full_well_e", self.full_well_e, 1, 1e9)
        object.__setattr__(self, "lambda_read", self._four("lambda_read", self.lambda_read, 0, 1))
        object.__setattr__(self, "lambda_shot", self._four("lambda_shot", self.lambda_shot, 0, 1))
        _num("bit_depth", self.bit_depth, 1, 16, integer=True)
        top = 2 ** self.bit_depth - 1
        if self.white_level_dn is None:
            object.__setattr__(self, "white_level_dn", top)
        _num("white_level_dn", self.white_level_dn, 1, top, integer=True)
        _num("black_level_dn", self.black_level_dn, 0, self.white_level_dn - 1, integer=True)

    @staticmethod
    def _four(name, v, lo, hi) -> tuple[float, float, float, float]:
        vals = list(v) if isinstance(v, (tuple, list)) else [v] * 4
        if len(vals) != 4:
            _fail(name, v, "a number or 4 numbers (R, Gr, Gb, B)")
        for x in vals:
            _num(name, x, lo, hi)
        return tuple(float(x) for x in vals)

    @classmethod
    def from_dict(cls, data: dict) -> "SensorConfig":
        """From a TOML table (lists for tuples); unknown keys rejected. Errors name the key."""
        names = [f.name for f in dataclasses.fields(cls)]
        for k in data:
            if k in SCENE_OPTICS:
                _fail(k, data[k], f"no value here: {k} comes from the scene file ({SCENE_OPTICS[k]})")
            if k in MOVED_DEFECT_KEYS:
                _fail(k, data[k], "no value here: dead and hot pixels are set by the profile (--profile; "
                                  "udc_render.sensor.defects.DefectConfig)")
            if k not in names:
                _fail(k, data[k], f"a known key ({', '.join(names)})")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})

    @classmethod
    def from_toml(cls, path: str | Path) -> "SensorConfig":
        """From a TOML file of sensor keys; errors name the file and the key."""
        data = read_toml(path, SensorError, "sensor config")
        try:
            return cls.from_dict(data)
        except SensorError as e:
            raise SensorError(f"{path}: {e}") from None

    @property
    def range_dn(self) -> int:
        """R = white − black: the DN span of the signal."""
        return self.white_level_dn - self.black_level_dn

    @property
    def dn_per_electron(self) -> float:
        """g = gain · conversion gain (DN per e⁻)."""
        conv = self.conversion_gain_dn_per_e or self.range_dn / self.full_well_e
        return self.gain * conv

