"""Displays in front of the camera: pixel layout, display-to-lens gap, spectral transmission, gain.

A display is what the PSF engine needs (a psf layout, or None for the bare lens) plus what the
optics and sensor need: the spectral transmission T(λ) of the stack apart from the layout's
openings (substrate, encapsulation, polariser; the openings' own power loss is the kernel set's
``transmittance``) and the sensor gain the paper used behind it.

Presets (docs/PHYSICS.md §2):

- ``glass``: the clean capture, a thin glass panel of the display's thickness: bare-lens kernels,
  T = 1, gain 1.
- ``toled``: stripe layout (open area 21 %), flat T, gain 6. T is set so that the virtual γ
  calibration gives the paper's γ = 0.97 in every channel: γ = gain · T · transmittance · (1 −
  energy outside) relative to glass, so T = 0.97 / (6 · 0.21 · …) ≈ 0.79.
- ``poled``: pentile layout (open area 23 %), gain 25, and the stack of a flexible OLED (the paper,
  l.116: "a poly-amide substrate … may make the images … appear yellow"): T(λ) = scale ·
  10^(−A(λ)) · T_cathode(λ) (``Transmission`` kind 'polyimide'), with scale, the absorbance edge and
  the cathode thickness fitted (``fit_poled_transmission``) so that γ = 0.34/0.34/0.34/0.20 (R, Gr,
  Gb, B) exactly, as the paper measured. No monotonic edge alone can do it: bringing B to 0.59 of R
  also cuts G's blue tail (best 0.344/0.335/0.200); the thin metal cathode, which transmits less
  towards the red, lifts G against R. The paper's 2.9 % transmission (a spectrophotometer, l.114)
  disagrees with its own γ and gain (0.029 × 25 = 0.73, not 0.34); we reproduce γ (what the captures
  show), which implies 1.2 % through the whole stack (τ · mean T; ``study realism`` reports it).

A display file (TOML) describes any other display, and a micrograph image is a display of that
layout; ``load_display`` reads every command's --display (scenes/README.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from psf import MicrographLayout, layouts
from udc_render.errors import UdcError
from udc_render.io.files import read_toml
from udc_render.optics.gamma import channel_gamma, white_weights

PAPER_GAMMA = {"glass": (1.0, 1.0, 1.0), "toled": (0.97, 0.97, 0.97), "poled": (0.34, 0.34, 0.20)}
PAPER_GAIN = {"glass": 1.0, "toled": 6.0, "poled": 25.0}
PRESETS = ("glass", "toled", "poled")
MICROGRAPH_SUFFIXES = (".png", ".tif", ".tiff", ".exr")
ALLOWED = (f"glass (or none), toled, poled, a display file (.toml) or a micrograph image "
           f"({'/'.join(MICROGRAPH_SUFFIXES)})")
TRANSMISSION_TYPES = ("flat", "edge", "polyimide", "csv")

# Fitted by fit_toled_transmission / fit_poled_transmission for the default rig (monitor white D65,
# Nikon 5100 (NPL), 30 bands of 10 nm, 511-px kernels at 1.55 µm, with the far field the γ calibration's white
# square collects: calibration.fit_gains); tests/udc_render/test_synth.py re-fits them.
TOLED_T = 0.78566
# P-OLED: the Urbach width is not fitted (the γ fix three numbers): 20 nm, the blue edge of a yellow
# aromatic polyimide film (DuPont Kapton HN data sheet: ~0 at 450 nm to ~0.5 at 550 nm, 25 µm film).
# Every width from 8 to 30 nm fits the γ exactly (study realism); T(450 nm) then spans 0.1–1.9 %.
POLED_URBACH_WIDTH_NM = 20.0
POLED_SCALE, POLED_EDGE_NM, POLED_CATHODE_NM = 0.112792, 444.308, 12.3775
SILVER_PLASMA_WAVELENGTH_NM = 137.9  # ħω_p = 9.0 eV (Ordal et al., Appl. Opt. 22, 1099, 1983)
STACK_INDEX = 1.5  # the dielectrics on both sides of the cathode (organic layers, encapsulation)


class DisplayError(UdcError):
    """A bad display name or display file; one line naming the file, key, value and what is allowed."""


def thin_metal_transmission(wavelength_nm, thickness_nm: float) -> np.ndarray:
    """Power transmission of a silver film much thinner than the wavelength between two media of index n
    (Tinkham's thin-film formula, Phys. Rev. 104, 845, 1956): T = |1 + Z0 σ_s / 2n|⁻², with the Drude
    sheet conductance above the collision rate, Z0 σ_s = i 2π d λ / λ_p² (λ_p: plasma wavelength).
    It falls towards the red: T(450 nm) = 0.73, T(650 nm) = 0.56 for d = 12.4 nm."""
    x = 2.0 * np.pi * thickness_nm * np.asarray(wavelength_nm, float) / SILVER_PLASMA_WAVELENGTH_NM ** 2
    return 1.0 / (1.0 + (x / (2.0 * STACK_INDEX)) ** 2)


@dataclass(frozen=True)
class Transmission:
    """Spectral transmission T(λ) of the display stack (dimensionless, 0..1)."""
    kind: str = "flat"
    value: float = 1.0  # flat
    scale: float = 1.0  # edge: scale · (floor + (1 − floor) · logistic((λ − edge_nm) / width_nm))
    edge_nm: float = 480.0
    width_nm: float = 20.0
    floor: float = 0.0
    urbach_width_nm: float = POLED_URBACH_WIDTH_NM  # polyimide: scale · 10^(−exp(−(λ − edge_nm)/w)) · T_cathode
    cathode_nm: float = 0.0
    table_nm: tuple = ()  # csv: wavelengths and values, linear interpolation, ends held
    table_t: tuple = ()
    source: str = ""

    def __call__(self, wavelengths_nm) -> np.ndarray:
        wl = np.asarray(wavelengths_nm, dtype=np.float64)
        if self.kind == "flat":
            return np.full(wl.shape, self.value)
        if self.kind == "edge":
            logistic = 0.5 * (1.0 + np.tanh(0.5 * (wl - self.edge_nm) / self.width_nm))  # overflow-free
            return self.scale * (self.floor + (1.0 - self.floor) * logistic)
        if self.kind == "polyimide":
            absorbance = np.exp(-(wl - self.edge_nm) / self.urbach_width_nm)
            return self.scale * 10.0 ** (-absorbance) * thin_metal_transmission(wl, self.cathode_nm)
        return np.interp(wl, np.asarray(self.table_nm), np.asarray(self.table_t))

    def band_means(self, edges_nm, samples_per_band: int = 16) -> np.ndarray:
        """Mean of T over each band (midpoint rule with samples_per_band points)."""
        e = np.asarray(edges_nm, float)
        u = (np.arange(samples_per_band) + 0.5) / samples_per_band
        pts = e[:-1, None] + np.diff(e)[:, None] * u[None, :]
        return self(pts).mean(axis=1)

    def describe(self) -> dict:
        if self.kind == "flat":
            return {"type": "flat", "value": self.value}
        if self.kind == "edge":
            return {"type": "edge", "scale": self.scale, "edge_nm": self.edge_nm, "width_nm": self.width_nm,
                    "floor": self.floor, "formula": "scale (floor + (1 - floor) / (1 + exp(-(l - edge) / width)))"}
        if self.kind == "polyimide":
            return {"type": "polyimide", "scale": self.scale, "edge_nm": self.edge_nm,
                    "urbach_width_nm": self.urbach_width_nm, "cathode_nm": self.cathode_nm,
                    "formula": "scale 10^(-exp(-(l - edge)/w)) / (1 + (pi d l / (n lp^2))^2)"}
        return {"type": "csv", "file": self.source, "wavelength_nm": list(self.table_nm), "t": list(self.table_t)}


@dataclass(frozen=True)
class Display:
    """A display (or the glass panel) in front of the lens."""
    name: str
    layout: object | None  # a psf layout; None: bare lens (glass)
    transmission: Transmission = field(default_factory=Transmission)
    gain: float = 1.0
    distance_mm: float = 0.0
    source: str = "preset"

    @property
    def is_glass(self) -> bool:
        return self.layout is None

    def describe(self) -> dict:
        return {"name": self.name, "source": self.source, "distance_mm": self.distance_mm, "gain": self.gain,
                "layout": None if self.layout is None else self.layout.describe(),
                "transmission": self.transmission.describe()}

    def with_distance(self, distance_mm: float) -> "Display":
        return replace(self, distance_mm=float(distance_mm))


def preset(name: str) -> Display:
    if name == "glass":
        return Display("glass", None, Transmission("flat", 1.0), PAPER_GAIN["glass"])
    if name == "toled":
        return Display("toled", layouts.toled(), Transmission("flat", TOLED_T), PAPER_GAIN["toled"])
    if name == "poled":
        return Display("poled", layouts.poled(), poled_transmission(), PAPER_GAIN["poled"])
    raise DisplayError(f"--display = {name!r}: expected {ALLOWED}")


def poled_transmission(scale=POLED_SCALE, edge_nm=POLED_EDGE_NM, cathode_nm=POLED_CATHODE_NM,
                       urbach_width_nm=POLED_URBACH_WIDTH_NM) -> Transmission:
    """The P-OLED stack: polyimide Urbach edge × thin silver cathode × a flat rest (module doc)."""
    return Transmission("polyimide", scale=scale, edge_nm=edge_nm, urbach_width_nm=urbach_width_nm,
                        cathode_nm=cathode_nm)


def load_display(spec: str, **micrograph) -> Display:
    """The one vocabulary of every command's --display: a preset (glass, or none: the bare lens; toled;
    poled), a display TOML file (scenes/README.md, 'Display files') or a micrograph image
    (``micrograph_display``; `micrograph`: its keyword arguments)."""
    if spec in PRESETS or spec == "none":
        return preset("glass" if spec == "none" else spec)
    path = Path(spec)
    suffix = path.suffix.lower()
    if suffix != ".toml" and suffix not in MICROGRAPH_SUFFIXES:
        raise DisplayError(f"--display = {spec!r}: expected {ALLOWED}")
    if not path.is_file():
        raise DisplayError(f"--display = {spec!r}: no such file; expected {ALLOWED}")
    if suffix == ".toml":
        return parse_display(read_toml(path, DisplayError, "display file"), path)
    return micrograph_display(path, **micrograph)


def display_name(spec: str) -> str:
    """The name a --display has in a dataset (train, evaluate): a preset's, a display file's [display] name
    or a micrograph's file stem (load_display's names, without building the layout or reading an image);
    any other word is taken as a dataset's display name as it is."""
    if spec == "none":
        return "glass"
    path = Path(spec)
    suffix = path.suffix.lower()
    if suffix not in (".toml", *MICROGRAPH_SUFFIXES):
        return spec
    if not path.is_file():
        raise DisplayError(f"--display = {spec!r}: no such file; expected {ALLOWED}")
    if suffix == ".toml":
        return _document_name(read_toml(path, DisplayError, "display file"), path)
    return micrograph_name(path)


