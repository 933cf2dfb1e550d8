"""The sensor: band radiance at the sensor plane ──► RGGB RAW mosaic in DN (PHYSICS.md §1, §2, §5).

Conventions
-----------
* Bayer pattern **RGGB**: R at (row 0, col 0), Gr at (0, 1), Gb at (1, 0), B at (1, 1), repeated
  with period 2. Packed RAW is ``[4, H/2, W/2]`` in the order (R, Gr, Gb, B).
* Input (spectral form): ``[K, H, W]`` band-mean radiance L_k in W·sr⁻¹·m⁻²·nm⁻¹ at the sensor
  pitch (already blurred and multiplied by the display transmission by the optics stage), with band
  edges ``edges_nm`` [K + 1]; radiance is taken as constant within a band.
* Input (per-channel form, the paper's ``y = γ_c x_c``): ``[3, H, W]`` linear R, G, B in normalised
  units, where x = 1 at γ = 1 fills the full well (and, at gain 1 with the default conversion gain,
  the white level).

Radiometry (spectral form), per pixel p of colour c(p):

    E_k   = π L_k / (4 N²) · cos⁴θ            image-side irradiance (on-axis, object at infinity;
                                              cos⁴θ only when ``cos4_falloff``; tan θ = r / f)
    e(p)  = Σ_k E_k · A · t · Δλ_k · q_ck       electrons, A = pitch², t = exposure
    q_ck  = (1/Δλ_k) ∫_band QE_c(λ) λ/(h c) dλ  photon-weighted band mean of the quantum efficiency
    QE_c  = peak_qe · S_c(λ) / max_{c,λ} S      (S: camera sensitivities, linearly interpolated,
                                              0 outside their table)

q_ck is integrated exactly for the piecewise-linear S (Simpson on each sub-interval, exact for
the quadratic S·λ), so a band-constant radiance gives the exact electron count.

Signal chain, with R = white − black (DN) and g = gain · conversion_gain (DN per e⁻):

    noise = "poisson":  DN = black + g · min(Poisson(e) + N(0, σ_read²), FW)
    noise = "gaussian": w = g · e / R,   DN = black + R · min(w + N(0, λ_read + λ_shot · w), g FW / R)
    noise = "none":     DN = black + g · min(e, FW)

(noise is drawn around the unsaturated signal and the full well then caps the read-out signal, as
in Yang & Sankaranarayanan 2021, so a saturated pixel reads exactly black + g · FW: the white level
at gain 1 with the default conversion gain)
then DN is rounded to an integer, clipped to [0, white] (never wraps) and stored as uint16; dead
pixels are set to the black level and hot pixels to the white level. The clean mosaic is
black + g · min(e, FW) clipped to [0, white], unquantised (float32).
Brooks et al. 2019 ("Unprocessing images for learned raw denoising") sampling, natural logs:
    log λ_shot ~ U(log 1e-4, log 1.2e-2),  log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²).
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

H_PLANCK_J_S = 6.62607015e-34
C_LIGHT_M_S = 299792458.0
CHANNELS = ("R", "Gr", "Gb", "B")
SITES = ((0, 0), (0, 1), (1, 0), (1, 1))  # (row, col) offsets of R, Gr, Gb, B in the 2 × 2 cell
SITE_COLOUR = (0, 1, 1, 2)  # index into the camera's (R, G, B) sensitivities
BROOKS_LOG_SHOT_RANGE = (math.log(1e-4), math.log(1.2e-2))
BROOKS_READ_SLOPE, BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA = 2.18, 1.20, 0.26
NEGATIVE_TOLERANCE_REL = 1e-4  # negatives above −1e-4 × max|x| are FFT round-off: clamped to 0


class SensorError(ValueError):
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


@dataclass(frozen=True)
class SensorConfig:
    """Every setting of the virtual sensor (defaults: the paper's rig, PHYSICS.md §2, §5).

    Optical/radiometric: pitch_um (1.55), f_number (1.8), exposure_s (0.125 = 8 fps), peak_qe,
    camera (colour-science name or CSV path: header row, wavelength_nm, r, g, b), cos4_falloff and
    focal_length_um (field angle for cos⁴), form ('spectral' or 'per_channel'), gamma_rggb (per-
    channel form only). Electronic: gain (the paper's 1 / 6 / 25), conversion_gain_dn_per_e (None:
    R / full_well_e, so the full well fills the range at gain 1), noise ('poisson', 'gaussian',
    'none'), read_noise_e, full_well_e, lambda_source ('fixed', 'brooks', 'sensor': the Gaussian λ
    equivalent to the photon model), lambda_read / lambda_shot (scalar or per R, Gr, Gb, B),
    brooks_per_channel, bit_depth, black_level_dn, white_level_dn (None: 2^bits − 1),
    dead_fraction, hot_fraction, defect_seed (defects are a property of the sensor: the same map
    for every capture of the same size).
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
    dead_fraction: float = 0.0
    hot_fraction: float = 0.0
    defect_seed: int = 0

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
        _num("dead_fraction", self.dead_fraction, 0, 1)
        _num("hot_fraction", self.hot_fraction, 0, 1 - self.dead_fraction)
        _num("defect_seed", self.defect_seed, 0, 2 ** 63 - 1, integer=True)

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
            if k not in names:
                _fail(k, data[k], f"a known key ({', '.join(names)})")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})

    @property
    def range_dn(self) -> int:
        """R = white − black: the DN span of the signal."""
        return self.white_level_dn - self.black_level_dn

    @property
    def dn_per_electron(self) -> float:
        """g = gain · conversion gain (DN per e⁻)."""
        conv = self.conversion_gain_dn_per_e or self.range_dn / self.full_well_e
        return self.gain * conv


