"""The randomization TOML: one distribution per parameter, validated on load.

A parameter is a fixed value or a table

    {dist = "uniform", low = A, high = B}        A + (B − A) u
    {dist = "log_uniform", low = A, high = B}    exp(log A + (log B − log A) u), 0 < A
    {dist = "choice", values = [...], weights = [...]}   weights optional (equal), normalised

with u ~ U[0, 1). SCHEMA lists every key, its unit and the values it allows; a user file is read over
the shipped default (default.toml: the documented ranges), so it names only what it changes. Errors
are one line: the file, the key, the value and what is allowed.
"""
from __future__ import annotations

import math
import tomllib
import zlib
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from udc_render.dataset.randomize.limits import check_ranges
from udc_render.dataset.randomize.panels import MAX_TRANSMISSION_SCALE, RandomizeError
from udc_render.io.files import read_toml

KINDS = ("uniform", "log_uniform", "choice")
DEFAULT = "default"
DEFAULT_FILE = "default.toml"


@dataclass(frozen=True)
class Allowed:
    """What a parameter may take: numbers in [lo, hi] (lo excluded when lo_open; whole numbers when
    integer), one of `words`, or a file's path (path: any text, checked by load_distributions); `what`
    describes it for the error line."""
    lo: float = 0.0
    hi: float = math.inf
    lo_open: bool = False
    integer: bool = False
    words: tuple[str, ...] = ()
    what: str = ""
    path: bool = False

    def admits(self, v) -> bool:
        if self.path:
            return isinstance(v, str)
        if self.words:
            return isinstance(v, str) and v in self.words
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return False
        if self.integer and not float(v).is_integer():
            return False
        return ((v > self.lo) if self.lo_open else (v >= self.lo)) and v <= self.hi

    def describe(self) -> str:
        if self.path:
            return f"a path{' ' + self.what if self.what else ''}"
        if self.words:
            return "one of " + ", ".join(self.words)
        rng = f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}]"
        return f"{'a whole number' if self.integer else 'a number'} in {rng}{' ' + self.what if self.what else ''}"


def _num(lo, hi, what="", lo_open=False, integer=False) -> Allowed:
    return Allowed(lo, hi, lo_open, integer, (), what)


PRESET_FAMILIES = ("toled", "poled")
FAMILIES = (*PRESET_FAMILIES, "file")  # file: a user's display file or micrograph (panels.file_display)
_PRESET = {  # per preset family, under [display.<family>]
    "pitch_um": _num(1.0, 1e4, "µm (the square cell's side)"),
    "open_fraction": _num(0.0, 0.75, "(open area / cell)", lo_open=True),
}
_FAMILY = {  # per display family, the file family included
    "transmission_scale": _num(0.0, 10.0, "(× the family's T(λ); T stays ≤ 1)", lo_open=True),
    "haze": _num(0.0, 0.5, "(share of the light scattered past 2.5°; optics.stray)"),
    "disorder_cells": _num(1, 8, "(supercell side, cells)", integer=True),
    "disorder_position_um": _num(0.0, 20.0, "µm (σ of each opening's shift)"),
    "disorder_size_sd": _num(0.0, 0.5, "(σ of each opening's relative size)"),
}
SCHEMA: dict[str, Allowed] = {
    "display.family": Allowed(words=FAMILIES),
    "display.distance_mm": _num(0.0, 100.0, "mm (display to the lens's principal plane)"),
    **{f"display.{f}.{k}": a for f in PRESET_FAMILIES for k, a in _PRESET.items()},
    **{f"display.{f}.{k}": a for f in FAMILIES for k, a in _FAMILY.items()},
    "display.file.path": Allowed(path=True, what="to a display file (.toml) or a micrograph image, relative to the "
                                                 "distributions file ('': none)"),
    "display.file.length_scale": _num(0.1, 10.0, "(× every length of the file's layout: its pitch and openings, "
                                                 "or a micrograph's pixel size)", lo_open=True),
    "display.toled.slit_height_fraction": _num(0.05, 1.0, "(of the cell)"),
    "display.poled.small_to_large": _num(0.0, 1.0, "(small / large opening radius)", lo_open=True),
    "display.poled.urbach_width_nm": _num(8.0, 30.0, "nm (the fitted table's range)"),
    "lens.focus_error_per_m": _num(-2.0, 2.0, "m⁻¹ (1/focus − 1/object distance)"),
    "lens.f_number": _num(0.5, 32.0),
    "sensor.gain_scale": _num(0.0, 100.0, "(× the family's gain: 6 T-OLED, 25 P-OLED)", lo_open=True),
    "sensor.read_noise_e": _num(0.0, 1e3, "e⁻"),
    "sensor.dead_fraction": _num(0.0, 0.01, "(of the pixels)"),
    "sensor.hot_fraction": _num(0.0, 0.01, "(of the pixels)"),
    "sensor.hot_dark_e_per_s": _num(0.0, 1e9, "e⁻/s"),
    "sensor.prnu": _num(0.0, 0.25, "(relative σ of the pixels' gains)"),
    "sensor.dsnu_e": _num(0.0, 1e3, "e⁻"),
    "sensor.row_offset_e": _num(0.0, 1e3, "e⁻"),
    "sensor.column_offset_e": _num(0.0, 1e3, "e⁻"),
    "sensor.dark_current_e_per_s": _num(0.0, 1e6, "e⁻/s"),
    "exposure.scale": _num(0.0, 100.0, "(× the exposure: auto or --exposure-s)", lo_open=True),
    "exposure.brightness": _num(0.0, 100.0, "(× the scene's radiance)", lo_open=True),
}