def micrograph_name(path: Path) -> str:
    """A micrograph display's name: its file's stem (one without spaces)."""
    if " " in path.stem:
        raise DisplayError(f"--display = {str(path)!r}: a micrograph display is named by its file's stem: expected "
                           "a file name without spaces")
    return path.stem


def micrograph_display(path: Path, pixel_um: float = 1.0, values: str = "amplitude", random_rotation: bool = False,
                       seed: int = 0, flip: bool = False) -> Display:
    """A transmission micrograph as a display, named by the file's stem: what a display file with only
    ``[display.layout] type = "micrograph"`` gives (T = 1, gain 1, d = 0), with the tile's pixel size,
    values, random tile rotation and mirror (flip) of ``psf.MicrographLayout.load``."""
    name = micrograph_name(path)
    layout = MicrographLayout.load(path, pixel_um, values, random_rotation, seed, flip)
    return Display(name, layout, Transmission("flat", 1.0), 1.0, 0.0, source=str(path))


def load_displays(specs: str, distance_mm: float | None = None) -> list[Display]:
    """Glass first, then each display of the comma-separated `specs` (load_display) once, with
    the display-to-lens distance override applied to all but glass."""
    names = [t.strip() for t in specs.split(",") if t.strip()]
    if not names:
        raise DisplayError(f"--display = {specs!r}: expected comma-separated displays, each {ALLOWED}")
    out = [load_display("glass")]
    for n in names:
        d = load_display(n)
        if not d.is_glass:
            out.append(d if distance_mm is None else d.with_distance(distance_mm))
    return out