@dataclass(frozen=True)
class Capture:
    """One synthetic capture. mosaic_dn [H, W] uint16 (RGGB), clean_dn [H, W] float32 (noise-free,
    unquantised, saturated like the sensor), packed_dn [4, H/2, W/2] uint16 (R, Gr, Gb, B),
    electrons [H, W] float64 (mean collected e⁻ before the full well), params: every setting, the
    derived constants and the sampled noise parameters (JSON-serialisable)."""
    mosaic_dn: np.ndarray
    clean_dn: np.ndarray
    packed_dn: np.ndarray
    electrons: np.ndarray
    params: dict = field(default_factory=dict)


# ---------------------------------------------------------------- packing


def _check_even(shape, what):
    if len(shape) < 2 or shape[-1] < 2 or shape[-2] < 2 or shape[-1] % 2 or shape[-2] % 2:
        raise SensorError(f"{what}: shape {tuple(shape)}: height and width must be even and ≥ 2 (RGGB 2 × 2 cells)")


def pack_rggb(mosaic: np.ndarray) -> np.ndarray:
    """[..., H, W] RGGB mosaic ──► [..., 4, H/2, W/2] planes (R, Gr, Gb, B); H and W even."""
    m = np.asarray(mosaic)
    _check_even(m.shape, "mosaic")
    return np.stack([m[..., i::2, j::2] for i, j in SITES], axis=-3)


def unpack_rggb(packed: np.ndarray) -> np.ndarray:
    """Exact inverse of pack_rggb: [..., 4, h, w] ──► [..., 2h, 2w]."""
    p = np.asarray(packed)
    if p.ndim < 3 or p.shape[-3] != 4:
        raise SensorError(f"packed RAW: shape {p.shape}: expected [..., 4, h, w] (R, Gr, Gb, B)")
    out = np.empty(p.shape[:-3] + (2 * p.shape[-2], 2 * p.shape[-1]), dtype=p.dtype)
    for c, (i, j) in enumerate(SITES):
        out[..., i::2, j::2] = p[..., c, :, :]
    return out