@dataclass(frozen=True)
class Dist:
    """One parameter's distribution: kind 'fixed' (values = (v,)), 'uniform', 'log_uniform' (low, high)
    or 'choice' (values, weights summing to 1)."""
    kind: str
    low: float = math.nan
    high: float = math.nan
    values: tuple = ()
    weights: tuple[float, ...] = ()

    def sample(self, rng: np.random.Generator):
        """One draw: a float, or one of the values (a fixed value is returned without drawing)."""
        if self.kind == "fixed":
            return self.values[0]
        if self.kind == "choice":
            return self.values[int(rng.choice(len(self.values), p=self.weights))]
        u = float(rng.random())
        if self.kind == "uniform":
            return self.low + (self.high - self.low) * u
        return math.exp(math.log(self.low) + (math.log(self.high) - math.log(self.low)) * u)

    @property
    def support(self) -> tuple:
        """Every value the draw can take at its ends: (low, high), or the values."""
        return (self.low, self.high) if self.kind in ("uniform", "log_uniform") else self.values

    def describe(self):
        """As the TOML writes it."""
        if self.kind == "fixed":
            return self.values[0]
        if self.kind == "choice":
            return {"dist": "choice", "values": list(self.values), "weights": list(self.weights)}
        return {"dist": self.kind, "low": self.low, "high": self.high}


@dataclass(frozen=True)
class Distributions:
    """Every parameter's distribution (SCHEMA's keys) and the file(s) they came from."""
    dists: dict
    source: str

    def __getitem__(self, key: str) -> Dist:
        return self.dists[key]

    def describe(self) -> dict:
        return {"source": self.source, "parameters": {k: d.describe() for k, d in sorted(self.dists.items())}}


def parse_dist(value, key: str, where: str) -> Dist:
    """A TOML value of `key` as a Dist, checked against SCHEMA[key]."""
    allowed = SCHEMA[key]

    def fail(why: str):
        raise RandomizeError(f"{where}: {key} = {value!r}: expected {why}")
    if not isinstance(value, dict):
        if not allowed.admits(value):
            fail(f"{allowed.describe()}, or a table {{dist = {' | '.join(KINDS)}, ...}}")
        return Dist("fixed", values=(_typed(value, allowed),))
    kind = value.get("dist")
    keys = {"uniform": ("dist", "low", "high"), "log_uniform": ("dist", "low", "high"),
            "choice": ("dist", "values", "weights")}
    if kind not in keys:
        fail(f"a table with dist = one of {', '.join(KINDS)}")
    extra = sorted(set(value) - set(keys[kind]))
    if extra:
        fail(f"only the keys {', '.join(keys[kind])} for dist = {kind!r} (not {', '.join(extra)})")
    if kind == "choice":
        values = value.get("values")
        if not isinstance(values, list) or not values or not all(allowed.admits(v) for v in values):
            fail(f"values = a non-empty list, each {allowed.describe()}")
        weights = value.get("weights", [1.0] * len(values))
        if (not isinstance(weights, list) or len(weights) != len(values)
                or not all(isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w >= 0
                           for w in weights) or not sum(weights) > 0):
            fail(f"weights = {len(values)} numbers ≥ 0 with a positive sum, one per value")
        total = float(sum(weights))
        return Dist("choice", values=tuple(_typed(v, allowed) for v in values),
                    weights=tuple(float(w) / total for w in weights))
    if allowed.words or allowed.integer or allowed.path:
        fail(f"a fixed value or dist = 'choice' ({allowed.describe()})")
    low, high = value.get("low"), value.get("high")
    if not (allowed.admits(low) and allowed.admits(high)):
        fail(f"low and high each {allowed.describe()}")
    if not low < high:
        fail("low < high (a fixed value for one number)")
    if kind == "log_uniform" and not low > 0:
        fail("low > 0 for dist = 'log_uniform'")
    return Dist(kind, float(low), float(high))


def _typed(v, allowed: Allowed):
    """A fixed or listed value as drawn: a word, a whole number, or a float."""
    return v if allowed.words or allowed.path else int(v) if allowed.integer else float(v)