_LAYOUT_KEYS = {"toled": ("pitch_um", "open_fraction", "slit_height_fraction"),
                "poled": ("pitch_um", "open_fraction", "small_to_large"),
                "micrograph": ("file", "pixel_um", "values", "tile_rotation", "tile_seed", "tile_flip",
                               "tile_arrangement")}
_TOP_KEYS = ("name", "layout", "distance_mm", "gain", "transmission")


def _fail(path, key, value, allowed):
    raise DisplayError(f"{path}: {key} = {value!r}: expected {allowed}")


def _number(path, table: dict, key: str, prefix: str, lo: float, hi: float, default=None, lo_open=False):
    if key not in table:
        if default is None:
            _fail(path, prefix + key, None, f"a number in [{lo:g}, {hi:g}]")
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or not ((v > lo) if lo_open else (v >= lo)) or v > hi:
        _fail(path, prefix + key, v, f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}]")
    return float(v)


def _check_keys(path, table, allowed, prefix):
    if not isinstance(table, dict):
        _fail(path, prefix.rstrip("."), table, "a table")
    for k in table:
        if k not in allowed:
            _fail(path, prefix + k, table[k], f"a known key ({', '.join(allowed)})")


def _document_name(data: dict, path: Path) -> str:
    """A display document's [display] name (default: the file's stem), its top-level keys checked."""
    _check_keys(path, data, ("display",), "")
    d = data.get("display")
    if d is None:
        _fail(path, "display", None, "a [display] table")
    _check_keys(path, d, _TOP_KEYS, "display.")
    name = d.get("name", path.stem)
    if not isinstance(name, str) or not name or any(c in name for c in "/\\ "):
        _fail(path, "display.name", name, "a non-empty name without spaces or slashes")
    return name


