"""colour-science's data tables, kept in the cache folder so that a process reads them without `import colour`.

colour-science 0.4.7 imports matplotlib through `colour.plotting`: `import colour` costs a process ~1.4 s, the
largest part of a dataset worker's first item. The tables a run reads are small fixed data of the installed
package: the CIE 1931 2° colour matching functions, the illuminants, the ColorChecker N Ohta reflectances, the
display primaries, the cameras' spectral sensitivities and the white points' chromaticities. The first process
that needs one imports colour and writes the table as it stands in colour-science (wavelengths and values, the
same float64 bits) into the cache folder (psf.cache.cache_dir: $UDC_RENDER_CACHE or ~/.cache/udc-render/psf),
keyed by the table, its name and the installed colour-science version (read from its metadata, without
importing it); every later process reads the .npz (about a millisecond). A folder that cannot be written costs
the import, nothing else. Names are looked up as colour-science's CanonicalMapping does (key()).
"""
from __future__ import annotations

import functools
from importlib.metadata import version

import numpy as np

from .cache import cache_dir, derived_key, entry_path
from .kernel_io import atomic_write, read_members

KIND = "colour-table-1"  # the layout of the entries below; change it when it changes
OBSERVER = "CIE 1931 2 Degree Standard Observer"
CHECKER = "ColorChecker N Ohta"
# dataset: where it lives in colour-science (a function of the imported module)
DATASETS = {
    "cmfs": lambda colour: colour.MSDS_CMFS,
    "illuminants": lambda colour: colour.SDS_ILLUMINANTS,
    "colourchecker": lambda colour: colour.SDS_COLOURCHECKERS[CHECKER],
    "display_primaries": lambda colour: colour.MSDS_DISPLAY_PRIMARIES,
    "camera_sensitivities": lambda colour: colour.MSDS_CAMERA_SENSITIVITIES,
    "white_points": lambda colour: colour.CCS_ILLUMINANTS[OBSERVER],
}


def names(dataset: str) -> tuple[str, ...]:
    """The names of a dataset's entries, in colour-science's order (e.g. the 24 ColorChecker patches)."""
    return tuple(str(n) for n in _table(dataset, None)["names"])


def key(dataset: str, name: str) -> str | None:
    """The entry's own name for `name` as colour-science's CanonicalMapping finds it (the name, its lower case,
    slugified or canonical form: 'd65', 'apple-studio-display'), or None when the dataset has no such entry."""
    t = _table(dataset, None)
    for column, query in (("names", name), ("lower", str(name).lower()), ("slugified", name), ("canonical", name)):
        hits = np.flatnonzero(t[column] == query)
        if hits.size:
            return str(t["names"][hits[0]])
    return None


def spectrum(dataset: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths nm [N], values [N] or [N, M]) of a (multi-)spectral distribution; name: key(dataset, ...)'s."""
    t = _table(dataset, name)
    return t["wavelengths"], t["values"]


def labels(dataset: str, name: str) -> tuple[str, ...]:
    """The channel labels of a multi-spectral distribution (a camera's 'red', 'green', 'blue')."""
    return tuple(str(n) for n in _table(dataset, name)["labels"])


def white_point_xy(name: str) -> np.ndarray:
    """CIE 1931 2° chromaticity (x, y) of the illuminant `name`: key('white_points', ...)'s."""
    return _table("white_points", name)["xy"]


@functools.lru_cache(maxsize=None)
def _table(dataset: str, name: str | None) -> dict[str, np.ndarray]:
    """The entry of (dataset, name) (None: the names) from the cache folder, or made and written there."""
    if dataset not in DATASETS:
        raise KeyError(f"colour table {dataset!r}: expected one of {', '.join(DATASETS)}")
    path = entry_path(derived_key(KIND, [_installed()], dataset=dataset, name=name), cache_dir())
    try:
        return {k: _frozen(v) for k, v in read_members(path).items()}
    except (OSError, ValueError, KeyError):
        pass  # absent or damaged: made again
    arrays = {k: _frozen(v) for k, v in _make(dataset, name).items()}
    try:
        atomic_write(path, lambda fh: np.savez(fh, **arrays))
    except OSError:
        pass  # a read-only folder: this process keeps its own
    return arrays


def _frozen(a) -> np.ndarray:
    """A read-only copy: the tables are shared by every caller of this process (lru_cache)."""
    a = np.array(a)
    a.setflags(write=False)
    return a


@functools.lru_cache(maxsize=1)
def _installed() -> str:
    """colour-science's version from its metadata (importlib.metadata: ~10 ms a lookup, so once)."""
    return f"colour-science {version('colour-science')}"


def _make(dataset: str, name: str | None) -> dict[str, np.ndarray]:
    import colour
    data = DATASETS[dataset](colour)
    if name is None:
        return {column: np.array(list(keys), dtype=str) for column, keys in (
            ("names", data.keys()), ("lower", data.lower_keys()), ("slugified", data.slugified_keys()),
            ("canonical", data.canonical_keys()))}
    entry = data[name]
    if dataset == "white_points":
        return {"xy": np.asarray(entry, dtype=np.float64)}
    arrays = {"wavelengths": np.asarray(entry.wavelengths), "values": np.asarray(entry.values)}
    if hasattr(entry, "labels"):
        arrays["labels"] = np.array(list(entry.labels), dtype=str)
    return arrays
