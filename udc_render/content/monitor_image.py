"""What the virtual monitor shows: any image file, a built-in image or a test pattern, as the
panel's linear drive levels [3, rows, cols] in [0, 1] at the panel's resolution.

As in the paper's MCIS, an image is shown full screen with its aspect ratio kept: a portrait image
is rotated a quarter turn to landscape on a landscape panel, then resized to fit inside the panel
(area-averaging when shrinking), centred, with black bars where the aspects differ. The panel
applies its transfer function (sRGB by default) to the file's code values; the drive levels drive
the panel's own primaries, as a monitor without colour management does.
"""
from __future__ import annotations

import importlib.util
import math
import warnings
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import png  # pypng: exact 16-bit decoding

from udc_render.content import charts
from udc_render.content.resample import resample, resize_matrix
from udc_render.errors import UdcError

# scikit-image's samples (skimage.data's function names) and their files in its data folder, which those functions
# read (skimage.data._fetchers): read here with imageio without importing skimage.data and skimage.io (0.3 s a
# process; the same pixels, tested)
BUILTIN_FILES = {"astronaut": "astronaut.png", "coffee": "coffee.png", "chelsea": "chelsea.png",
                 "rocket": "rocket.jpg", "camera": "camera.png", "immunohistochemistry": "ihc.png"}
BUILTIN_IMAGES = tuple(BUILTIN_FILES)
PATTERNS = ("checker", "white", "grid", "orientation")
CHARTS = {  # name: (function(cols, rows, arg), argument type, default argument)
    "slanted_edge": (charts.slanted_edge, float, 5.0),
    "sine_x": (lambda c, r, n: charts.sine(c, r, n, "x"), float, 64.0),
    "sine_y": (lambda c, r, n: charts.sine(c, r, n, "y"), float, 64.0),
    "siemens": (charts.siemens, int, 72),
    "dead_leaves": (charts.dead_leaves, int, 0),
    "dead_leaves_colour": (lambda c, r, seed: charts.dead_leaves_colour(c, r, seed, photo_palette(seed)), int, 1),
}
PATTERN_ARGS = {"slanted_edge": "ANGLE_DEG (0 to 45)", "sine_x": "CYCLES", "sine_y": "CYCLES",
                "siemens": "SPOKES", "dead_leaves": "SEED", "dead_leaves_colour": "SEED"}
COLOUR_PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "immunohistochemistry")  # BUILTIN_IMAGES in colour


class DisplayImageError(UdcError):
    """An image that cannot be shown; one line."""


def decode(code: np.ndarray, transfer: str) -> np.ndarray:
    """Code values in [0, 1] to linear drive levels (IEC 61966-2-1 sRGB, pure 2.2 gamma, or linear)."""
    if transfer == "srgb":
        c = np.asarray(code, dtype=np.float64)
        out = np.empty_like(c)
        np.add(c, 0.055, out=out)
        out /= 1.055
        np.power(out, 2.4, out=out)  # in place: the panel holds 25 M values
        low = c <= 0.04045
        out[low] = c[low] / 12.92
        return out
    if transfer == "gamma2.2":
        return code ** 2.2
    return code


def photo_palette(seed: int) -> np.ndarray:
    """[N, 3] the pixels of the built-in colour photograph COLOUR_PHOTOS[seed mod 5] as an sRGB panel shows
    them (linear drive levels): the colours of pattern:dead_leaves_colour:SEED."""
    name = COLOUR_PHOTOS[int(seed) % len(COLOUR_PHOTOS)]
    return decode(read_code_values(f"builtin:{name}"), "srgb").reshape(-1, 3)