def parse_display(data: dict, path: Path) -> Display:
    """Validate a display document: [display] name, layout {type, …}, distance_mm, gain, transmission."""
    name = _document_name(data, path)
    d = data["display"]
    lay = d.get("layout")
    kind = lay.get("type") if isinstance(lay, dict) else None
    if kind not in _LAYOUT_KEYS:
        _fail(path, "display.layout.type", kind, "one of " + ", ".join(_LAYOUT_KEYS))
    _check_keys(path, lay, ("type",) + _LAYOUT_KEYS[kind], "display.layout.")
    p = "display.layout."
    try:
        if kind == "micrograph":
            f = lay.get("file")
            if not isinstance(f, str):
                _fail(path, p + "file", f, "the path of a PNG/TIFF/EXR transmission image")
            fp = Path(f) if Path(f).is_absolute() else path.parent / f
            if not fp.is_file():
                _fail(path, p + "file", f, f"an existing image file (no {fp})")
            values = lay.get("values", "amplitude")
            if values not in ("amplitude", "intensity"):
                _fail(path, p + "values", values, "amplitude or intensity")
            rotation, seed = lay.get("tile_rotation", False), lay.get("tile_seed", 0)
            if not isinstance(rotation, bool):
                _fail(path, p + "tile_rotation", rotation, "true or false")
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                _fail(path, p + "tile_seed", seed, "a non-negative integer")
            flip = lay.get("tile_flip", False)
            if not isinstance(flip, bool) or flip and not rotation:
                _fail(path, p + "tile_flip", flip, "true or false; true mirrors the turned tiles at random (D4) and "
                      "needs tile_rotation = true")
            layout = MicrographLayout.load(fp, _number(path, lay, "pixel_um", p, 0, 1e4, 1.0, lo_open=True), values,
                                           rotation, seed, flip, lay.get("tile_arrangement"))
        else:
            factory = layouts.toled if kind == "toled" else layouts.poled
            kw = {k: _number(path, lay, k, p, 0, 1e4, lo_open=True) for k in _LAYOUT_KEYS[kind] if k in lay}
            layout = factory(**kw)
    except layouts.LayoutError as e:
        raise DisplayError(f"{path}: display.layout: {e}") from None
    t = d.get("transmission", {"type": "flat", "value": 1.0})
    tkind = t.get("type") if isinstance(t, dict) else None
    if tkind not in TRANSMISSION_TYPES:
        _fail(path, "display.transmission.type", tkind, "one of " + ", ".join(TRANSMISSION_TYPES))
    p = "display.transmission."
    if tkind == "flat":
        _check_keys(path, t, ("type", "value"), p)
        trans = Transmission("flat", _number(path, t, "value", p, 0, 1, lo_open=True))
    elif tkind == "edge":
        _check_keys(path, t, ("type", "scale", "edge_nm", "width_nm", "floor"), p)
        trans = Transmission("edge", scale=_number(path, t, "scale", p, 0, 1, lo_open=True),
                             edge_nm=_number(path, t, "edge_nm", p, 200, 1200),
                             width_nm=_number(path, t, "width_nm", p, 0.1, 1000),
                             floor=_number(path, t, "floor", p, 0, 1, 0.0))
    elif tkind == "polyimide":
        _check_keys(path, t, ("type", "scale", "edge_nm", "urbach_width_nm", "cathode_nm"), p)
        trans = poled_transmission(_number(path, t, "scale", p, 0, 1, lo_open=True),
                                   _number(path, t, "edge_nm", p, 200, 1200),
                                   _number(path, t, "cathode_nm", p, 0, 100, 0.0),
                                   _number(path, t, "urbach_width_nm", p, 0.1, 1000, POLED_URBACH_WIDTH_NM))
    else:
        _check_keys(path, t, ("type", "file"), p)
        trans = _transmission_csv(path, t.get("file"))
    return Display(name=name, layout=layout, transmission=trans,
                   gain=_number(path, d, "gain", "display.", 0, 1e6, 1.0, lo_open=True),
                   distance_mm=_number(path, d, "distance_mm", "display.", 0, 1e4, 0.0), source=str(path))


