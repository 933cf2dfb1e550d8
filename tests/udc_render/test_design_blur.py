"""Part (i) of `udc-render study design` (udc_render.studies.design_blur) and the channel kernel of
design.pattern.blur_error_db."""
from __future__ import annotations

import numpy as np
import torch

from udc_render.design import torch_psf as tp
from udc_render.design.pattern import blur_error_db
from udc_render.studies import design_blur as db

CELL = np.zeros((12, 12))
CELL[2:5, 3:9] = 1.0  # a slit off the centre: every D4 element moves it


def _grid(wavelengths_nm) -> tp.CellGrid:
    return tp.cell_grid(12, 8.0, wavelengths_nm=wavelengths_nm, pixel_um=6.2, size_px=31, pupil_samples=256)


def test_a_weight_on_one_wavelength_is_that_wavelengths_blur():
    """The channel kernel Σ w t k / Σ w t with all the weight on one wavelength is that wavelength's own kernel: its
    blur error equals a one-wavelength grid's (the same sampling: the pupil step follows the shortest wavelength)."""
    three, one = _grid((450.0, 520.0, 640.0)), _grid((450.0,))
    transforms = tp.tile_transforms(three.tiles, 0)
    x = torch.tensor(CELL)
    assert abs(blur_error_db(x, three, transforms, [1.0, 0.0, 0.0]) - blur_error_db(x, one, transforms)) < 1e-10
    assert abs(blur_error_db(x, three, transforms, [0.0, 2.0, 0.0])
               - blur_error_db(x, three, transforms, [0.0, 1.0, 0.0])) < 1e-12


def test_the_channel_kernel_weighs_each_wavelength_by_its_light_inside_the_window():
    """Two wavelengths at equal weight: the blur error is that of (t₁ k₁ + t₂ k₂) / (t₁ + t₂), k and t from
    kernels_and_window (psf.spectral.combine's rule), and its energy is at most the weighted mean of the two
    wavelengths' own (Jensen: |Σ a_i (1 − H_i)|² ≤ Σ a_i |1 − H_i|² for a_i ≥ 0 summing to 1)."""
    grid = _grid((450.0, 640.0))
    transforms = tp.tile_transforms(grid.tiles, 0)
    x = torch.tensor(CELL)
    with torch.no_grad():
        ks, inside = tp.kernels_and_window(x, grid, transforms)
    from udc_render.design import metrics
    scene = metrics.natural_spectrum(31, (metrics.RMS_CONTRAST * metrics.MEAN_LEVEL) ** 2)

    def energy(k):
        return (scene * np.abs(1 - np.fft.fft2(np.fft.ifftshift(k))) ** 2).mean()

    t = inside.double().numpy()
    mixed = (t[0] * ks[0].double().numpy() + t[1] * ks[1].double().numpy()) / t.sum()
    assert abs(blur_error_db(x, grid, transforms) + 10 * np.log10(energy(mixed))) < 1e-10
    singles = np.array([energy(k.double().numpy()) for k in ks])
    assert energy(mixed) <= (t * singles).sum() / t.sum() * (1 + 1e-12)
    assert abs(t[0] - t[1]) > 1e-4  # the weights differ: the test could tell t from equal weights


def test_the_g_channel_is_the_cameras_green_above_its_cutoff():
    """g_channel: wavelengths where G's weight is ≥ 1 % of its peak, weights positive, peak in the green."""
    lam, w = db.g_channel(10.0)
    assert np.all(w >= db.G_CUTOFF * w.max()) and 500 <= lam[int(np.argmax(w))] <= 560
    assert len(db.g_channel(40.0)[0]) < len(lam)


def test_a_d4_symmetric_cell_has_no_gap_and_no_draw_spread_on_any_setting(monkeypatch):
    """A centred square, which every D4 element leaves unchanged: the cell turned's draws and the random patterns are
    one display, so every row's sd and gap are 0; the settings are one knob at a time, each axis's finest last, and
    its errors are 0 there."""
    cell = np.zeros((12, 12))
    cell[4:8, 4:8] = 1.0
    monkeypatch.setattr(db, "BLUR_RIG", {"wavelengths_nm": (520.0,), "pixel_um": 6.2, "size_px": 31,
                                         "pupil_samples": 128})  # a small rig for the other knobs
    cfg = {"cell_um": 96.0, "blur_pupil": (128, 256), "blur_px": (31, 65), "blur_step_nm": (40,), "blur_draws": 2,
           "blur_patterns": 2, "blur_tiles": 2}
    rows = db.blur_rows(cfg, {"square": cell})
    assert [(r["axis"], r["pupil_samples"], r["size_px"], r["step_nm"]) for r in rows] == [
        ("pupil", 128, 31, None), ("pupil", 256, 31, None), ("window", None, 31, None), ("window", None, 65, None),
        ("wavelengths", 128, 31, None), ("wavelengths", 128, 31, 40)]
    for r in rows:
        assert r["turned_sd_db"] < 1e-9 and abs(r["gap_db"]) < 1e-9 and np.isfinite(r["turned_db"])
    for last in (rows[1], rows[3], rows[5]):
        assert last["error_gap_db"] == 0.0 and last["error_turned_db"] in (0.0, None)
    assert rows[2]["error_turned_db"] is None  # the window's scene is its own: no error across windows


def test_the_guides_blur_rig_table_is_the_committed_study():
    """Consistency, not physics: the design guide's part (i) errors are the committed study's, the largest over the
    two cells."""
    import json
    from pathlib import Path
    root = Path(__file__).parents[2]
    rows = json.loads((root / "docs/figures/design/study_knobs/study_design.json").read_text())["blur"]
    guide = (root / "docs/guides/design.md").read_text()

    def worst(axis, key, **at):  # as the guide writes it: 3.8e-4
        v = max(r[key] for r in rows if r["axis"] == axis and all(r[k] == v for k, v in at.items()))
        return f"{v:.1e}".replace("e-0", "e-")
    assert f"| 1024, the rig | {worst('pupil', 'error_gap_db', pupil_samples=1024)} | " \
           f"{worst('pupil', 'error_turned_db', pupil_samples=1024)} |" in guide
    assert f"| 520 nm, the rig (against G at 10 nm) | {worst('wavelengths', 'error_gap_db', step_nm=None)} |" in guide
    window = [worst("window", "error_gap_db", size_px=s) for s in (65, 129)]
    assert f"| {window[0]} / {window[1]} | (its own scene) |" in guide
    sd = max(r["turned_sd_db"] for r in rows if r["axis"] == "pupil" and r["pupil_samples"] == 1024)
    assert f"sd over 8 draws | | {sd:.3f} (T-OLED)" in guide
