"""`study layout-dipole` (udc_render.studies.layout_dipole): the centroid in closed form, the fit recovering a known
law, and the quick study's invariants (the reference over itself is 1; a centred slit bands less turned)."""
from __future__ import annotations

import json

import numpy as np

from udc_render import cli
from udc_render.studies.layout_dipole import NAME, centroid_um, fit_dipole


def test_the_centroid_is_the_open_squares_mean_offset_from_the_tiles_centre():
    """One open corner square of a 21 × 21 cell of 8 µm: |μ| = √2 × 80 µm; a D4-symmetric cell: 0."""
    corner = np.zeros((21, 21))
    corner[0, 0] = 1.0
    cross = np.zeros((21, 21))
    cross[10, :] = cross[:, 10] = 1.0
    assert abs(centroid_um(corner) - np.sqrt(2) * 80.0) < 1e-12 and centroid_um(cross) < 1e-12


def test_the_fit_recovers_a_dipole_law():
    """Rows made from sd² = a + κ |μ|² give back a, κ and no misfit."""
    a, kappa = 1.2e-5, 1.0e-8
    rows = [{"centroid_um": m, "bands_turned": [0.0, np.sqrt(a + kappa * m * m), 0.0]} for m in (0.0, 16.0, 40.0, 64.0)]
    fit = fit_dipole(rows)
    assert abs(fit["a"] / a - 1) < 1e-9 and abs(fit["kappa_per_um2"] / kappa - 1) < 1e-9
    assert fit["max_rel_misfit_sd"] < 1e-9


def test_the_quick_study_writes_its_rows(tmp_path):
    """Three framings of the T-OLED on the design's squares (88 open): the slit at the edge (|μ| 64 µm) and near the
    centre (2 µm, its 88th square off the axis); the centred slit bands less turned, by the dipole's share, and has
    the lower UPC ratio and veil objective; tiled plainly, a framing is a shift of the display, and the objective
    stays within 0.05 dB."""
    assert cli.main(["study", "layout-dipole", "--quick", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / f"{NAME}.json").read_text())
    rows = {r["roll"]: r for r in doc["rows"]}
    assert rows[0]["centroid_um"] > 60 and rows[8]["centroid_um"] < 3
    assert all(rows[8]["bands_turned"][c] < rows[0]["bands_turned"][c] for c in range(3))
    assert rows[8]["upc_ratio"][1] < rows[0]["upc_ratio"][1] and rows[8]["veil_psnr_db"] < rows[0]["veil_psnr_db"]
    plain = [r["veil_psnr_repeated_db"] for r in rows.values()]
    assert max(plain) - min(plain) < 0.05
    for suffix in (".csv", ".md", ".png"):
        assert (tmp_path / f"{NAME}{suffix}").is_file()