def pattern(name: str, cols: int, rows: int) -> np.ndarray:
    """Test patterns in linear drive levels [3, rows, cols]; `name` is NAME or NAME:ARG:
    checker (8 × 8 squares per panel height), white, grid (1-px white lines every 1/8 of the height),
    orientation (black panel, red square top-left, green top-right, blue bottom-left, 1/8 height),
    and the grey charts of `udc_render.charts`: slanted_edge[:ANGLE_DEG], sine_x[:CYCLES],
    sine_y[:CYCLES], siemens[:SPOKES], dead_leaves[:SEED]; and dead_leaves_colour[:SEED], the dead leaves
    in the colours of a built-in photograph (photo_palette)."""
    kind, _, arg = name.partition(":")
    if kind in CHARTS:
        chart, cast, default = CHARTS[kind]
        try:
            value = cast(arg) if arg else default
        except ValueError:
            value = None
        if (value is None or not math.isfinite(value) or value < 0 or (kind == "slanted_edge" and value >= 45)
                or (kind == "siemens" and value < 1)):
            raise DisplayImageError(f"content.image = 'pattern:{name}': expected pattern:{kind}:{PATTERN_ARGS[kind]}")
        img = chart(cols, rows, value)
        return img if img.ndim == 3 else np.broadcast_to(img[None], (3, rows, cols)).copy()
    if arg or kind not in PATTERNS:
        raise DisplayImageError(f"content.image = 'pattern:{name}': expected one of "
                                + ", ".join(f"pattern:{p}" for p in PATTERNS)
                                + ", " + ", ".join(f"pattern:{k}[:{v}]" for k, v in PATTERN_ARGS.items()))
    y, x = np.mgrid[0:rows, 0:cols]
    s = max(rows // 8, 1)
    img = np.zeros((3, rows, cols))
    if kind == "white":
        img[:] = 1.0
    elif kind == "checker":
        img[:] = ((y // s + x // s) % 2)[None]
    elif kind == "grid":
        img[:] = ((y % s == 0) | (x % s == 0))[None]
    else:  # orientation
        img[0, :s, :s] = 1.0
        img[1, :s, -s:] = 1.0
        img[2, -s:, :s] = 1.0
    return img


def builtin_image(name: str) -> np.ndarray:
    """scikit-image's sample `name` (BUILTIN_IMAGES) as skimage.data gives it: its file read with imageio, or
    skimage.data's function where the file is not in the installed package's data folder."""
    folder = importlib.util.find_spec("skimage").submodule_search_locations[0]
    path = Path(folder) / "data" / BUILTIN_FILES[name]
    if path.is_file():
        return iio.imread(path)
    import skimage.data
    return getattr(skimage.data, name)()


def read_code_values(spec: str, base: Path | None = None) -> np.ndarray:
    """An image's code values [rows, cols, 3] in [0, 1]: 'builtin:NAME' (scikit-image's shipped
    samples) or a file path (PNG, JPEG, TIFF, …; 8- or 16-bit, grey or colour, alpha dropped)."""
    if spec.startswith("builtin:"):
        name = spec.split(":", 1)[1]
        if name not in BUILTIN_IMAGES:
            raise DisplayImageError(f"content.image = {spec!r}: expected one of "
                                    + ", ".join(f"builtin:{n}" for n in BUILTIN_IMAGES))
        a = builtin_image(name)
    else:
        path = Path(spec) if base is None or Path(spec).is_absolute() else base / spec
        try:
            a = _read_png16(path) if _is_png16(path) else _read_any(path)
        except Exception as e:  # the readers raise many kinds for unreadable files
            raise DisplayImageError(f"content.image = {spec!r}: cannot read {path} as an image "
                                    f"({type(e).__name__})") from None
    a = np.asarray(a)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, -1)
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4) or min(a.shape[:2]) < 1:
        raise DisplayImageError(f"content.image = {spec!r}: expected a grey, RGB or RGBA image, got shape {a.shape}")
    if a.shape[2] == 1:
        a = np.repeat(a, 3, -1)
    a = a[..., :3]
    if np.issubdtype(a.dtype, np.integer):
        return a.astype(np.float64) / np.iinfo(a.dtype).max
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 1:
        raise DisplayImageError(f"content.image = {spec!r}: floating-point values must be finite and in [0, 1]")
    return a


def _is_png16(path: Path) -> bool:
    """A 16-bit PNG (IHDR bit depth at byte 24): Pillow, imageio's PNG reader, drops colour ones to 8 bits."""
    with open(path, "rb") as f:
        head = f.read(25)
    return head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) == 25 and head[24] == 16


def _read_png16(path: Path) -> np.ndarray:
    w, h, rows, info = png.Reader(filename=str(path)).asDirect()
    planes = info["planes"]
    a = np.vstack([np.asarray(r, dtype=np.uint16) for r in rows]).reshape(h, w, planes)
    return a[..., 0] if planes == 1 else a


def _read_any(path: Path) -> np.ndarray:
    with warnings.catch_warnings():  # probing a non-image wakes imageio's deprecated legacy plugins
        warnings.simplefilter("ignore", DeprecationWarning)
        return iio.imread(path)


def fit_to_panel(code: np.ndarray, cols: int, rows: int) -> tuple[np.ndarray, dict]:
    """Rotate (portrait on landscape or vice versa) and resize [r, c, 3] to fit inside the panel,
    centred with black bars. Returns code values [3, rows, cols] and what was done."""
    rotated = (code.shape[0] > code.shape[1]) != (rows > cols) and code.shape[0] != code.shape[1]
    if rotated:
        code = np.rot90(code)  # a quarter turn counter-clockwise
    scale = min(cols / code.shape[1], rows / code.shape[0])
    w, h = max(1, round(code.shape[1] * scale)), max(1, round(code.shape[0] * scale))
    img = resample(code.transpose(2, 0, 1), resize_matrix(code.shape[0], h), resize_matrix(code.shape[1], w))
    out = np.zeros((3, rows, cols))
    y0, x0 = (rows - h) // 2, (cols - w) // 2
    out[:, y0:y0 + h, x0:x0 + w] = np.clip(img, 0, 1)
    return out, {"rotated": bool(rotated), "shown_px": [w, h], "offset_px": [x0, y0], "scale": scale}


def panel_drive(spec: str, cols: int, rows: int, transfer: str, base: Path | None = None) -> tuple[np.ndarray, dict]:
    """Linear drive levels [3, rows, cols] for what the scene asks the panel to show."""
    if spec.startswith("pattern:"):
        return pattern(spec.split(":", 1)[1], cols, rows), {"pattern": spec}
    code, how = fit_to_panel(read_code_values(spec, base), cols, rows)
    (x0, y0), (w, h) = how["offset_px"], how["shown_px"]
    shown = (slice(None), slice(y0, y0 + h), slice(x0, x0 + w))
    code[shown] = decode(code[shown], transfer)  # the black bars decode to 0: left as they are
    return code, how