def _flatten(table: dict, prefix: str, where: str, out: dict) -> None:
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and "dist" not in v and key not in SCHEMA:
            if not any(s.startswith(key + ".") for s in SCHEMA):
                raise RandomizeError(f"{where}: [{key}]: expected a known table or key ({_known(prefix)})")
            _flatten(v, key + ".", where, out)
        elif key not in SCHEMA:
            raise RandomizeError(f"{where}: {key} = {v!r}: expected a known key ({_known(prefix)})")
        else:
            out[key] = v


def _known(prefix: str) -> str:
    names = sorted({k[len(prefix):].split(".")[0] for k in SCHEMA if k.startswith(prefix)})
    return ", ".join(names)


def parse(data: dict, where: str, base: Distributions | None = None) -> Distributions:
    """The distributions of a TOML document, read over `base` (None: every key must be given)."""
    flat: dict = {}
    _flatten(data, "", where, flat)
    dists = dict(base.dists) if base is not None else {}
    dists.update({k: parse_dist(v, k, where) for k, v in flat.items()})
    missing = sorted(set(SCHEMA) - set(dists))
    if missing:
        raise RandomizeError(f"{where}: {missing[0]} = None: expected a value or a distribution for every key "
                             f"({len(missing)} missing)")
    _check_together(dists, where)
    return Distributions(dists, where if base is None else f"{base.source} + {where}")


def _check_together(dists: dict, where: str) -> None:
    """What single keys cannot say: a T-OLED's slit must hold its open area."""
    top = max(dists["display.toled.open_fraction"].support)
    slit = min(dists["display.toled.slit_height_fraction"].support)
    if top > slit:
        raise RandomizeError(f"{where}: display.toled.open_fraction = "
                             f"{dists['display.toled.open_fraction'].describe()!r}"
                             f": expected at most the smallest display.toled.slit_height_fraction ({slit:g}): the "
                             "slit is as wide as the open area needs")
    if "file" in dists["display.family"].support and "" in dists["display.file.path"].support:
        raise RandomizeError(f"{where}: display.family = {dists['display.family'].describe()!r}: the family 'file' "
                             "needs display.file.path = a display file (.toml) or a micrograph image")
    for family, top in MAX_TRANSMISSION_SCALE.items():
        key = f"display.{family}.transmission_scale"
        if max(dists[key].support) > top:
            raise RandomizeError(f"{where}: {key} = {dists[key].describe()!r}: expected at most {top:.3g} (T(λ) ≤ 1)")


def default_distributions() -> Distributions:
    """The shipped default.toml: the documented ranges (docs/guides/randomize.md)."""
    text = resources.files(__package__).joinpath(DEFAULT_FILE).read_text(encoding="utf-8")
    return parse(tomllib.loads(text), f"randomize {DEFAULT}")


def load_distributions(spec: str | Path) -> Distributions:
    """'default' (the shipped ranges) or a TOML file read over them, its ranges checked for every draw
    (randomize.limits)."""
    if str(spec) == DEFAULT:
        dists = default_distributions()
        check_ranges(dists, f"randomize {DEFAULT}")
        return dists
    path = Path(spec)
    if path.suffix.lower() != ".toml":
        raise RandomizeError(f"--randomize = {str(spec)!r}: expected {DEFAULT} or a .toml file of distributions")
    dists = _with_display_files(parse(read_toml(path, RandomizeError, "--randomize"), str(path),
                                      default_distributions()), path)
    check_ranges(dists, str(path))
    return dists


def _with_display_files(dists: Distributions, toml: Path) -> Distributions:
    """display.file.path's values made absolute (relative ones from the TOML file's folder), each checked to be
    a file."""
    key, d = "display.file.path", dists["display.file.path"]
    paths = tuple("" if v == "" else str((toml.parent / v).resolve()) for v in d.values)
    for given, found in zip(d.values, paths):
        if found and not Path(found).is_file():
            raise RandomizeError(f"{toml}: {key} = {given!r}: no such file ({found}); expected a display file "
                                 "(.toml) or a micrograph image")
    return Distributions({**dists.dists, key: replace(d, values=paths)}, dists.source)


def stream(seed: int, *keys) -> np.random.Generator:
    """A generator of its own for (seed, keys…): integers as they are, strings by crc32, so that each
    parameter's draw depends on its name and not on the other parameters. Every caller's key is (what, index,
    name) with a CRC-32 last, nonzero and distinct for every name drawn (tests/udc_render/test_dataset_streams.py),
    so numpy's zero padding of the entropy makes no two draws one stream. Kept as it is, not moved to
    udc_render.streams: the draws, and so the shipped banks' fingerprints, would change."""
    parts = [int(seed)] + [k if isinstance(k, int) else zlib.crc32(str(k).encode()) for k in keys]
    return np.random.default_rng(np.random.SeedSequence(parts))