def _transmission_csv(path: Path, file) -> Transmission:
    key = "display.transmission.file"
    if not isinstance(file, str):
        _fail(path, key, file, "a CSV file of wavelength_nm,t")
    fp = Path(file) if Path(file).is_absolute() else path.parent / file
    try:
        lines = [ln for ln in fp.read_text().splitlines() if ln.strip()]
    except OSError:
        _fail(path, key, file, f"an existing CSV file (cannot read {fp})")
    rows = []
    for i, ln in enumerate(lines):
        try:
            rows.append([float(x) for x in ln.split(",")])
        except ValueError:
            if i == 0:
                continue  # header
            _fail(path, key, file, f"numeric rows wavelength_nm,t (line {i + 1}: {ln!r})")
    a = np.asarray(rows, float)
    if a.ndim != 2 or a.shape[0] < 2 or a.shape[1] != 2 or np.any(np.diff(a[:, 0]) <= 0) \
            or not np.all(np.isfinite(a)) or np.any(a[:, 1] < 0) or np.any(a[:, 1] > 1):
        _fail(path, key, file, "≥ 2 rows wavelength_nm,t with increasing wavelengths and 0 ≤ t ≤ 1")
    return Transmission("csv", table_nm=tuple(a[:, 0]), table_t=tuple(a[:, 1]), source=str(fp))


# ---------------------------------------------------------------- the presets' T(λ) fitted to the paper's γ


def fit_toled_transmission(display_gain_k, glass_gain_k, edges_nm, camera="Nikon 5100 (NPL)",
                           target=PAPER_GAMMA["toled"][1], gain=PAPER_GAIN["toled"]) -> float:
    """Flat T giving γ_G = target (γ is linear in T; optics.gamma)."""
    w = white_weights(edges_nm, camera)
    unit = Display("t", layouts.toled(), Transmission("flat", 1.0), gain)
    return float(target / channel_gamma(w, unit, display_gain_k, glass_gain_k, edges_nm)[1])


def fit_poled_transmission(display_gain_k, glass_gain_k, edges_nm, camera="Nikon 5100 (NPL)",
                           target=PAPER_GAMMA["poled"], gain=PAPER_GAIN["poled"], layout=None,
                           urbach_width_nm=POLED_URBACH_WIDTH_NM) -> tuple[float, float, float]:
    """(scale, edge_nm, cathode_nm) of the polyimide T(λ) giving γ (R, G, B) = target (least squares on
    the relative errors; three numbers, three unknowns: an exact solve where one exists)."""
    from scipy.optimize import least_squares
    w = white_weights(edges_nm, camera)
    layout = layout or layouts.poled()

    def rel_error(p):
        d = Display("p", layout, poled_transmission(p[0], p[1], p[2], urbach_width_nm), gain)
        return channel_gamma(w, d, display_gain_k, glass_gain_k, edges_nm) / np.asarray(target) - 1.0

    fit = least_squares(rel_error, [0.1, 450.0, 10.0], bounds=([1e-4, 300.0, 0.0], [1.0, 700.0, 100.0]),
                        x_scale=[0.1, 10.0, 10.0], xtol=1e-12, ftol=1e-12)
    return float(fit.x[0]), float(fit.x[1]), float(fit.x[2])
