"""`udc-render study design` (udc_render.studies.design_knobs) on a tiny setting: both parts and the outputs."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from udc_render.design import metrics, torch_psf as tp
from udc_render.design.optimise import DesignConfig, Designer
from udc_render.studies import design_knobs as dk
from udc_render.studies.design_knobs_report import write

TINY = {"cell_um": 96.0, "kernel_px": 15, "samples": (64, 128), "steps": (2,), "design_pupil_samples": 64}


@pytest.fixture(scope="module")
def sampling():
    return dk.sampling_rows(TINY)


def test_the_sampling_rows_measure_against_the_finest_setting(sampling):
    rows = sampling
    assert [r["cell"] for r in rows] == ["toled_edge"] * 2 + ["scatter"] * 2
    for ref in (rows[1], rows[3]):  # the finest setting is the reference
        assert ref["error_psnr_db"] == 0 and ref["error_ring_minima_rel"] == 0
    # the samples per cell follow the engine's display grid: 3 and 5 samples across a 96 µm cell
    assert [r["samples_per_cell"] for r in rows[:2]] == [3, 5]
    for coarse, fine in ((rows[0], rows[1]), (rows[2], rows[3])):
        assert coarse["error_psnr_db"] == max(abs(a - b) for a, b in zip(coarse["psnr_db"], fine["psnr_db"])) > 0
        assert coarse["cpu_s"] > 0 and coarse["cpu_gradient_s"] > 0


def test_the_study_cells_are_open_at_20_percent():
    """The T-OLED's area-weighted raster keeps its exact open area; the scatter opens round(0.2 · 441) squares."""
    c = dk.cells(168.0)
    assert c["toled_edge"].shape == (21, 21) and abs(c["toled_edge"].mean() - 0.2) < 1e-12
    assert c["scatter"].sum() == 88 and set(np.unique(c["scatter"])) == {0.0, 1.0}


def test_the_steps_rows_score_the_searched_cell_as_the_numpy_metric_does(tmp_path, sampling):
    """The search's cell after 2 steps, scored by the designer (torch), equals metrics.restorability's mean Wiener
    MSE of the torch PSF's kernels of that cell on the held-out tiling, the light outside the window lost (numpy);
    the swaps keep round(0.2 · 144) = 29 squares, and the search beats its initial scatter on the held-out tiling."""
    first, row = dk.steps_rows(TINY)
    assert first["steps"] == 0 and first["steps_done"] == 0 and abs(first["open_area"] - 29 / 144) < 1e-12
    assert row["steps"] == 2 and abs(row["open_area"] - 29 / 144) < 1e-12 and row["cpu_s"] > first["cpu_s"]
    assert abs(row["psnr_db"] + 10 * np.log10(row["objective"])) < 1e-12 and row["psnr_db"] > first["psnr_db"]
    designer = Designer(DesignConfig(cell_um=96.0, kernel_px=15, pupil_samples=64, steps=2))
    designer.step()
    designer.step()
    cell = designer.cell
    turns = designer.transforms("final")
    k, inside = (v.numpy() for v in tp.kernels_and_window(torch.tensor(cell), designer.grid, turns))
    mse = metrics.restorability(k, cell.mean() * inside)["wiener_mse"]
    assert abs(np.mean(mse) / row["objective"] - 1) < 1e-9
    names = write({"config": {**TINY, "feature_um": 8.0, "open_fraction": 0.2, "seed": 0,
                              "wavelengths_nm": (640.0, 520.0, 450.0), "threads": 1},
                   "sampling": sampling, "steps": [first, row]}, tmp_path)
    assert all((tmp_path / n).stat().st_size > 0 for n in names)
    assert "| 2 | 2 | " in (tmp_path / "study_design.md").read_text()