def site_colour(height_px: int, width_px: int) -> np.ndarray:
    """[H, W] int8: 0 R, 1 Gr, 2 Gb, 3 B (the RGGB convention above)."""
    _check_even((height_px, width_px), "mosaic")
    return np.tile(np.array([[0, 1], [2, 3]], np.int8), (height_px // 2, width_px // 2))


# ---------------------------------------------------------------- radiometry


@functools.lru_cache(maxsize=8)
def _relative_sensitivity(camera: str) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths_nm [M], S [3, M]) with max S = 1 over all channels."""
    from psf.spectral import load_sensitivities
    from psf.engine import PSFError
    try:
        wl, s, _ = load_sensitivities(camera)
    except PSFError as exc:
        raise SensorError(f"sensor.camera = {camera!r}: {exc}") from None
    if s.shape[0] != 3:
        raise SensorError(f"sensor.camera = {camera!r}: {s.shape[0]} channels, expected 3 (r, g, b)")
    if not np.all(np.isfinite(s)) or s.max() <= 0:
        raise SensorError(f"sensor.camera = {camera!r}: sensitivities must be finite with a positive maximum")
    return wl, s / s.max()


def photon_weights(edges_nm, camera: str = "Nikon 5100 (NPL)", peak_qe: float = 1.0) -> np.ndarray:
    """q [3, K] in e⁻ per J: q_ck = (1/Δλ_k) ∫_band QE_c(λ) λ/(h c) dλ (λ in m), so
    electrons = Σ_k E_k A t Δλ_k q_ck. Exact for the linearly interpolated sensitivity (Simpson on
    every sub-interval between table nodes and band edges; S·λ is quadratic there)."""
    wl, s = _relative_sensitivity(camera)
    edges = np.asarray(edges_nm, float)
    out = np.zeros((3, edges.size - 1))
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        a_in, b_in = max(a, wl[0]), min(b, wl[-1])  # S = 0 outside the table (a jump at its ends)
        if a_in >= b_in:
            continue
        x = np.unique(np.concatenate([[a_in, b_in], wl[(wl > a_in) & (wl < b_in)]]))
        lo, hi, mid = x[:-1], x[1:], 0.5 * (x[:-1] + x[1:])
        for c in range(3):
            f = lambda z: np.interp(z, wl, s[c], left=0.0, right=0.0) * z  # noqa: E731
            out[c, k] = np.sum((hi - lo) / 6 * (f(lo) + 4 * f(mid) + f(hi))) / (b - a)
    return out * peak_qe * 1e-9 / (H_PLANCK_J_S * C_LIGHT_M_S)


def _check_finite(a: np.ndarray, what: str) -> tuple[np.ndarray, int]:
    """Reject NaN/inf and real negatives; clamp round-off negatives. Returns (array, n_clamped)."""
    bad = ~np.isfinite(a)
    if bad.any():
        raise SensorError(f"{what}: {int(bad.sum())} NaN or infinite values (first at index "
                          f"{tuple(int(i) for i in np.argwhere(bad)[0])}); the sensor needs finite input")
    lo = float(a.min()) if a.size else 0.0
    if lo >= 0:
        return a, 0
    scale = float(np.abs(a).max())
    if lo < -NEGATIVE_TOLERANCE_REL * scale:
        raise SensorError(f"{what}: negative value {lo:g} (max |x| {scale:g}); only round-off negatives "
                          f"≥ −{NEGATIVE_TOLERANCE_REL:g} × max|x| are accepted (clamped to 0)")
    neg = a < 0
    return np.where(neg, 0, a), int(neg.sum())


def _bin(a: np.ndarray, input_pitch_um: float | None, pitch_um: float, what: str) -> tuple[np.ndarray, int]:
    """Block-mean of a render at pitch/s to the sensor pitch (s integer)."""
    if input_pitch_um is None:
        return a, 1
    s = pitch_um / input_pitch_um
    if not (input_pitch_um > 0 and abs(s - round(s)) < 1e-6 and round(s) >= 1):
        raise SensorError(f"{what}: input_pitch_um = {input_pitch_um!r}: must be the sensor pitch "
                          f"{pitch_um} µm divided by an integer")
    s = int(round(s))
    if s == 1:
        return a, 1
    if a.shape[-1] % s or a.shape[-2] % s:
        raise SensorError(f"{what}: shape {a.shape} not divisible by the binning factor {s}")
    k, h, w = a.shape
    return a.reshape(k, h // s, s, w // s, s).mean(axis=(2, 4), dtype=np.float64), s


def cos4_map(height_px: int, width_px: int, pitch_um: float, focal_length_um: float) -> np.ndarray:
    """cos⁴θ = 1 / (1 + r²/f²)² at pixel centres, r from the mosaic centre."""
    y = (np.arange(height_px) + 0.5 - height_px / 2) * pitch_um
    x = (np.arange(width_px) + 0.5 - width_px / 2) * pitch_um
    return 1.0 / (1.0 + (y[:, None] ** 2 + x[None, :] ** 2) / focal_length_um ** 2) ** 2


def band_electron_weights(edges_nm, sensor: SensorConfig) -> np.ndarray:
    """[3, K] electrons per pixel per unit band radiance (W·sr⁻¹·m⁻²·nm⁻¹) of band k in channel c:
    π/(4N²) · A · t · Δλ_k · q_ck (on-axis, no cos⁴)."""
    edges = np.asarray(edges_nm, float)
    area_m2 = (sensor.pitch_um * 1e-6) ** 2
    const = math.pi / (4 * sensor.f_number ** 2) * area_m2 * sensor.exposure_s
    return photon_weights(edges, sensor.camera, sensor.peak_qe) * np.diff(edges)[None, :] * const


def electrons_rgb(radiance_bands: np.ndarray, edges_nm, sensor: SensorConfig) -> np.ndarray:
    """[3, H, W] mean electrons that an R, G and B pixel would collect at every pixel (the
    demosaic-free camera RGB used as ground truth; no noise, no full well, cos⁴ if enabled)."""
    L = np.asarray(radiance_bands)
    L, _ = _check_finite(L, "radiance_bands")
    w = band_electron_weights(edges_nm, sensor)
    e = np.einsum("ck,khw->chw", w, L, dtype=np.float64, optimize=True)
    if sensor.cos4_falloff:
        e *= cos4_map(*e.shape[1:], sensor.pitch_um, sensor.focal_length_um)
    return e


def electrons_spectral(radiance_bands: np.ndarray, edges_nm, sensor: SensorConfig,
                       input_pitch_um: float | None = None) -> np.ndarray:
    """Mean collected electrons [H, W] (float64, no noise, no full well) of an RGGB mosaic from
    band-mean radiance [K, H, W] (W·sr⁻¹·m⁻²·nm⁻¹): e = Σ_k π L_k/(4N²) [cos⁴θ] A t Δλ_k q_ck."""
    L = np.asarray(radiance_bands)
    edges = np.asarray(edges_nm, float)
    if L.ndim != 3 or edges.ndim != 1 or edges.size != L.shape[0] + 1:
        raise SensorError(f"radiance_bands: shape {L.shape} with {edges.size} edges: expected [K, H, W] and K + 1 edges")
    if not (np.all(np.isfinite(edges)) and np.all(edges > 0) and np.all(np.diff(edges) > 0)):
        raise SensorError(f"edges_nm = {edges.tolist()}: expected increasing positive finite wavelengths")
    L, _ = _check_finite(L, "radiance_bands")
    L, _ = _bin(L, input_pitch_um, sensor.pitch_um, "radiance_bands")
    _check_even(L.shape, "radiance_bands")
    w = band_electron_weights(edges, sensor)
    h, wd = L.shape[1:]
    e = np.zeros((h, wd))
    for c, (i, j) in enumerate(SITES):
        acc = e[i::2, j::2]
        for k in np.nonzero(w[SITE_COLOUR[c]])[0]:
            acc += w[SITE_COLOUR[c], k] * L[k, i::2, j::2]
    if sensor.cos4_falloff:
        e *= cos4_map(h, wd, sensor.pitch_um, sensor.focal_length_um)
    return e


def electrons_per_channel(rgb: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """The paper's form y = γ_c x_c: electrons [H, W] = γ_c x_c · R / conversion_gain from a linear
    [3, H, W] image (x = 1 at γ = 1 fills the full well with the default conversion gain)."""
    x = np.asarray(rgb)
    if x.ndim != 3 or x.shape[0] != 3:
        raise SensorError(f"rgb: shape {x.shape}: expected [3, H, W] (R, G, B) for the per-channel form")
    x, _ = _check_finite(x, "rgb")
    _check_even(x.shape, "rgb")
    per_e = sensor.dn_per_electron / sensor.gain / sensor.range_dn  # normalised units per e⁻ at gain 1
    e = np.empty(x.shape[1:])
    for c, (i, j) in enumerate(SITES):
        e[i::2, j::2] = sensor.gamma_rggb[c] * x[SITE_COLOUR[c], i::2, j::2] / per_e
    if sensor.cos4_falloff:
        e *= cos4_map(*e.shape, sensor.pitch_um, sensor.focal_length_um)
    return e


# ---------------------------------------------------------------- noise


def sample_brooks(rng: np.random.Generator, size=None) -> tuple[np.ndarray, np.ndarray]:
    """(λ_read, λ_shot) from Brooks et al. 2019: log λ_shot ~ U(log 1e-4, log 1.2e-2),
    log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²) (natural logs; normalised [0, 1] units)."""
    log_shot = rng.uniform(*BROOKS_LOG_SHOT_RANGE, size=size)
    log_read = rng.normal(BROOKS_READ_SLOPE * log_shot + BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA)
    return np.exp(log_read), np.exp(log_shot)


def sensor_lambdas(sensor: SensorConfig) -> tuple[float, float]:
    """(λ_read, λ_shot) of the Gaussian model equivalent to the photon model in normalised units:
    λ_shot = g / R, λ_read = (g σ_read / R)² (quantisation excluded)."""
    u = sensor.dn_per_electron / sensor.range_dn
    return (u * sensor.read_noise_e) ** 2, u


def noise_lambdas(sensor: SensorConfig, rng: np.random.Generator) -> tuple[tuple, tuple]:
    """Per-channel (λ_read[4], λ_shot[4]) for the Gaussian model, drawn from rng when 'brooks'."""
    if sensor.lambda_source == "fixed":
        return sensor.lambda_read, sensor.lambda_shot
    if sensor.lambda_source == "sensor":
        r, s = sensor_lambdas(sensor)
        return (r,) * 4, (s,) * 4
    r, s = sample_brooks(rng, 4 if sensor.brooks_per_channel else 1)
    r, s = (np.repeat(r, 4), np.repeat(s, 4)) if r.size == 1 else (r, s)
    return tuple(float(v) for v in r), tuple(float(v) for v in s)


def defect_map(height_px: int, width_px: int, sensor: SensorConfig) -> np.ndarray:
    """[H, W] int8: 0 good, 1 dead (reads black), 2 hot (reads white); round(f · H · W) of each,
    drawn without replacement from default_rng(defect_seed), independent of the noise generator."""
    out = np.zeros((height_px, width_px), np.int8)
    n = height_px * width_px
    n_dead, n_hot = round(sensor.dead_fraction * n), round(sensor.hot_fraction * n)
    if n_dead + n_hot:
        idx = np.random.default_rng(sensor.defect_seed).choice(n, n_dead + n_hot, replace=False)
        out.flat[idx[:n_dead]] = 1
        out.flat[idx[n_dead:]] = 2
    return out


def _to_dn(signal_dn: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """Round to integer DN, clip to [0, white] (no wrap) and cast to uint16 (in place on float64)."""
    np.rint(signal_dn, out=signal_dn)
    np.clip(signal_dn, 0, sensor.white_level_dn, out=signal_dn)
    return signal_dn.astype(np.uint16)


def expose(electrons: np.ndarray, sensor: SensorConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict]:
    """Mean electrons [H, W] ──► (mosaic uint16, clean float32, sampled-noise params). See module doc."""
    e = np.asarray(electrons, dtype=np.float64)
    if not np.all(np.isfinite(e)):  # overflow of huge but finite radiance: saturate, never NaN
        e = np.nan_to_num(e, nan=0.0, posinf=np.finfo(np.float64).max)
    _check_even(e.shape, "electrons")
    g, black, rng_dn = sensor.dn_per_electron, sensor.black_level_dn, sensor.range_dn
    fw = sensor.full_well_e
    charge = np.minimum(e, fw)
    clean = np.clip(black + g * charge, 0, sensor.white_level_dn).astype(np.float32)
    info: dict = {"noise": sensor.noise}
    if sensor.noise == "poisson":
        # Poisson(λ) + read noise ≥ FW for λ ≥ cap with probability 1 − e^(−hundreds): the cap only
        # avoids numpy's limit on λ (and overflow); the clipped result is the same.
        cap = 2 * fw + 100 + 40 * sensor.read_noise_e
        n = rng.poisson(np.minimum(e, cap)).astype(np.float64)
        if sensor.read_noise_e > 0:
            n += rng.normal(0.0, sensor.read_noise_e, size=n.shape)
        np.minimum(n, fw, out=n)
        sig = black + g * n
        info.update(read_noise_e=sensor.read_noise_e, full_well_e=fw)
    elif sensor.noise == "gaussian":
        lam_read, lam_shot = noise_lambdas(sensor, rng)
        # Noise around the unsaturated signal, then the full-well clip (as in the photon model), so a
        # saturated pixel reads exactly g·FW. The cap keeps w finite and lies ≥ 40 σ above g·FW / R.
        w_fw = g * fw / rng_dn
        cap = 2 * w_fw + 1600 * max(lam_shot) + 40 * math.sqrt(max(lam_read))
        w = np.minimum(g * e / rng_dn, cap)
        var = np.empty_like(w)
        for c, (i, j) in enumerate(SITES):
            var[i::2, j::2] = lam_read[c] + lam_shot[c] * w[i::2, j::2]
        y = w + rng.standard_normal(w.shape) * np.sqrt(var)
        sig = black + rng_dn * np.minimum(y, g * fw / rng_dn, out=y)
        info.update(lambda_source=sensor.lambda_source, lambda_read=list(lam_read), lambda_shot=list(lam_shot))
    else:
        sig = black + g * charge
    mosaic = _to_dn(sig, sensor)
    defects = defect_map(*mosaic.shape, sensor)
    mosaic[defects == 1] = black
    mosaic[defects == 2] = sensor.white_level_dn
    info.update(dead_pixels=int((defects == 1).sum()), hot_pixels=int((defects == 2).sum()))
    return mosaic, clean, info


# ---------------------------------------------------------------- the capture


def capture(image: np.ndarray, edges_nm, sensor: SensorConfig, rng: np.random.Generator,
            input_pitch_um: float | None = None) -> Capture:
    """Synthesise one RAW capture.

    image: [K, H, W] band-mean radiance (W·sr⁻¹·m⁻²·nm⁻¹) with edges_nm [K + 1] when
    sensor.form == 'spectral'; [3, H, W] linear RGB (edges_nm ignored, may be None) when
    'per_channel'. input_pitch_um: the image's pitch when it is the sensor pitch / an integer
    (block-mean binning; spectral form); None: already at the sensor pitch. H, W even.
    rng: the generator for the noise (its state before the draws is recorded in params).
    """
    if not isinstance(rng, np.random.Generator):
        raise SensorError(f"rng: {type(rng).__name__}: expected a numpy.random.Generator")
    state = rng.bit_generator.state
    img = np.asarray(image)
    if sensor.form == "spectral":
        e = electrons_spectral(img, edges_nm, sensor, input_pitch_um)
    else:
        e = electrons_per_channel(img, sensor)
    clamped = int((img < 0).sum())  # input already checked finite; these were round-off, set to 0
    mosaic, clean, info = expose(e, sensor, rng)
    params = {
        "sensor": dataclasses.asdict(sensor),
        "bayer": "RGGB: R (0,0), Gr (0,1), Gb (1,0), B (1,1); packed order R, Gr, Gb, B",
        "form": sensor.form,
        "input_shape": list(img.shape),
        "input_pitch_um": input_pitch_um,
        "edges_nm": None if edges_nm is None or sensor.form != "spectral" else np.asarray(edges_nm, float).tolist(),
        "dn_per_electron": sensor.dn_per_electron,
        "range_dn": sensor.range_dn,
        "negative_values_clamped": clamped,
        "rng_state_before": state,
        **info,
    }
    if sensor.form == "spectral":
        params["photon_weights_e_per_J"] = photon_weights(edges_nm, sensor.camera, sensor.peak_qe).tolist()
        params["irradiance"] = "E = pi L / (4 N^2)" + (" cos^4" if sensor.cos4_falloff else "") + " (on-axis)"
    return Capture(mosaic, clean, pack_rggb(mosaic), e, params)
