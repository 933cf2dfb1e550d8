"""psf.colour_tables: colour-science's tables kept in the cache folder, read without `import colour`."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import colour
import numpy as np
import pytest

from psf import colour_tables

ROOT = Path(__file__).resolve().parents[2]

# Every table a dataset item reads, then whether colour was imported (run in a fresh process)
_PROBE = """
import sys
from udc_render.content import spectra
from udc_render.io import dng
from psf.spectral import load_sensitivities, load_weight
spectra.monitor_primaries("Apple Studio Display", 100.0)
spectra.illuminant("D65"), spectra.colourchecker("dark skin"), dng.color_matrix_fit("Nikon 5100 (NPL)")
load_sensitivities("Nikon 5100 (NPL)"), load_weight("D65")
print("colour" in sys.modules)
"""


@pytest.fixture()
def fresh_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("UDC_RENDER_CACHE", str(tmp_path))
    colour_tables._table.cache_clear()
    yield tmp_path
    colour_tables._table.cache_clear()


def _probe(cache: Path) -> bool:
    env = dict(os.environ, UDC_RENDER_CACHE=str(cache), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip() == "True"


def test_a_process_that_finds_the_tables_does_not_import_colour(fresh_cache):
    """The first process imports colour and writes the tables; the next one reads them and never imports it."""
    assert _probe(fresh_cache) is True
    assert any(fresh_cache.glob("*.npz"))
    assert _probe(fresh_cache) is False


def test_the_tables_are_colour_sciences_bits(fresh_cache):
    """Read back from the folder (a cleared process memory), every array equals colour-science's own."""
    cmfs = colour.MSDS_CMFS[colour_tables.OBSERVER]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    nikon = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    for _ in range(2):  # made, then read from the folder
        colour_tables._table.cache_clear()
        w, v = colour_tables.spectrum("cmfs", colour_tables.OBSERVER)
        assert np.array_equal(w, cmfs.wavelengths) and np.array_equal(v, cmfs.values)
        w, v = colour_tables.spectrum("illuminants", "D65")
        assert np.array_equal(w, d65.wavelengths) and np.array_equal(v, d65.values)
        w, v = colour_tables.spectrum("camera_sensitivities", "Nikon 5100 (NPL)")
        assert np.array_equal(v, nikon.values) and colour_tables.labels("camera_sensitivities",
                                                                        "Nikon 5100 (NPL)") == tuple(nikon.labels)
        assert colour_tables.names("colourchecker") == tuple(colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"])
        assert np.array_equal(colour_tables.white_point_xy("D50"),
                              colour.CCS_ILLUMINANTS[colour_tables.OBSERVER]["D50"])
        with pytest.raises(ValueError, match="read-only"):  # shared by every caller: not to be changed in place
            colour_tables.spectrum("illuminants", "D65")[1][0] = 0.0


@pytest.mark.parametrize("dataset, name", [("illuminants", "d65"), ("illuminants", "FL2"), ("illuminants", "fl2"),
                                           ("display_primaries", "apple-studio-display"),
                                           ("display_primaries", "applestudiodisplay"), ("white_points", "d50"),
                                           ("illuminants", "D 65"), ("illuminants", "no such"),
                                           ("display_primaries", "primaries.csv")])
def test_names_are_found_as_colour_science_finds_them(fresh_cache, dataset, name):
    """key() accepts what colour-science's CanonicalMapping accepts (lower case, slugified, canonical), no more."""
    mapping = colour_tables.DATASETS[dataset](colour)
    found = colour_tables.key(dataset, name)
    assert (found is not None) == (name in mapping)
    if found is not None:
        assert mapping[found] is mapping[name]


def test_a_folder_that_cannot_be_written_costs_nothing_but_time(tmp_path, monkeypatch):
    """A cache path that is a file: the table is made in memory, the same values, and nothing fails."""
    blocked = tmp_path / "file"
    blocked.write_text("")
    monkeypatch.setenv("UDC_RENDER_CACHE", str(blocked / "psf"))
    colour_tables._table.cache_clear()
    try:
        w, v = colour_tables.spectrum("illuminants", "A")
    finally:
        colour_tables._table.cache_clear()
    assert np.array_equal(v, colour.SDS_ILLUMINANTS["A"].values)
