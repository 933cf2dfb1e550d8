"""Shared helpers for the PSF-engine tests: analytic oracles and independent re-implementations.

Everything here is written from the physics (docs/PHYSICS.md §3, §4, §6), not copied from the engine,
so that a test compares the engine with something that could disagree with it.
Helpers are plain functions exposed through the `psfkit` fixture (tests never import conftest).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.signal
from scipy.special import j0, j1, jn_zeros

from psf.lens import Lens
from psf.pupil import aperture_slices, display_grid, lens_grid, tile_mask


def bare_pupil(lens: Lens, n: int):
    """The engine's bare-lens raster (δ = D/N, area-weighted disc) cropped to the aperture: (grid, g)."""
    grid = lens_grid(lens, n)
    sy, sx = aperture_slices(grid, lens.aperture_um)
    pg = grid.crop(sy, sx)
    return pg, lens.aperture_area_fraction(pg.x_edges_um, pg.y_edges_um)


def display_pupil(layout, lens: Lens, n: int, mask_raster: str = "band_limited"):
    """The engine's display raster (whole periods, tile_mask) × aperture, cropped: (grid, g, kappa)."""
    grid, cell_n, tiles = display_grid(layout.period_um, lens, n)
    mask, kappa = tile_mask(layout, cell_n, tiles, mask_raster)
    sy, sx = aperture_slices(grid, lens.aperture_um)
    pg = grid.crop(sy, sx)
    return pg, mask[sy, sx] * lens.aperture_area_fraction(pg.x_edges_um, pg.y_edges_um), kappa


def airy_norm(r_um, lens: Lens, wavelength_um: float):
    """(2 J1(v)/v)², v = π D r / (λ z): the Airy intensity relative to its peak."""
    v = math.pi * lens.aperture_um * np.asarray(r_um, dtype=np.float64) / (wavelength_um * lens.image_distance_um)
    safe = np.where(v > 0, v, 1.0)
    return np.where(v > 0, (2 * j1(safe) / safe) ** 2, 1.0)


def airy_peak(lens: Lens, wavelength_um: float) -> float:
    """Peak intensity (A/λz)² for unit irradiance on the pupil; the total power is A = πD²/4."""
    return (math.pi * lens.aperture_um ** 2 / 4 / (wavelength_um * lens.image_distance_um)) ** 2


def airy_pixel_energy(centres_um, pixel_um: float, lens: Lens, wavelength_um: float, nodes: int = 32):
    """Energy of the analytic Airy pattern on each pixel (pixel centres on a square grid), as a
    fraction of the total power, by a nodes × nodes Gauss-Legendre rule per pixel ([M, M] array)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = x * pixel_um / 2, w * pixel_um / 2
    pts = np.asarray(centres_um, dtype=np.float64)[:, None] + x[None, :]           # [M, n]
    r = np.hypot(pts[:, :, None, None], pts[None, None, :, :])                     # [My, n, Mx, n]
    val = airy_norm(r, lens, wavelength_um) * airy_peak(lens, wavelength_um)
    area = math.pi * lens.aperture_um ** 2 / 4
    return np.einsum("anbm,n,m->ab", val, w, w) / area


def disc_ft(nu, diameter_um: float):
    """Fourier transform of the aperture disc at radial frequency ν: π D²/4 · 2 J1(π D ν)/(π D ν)."""
    q = math.pi * diameter_um * np.abs(np.asarray(nu, dtype=np.float64))
    safe = np.where(q > 0, q, 1.0)
    return math.pi * diameter_um ** 2 / 4 * np.where(q > 0, 2 * j1(safe) / safe, 1.0)


def propagated_orders(layout, wavelength_um: float, distance_um: float):
    """Fourier coefficients a_m = c_m H_m of the mask propagated over d (propagating orders only).

    H_m = exp(2πi d [sqrt(1/λ² − |ν_m|²) − 1/λ]) written directly (not the engine's
    cancellation-safe form); evanescent orders (|ν| ≥ 1/λ) are dropped. Returns (kx, ky, a[ky, kx]).
    """
    px, py = layout.period_um
    mx, my = int(px / wavelength_um) + 1, int(py / wavelength_um) + 1
    kx, ky = np.arange(-mx, mx + 1), np.arange(-my, my + 1)
    nu2 = (kx[None, :] / px) ** 2 + (ky[:, None] / py) ** 2
    prop = nu2 < 1.0 / wavelength_um ** 2
    root = np.sqrt(np.where(prop, 1.0 / wavelength_um ** 2 - nu2, 0.0))
    H = np.exp(2j * np.pi * distance_um * (root - 1.0 / wavelength_um))
    a = np.where(prop, layout.fourier_coefficients(kx, ky) * H, 0.0)
    return kx, ky, a


def series_power(layout, lens: Lens, wavelength_um: float, distance_um: float, shifts_um):
    """Transmitted power P(s) = Σ_k b_k(d) Â(k/p) exp(−2πi k·s/p) (docs/PHYSICS.md §4), [..., 2] shifts (x, y).

    b_k = Σ_m a_{m+k} a*_m (scipy.signal.correlate), Â the disc transform. The mask shifted by +s
    (m(x − s)) under a fixed aperture: P(s) = ∫ A(x) |m_d(x − s)|² dx, hence the minus sign.
    """
    kx, ky, a = propagated_orders(layout, wavelength_um, distance_um)
    b = scipy.signal.correlate(a, a, mode="full", method="fft")
    bkx = np.arange(-(kx.size - 1), kx.size)
    bky = np.arange(-(ky.size - 1), ky.size)
    px, py = layout.period_um
    weights = b * disc_ft(np.hypot(bkx[None, :] / px, bky[:, None] / py), lens.aperture_um)
    s = np.asarray(shifts_um, dtype=np.float64)
    ex = np.exp(-2j * np.pi * s[..., 0, None] * bkx / px)
    ey = np.exp(-2j * np.pi * s[..., 1, None] * bky / py)
    return np.einsum("...y,yx,...x->...", ey, weights, ex)



def slit_power_quadrature(layout, lens: Lens, wavelength_um: float, distance_um: float, shifts_x_um,
                          panels: int = 400, nodes: int = 24):
    """Brute force for masks invariant along y: P(s) = ∫ 2 sqrt(R² − x²) |m_d(x − s)|² dx by composite
    Gauss-Legendre in θ (x = R sin θ removes the square-root end points). No Bessel functions,
    no correlation of orders: the field m_d(x) = Σ a_m e^{2πimx/p} is summed at every node."""
    kx, ky, a = propagated_orders(layout, wavelength_um, distance_um)
    row = a[ky == 0][0]
    assert np.allclose(a[ky != 0], 0.0), "mask must be invariant along y"
    R = lens.aperture_um / 2
    t, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.linspace(-math.pi / 2, math.pi / 2, panels + 1)
    half = np.diff(edges) / 2
    theta = ((edges[:-1] + half)[:, None] + half[:, None] * t[None, :]).ravel()
    weight = (half[:, None] * w[None, :]).ravel() * 2 * R * R * np.cos(theta) ** 2
    x = R * np.sin(theta)
    px = layout.period_um[0]
    shifts = np.atleast_1d(np.asarray(shifts_x_um, dtype=np.float64))
    # m_d(x − s) = Σ a_m e^{−2πims/p} e^{2πimx/p}
    coef = row[:, None] * np.exp(-2j * np.pi * np.outer(kx, shifts) / px)
    total = np.zeros(shifts.size)
    for lo in range(0, x.size, 2048):
        field = np.exp(2j * np.pi * np.outer(x[lo:lo + 2048], kx) / px) @ coef
        total += weight[lo:lo + 2048] @ (np.abs(field) ** 2)
    return total


def encircled_energy(v):
    """Fraction of the Airy power inside radius v (in units of λz/(πD)): 1 − J0² − J1²."""
    return 1.0 - j0(v) ** 2 - j1(v) ** 2


@pytest.fixture(scope="session")
def psfkit():
    return SimpleNamespace(bare_pupil=bare_pupil, display_pupil=display_pupil, airy_norm=airy_norm,
                           airy_peak=airy_peak, airy_pixel_energy=airy_pixel_energy, disc_ft=disc_ft,
                           propagated_orders=propagated_orders, series_power=series_power,
                           slit_power_quadrature=slit_power_quadrature, encircled_energy=encircled_energy,
                           j1_zeros=jn_zeros(1, 3))


# ---------------------------------------------------------------- rendering (udc_render) helpers


def toml_text(doc: dict) -> str:
    """A scene document (top-level tables of numbers, strings, booleans and lists) as TOML text."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    lines = []
    for table, body in doc.items():
        lines.append(f"[{table}]")
        lines += [f"{k} = {value(v)}" for k, v in body.items()]
        lines.append("")
    return "\n".join(lines)


def monitor_doc(image="pattern:white", framing="fill", sensor_px=(128, 64), pitch_um=24.8,
                resolution_px=(480, 270), render=None, bands=None, **content) -> dict:
    """A tiny virtual-MCIS scene document: a small panel, a small coarse sensor, 4 spp, seed 1.
    24.8 µm = 16 × the paper's 1.55 µm, so 128 × 64 px see what 2048 × 1024 px do."""
    doc = {"sensor": {"width_px": sensor_px[0], "height_px": sensor_px[1], "pitch_um": pitch_um},
           "render": {"spp": 4, "seed": 1, **(render or {})},
           "content": {"type": "monitor", "image": image, "framing": framing,
                       "resolution_px": list(resolution_px), **content}}
    if bands:
        doc["bands"] = bands
    return doc


def write_scene(path, doc: dict):
    """Write `doc` as TOML to `path` and return the validated Scene."""
    from pathlib import Path

    from udc_render.scene import load_scene
    path = Path(path)
    path.write_text(toml_text(doc))
    return load_scene(path)


@pytest.fixture(scope="session")
def udc():
    """Scene-building helpers for the render tests (tests never import conftest)."""
    return SimpleNamespace(toml_text=toml_text, monitor_doc=monitor_doc, write_scene=write_scene)


@pytest.fixture(scope="module")
def tiny_dataset_scene(tmp_path_factory):
    """The dataset tests' scene: 64 × 32 px at 49.6 µm, 3 bands, 2 spp, a 150 µm margin (4 px: 9 px kernels)."""
    path = tmp_path_factory.mktemp("scene") / "mon.toml"
    write_scene(path, monitor_doc(sensor_px=(64, 32), pitch_um=49.6, render={"spp": 2, "margin_um": 150},
                                  bands={"range_nm": [400, 700], "step_nm": 100}))
    return path


@pytest.fixture(scope="module")
def render_cache(tmp_path_factory):
    """A fresh UDC_RENDER_CACHE (LLVM probe verdicts) for a render test module, not the user's."""
    with pytest.MonkeyPatch.context() as mp:
        path = tmp_path_factory.mktemp("udc_cache")
        mp.setenv("UDC_RENDER_CACHE", str(path))
        yield path


def write_pairs(root, splits=(("train", 6), ("val", 1), ("test", 2)), size_px=(64, 96), displays=("blur",),
                gamma=0.5, blur_px=9, noise=0.01, seed=0):
    """A dataset folder in `udc-render dataset`'s layout with synthetic pairs (no rendering): smooth
    random ground truth (Gaussian blobs), capture = γ · (ground truth ⊗ a 1 × blur_px horizontal box)
    + Gaussian noise (σ = noise), mosaicked and written as raw.dng. Returns the folder."""
    import json
    from pathlib import Path

    from scipy.ndimage import gaussian_filter, uniform_filter1d

    from udc_render.io.dng import save_dng
    from udc_render.io.exr import save_exr
    from udc_render.sensor import mosaic_of
    root, rng = Path(root), np.random.default_rng(seed)
    h, w = size_px
    lines, item = [], 0
    for split, count in splits:
        for _ in range(count):
            gt = np.stack([gaussian_filter(rng.random((h, w)), 2.0) for _ in range(3)])
            gt = np.clip((gt - gt.min()) / (np.ptp(gt) + 1e-9) * 0.8, 0, 1).astype(np.float32)
            folder = Path(split) / "shard_0000" / f"item_{item:06d}"
            (root / folder).mkdir(parents=True)
            save_exr(root / folder / "gt.exr", {c: gt[i] for i, c in enumerate("RGB")})
            for d in displays:
                blurred = uniform_filter1d(gt, blur_px, axis=2, mode="nearest")
                raw = np.clip(gamma * mosaic_of(blurred) + rng.normal(0, noise, (h, w)), 0, 1)
                (root / folder / d).mkdir()
                save_dng(root / folder / d / "raw.dng", np.round(raw * 65535).astype(np.uint16), "Nikon 5100 (NPL)",
                         0, 65535)
                (root / folder / d / "capture.json").write_text(json.dumps(
                    {"sensor": {"black_level_dn": 0, "white_level_dn": 65535, "pitch_um": 1.55,
                                "camera": "Nikon 5100 (NPL)"}}))
            lines.append(json.dumps({"item": item, "split": split, "folder": str(folder), "image": f"blobs:{item}",
                                     "displays": ["glass", *displays]}))
            item += 1
    (root / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    return root


@pytest.fixture
def pairs_dir(tmp_path):
    """A small synthetic dataset folder (write_pairs' defaults)."""
    return write_pairs(tmp_path / "pairs")


# Moved to the slow suite for CI's 20 minutes (each 6–15 s on the 2-core machine; a clean-clone CI ran 20 min 5 s
# before): node id → the fast test that keeps its mechanism in CI. `pytest -m slow` runs them.
MOVED_TO_SLOW = {
    "tests/restore/test_train.py::test_tiny_unet_trained_in_bf16_beats_the_identity":
        "test_tiny_unet_learns_and_beats_the_identity_on_held_out_pairs (fp32)",
    "tests/udc_render/test_stray_light.py::test_profiles_and_records": "tests/udc_render/test_profiles.py",
    "tests/psf/test_paper_recipe.py::test_kernel_is_the_pattern_sampled_at_printed_over_formula_pitch[toled]":
        "its other parameters",
    "tests/udc_render/test_synth_fused.py::test_fused_synthesis_equals_the_per_band_reference[2.0]": "[0.0]",
    "tests/udc_render/test_fit_roundtrip.py::test_a_weak_pentile_is_fitted_from_every_order_it_shows":
        "test_fit_oracles.py::test_a_pentile_at_another_pitch_from_two_12_bit_exposures",
    "tests/udc_render/test_cli.py::test_band_weight_spectrum_from_illuminant_changes_kernels":
        "tests/psf/test_spectral.py",
    "tests/udc_render/test_depth_layers.py::test_the_sun_in_frame_synthesises_at_the_default_precision":
        "the other depth-layer tests",
    "tests/udc_render/test_paper_channel_kernels.py::test_camera_weighted_kernels_stay_an_option":
        "test_the_choice_is_recorded",
    "tests/udc_render/test_synth.py::test_per_channel_form_uses_the_papers_gamma":
        "test_presets_reproduce_the_papers_gammas",
    "tests/udc_render/test_primaries.py::test_through_the_planes_equals_the_band_path[2.0]": "[0.0]",
    "tests/udc_render/test_study_defocus.py::test_quick_study_writes_files_and_passes_checks":
        "test_blur_grows_with_defocus_on_both_sides",
    "tests/udc_render/test_design_optimise.py::test_the_search_ends_in_a_local_optimum_of_all_swaps[repeated]":
        "[turned]",
    "tests/udc_render/test_layout_restore.py::test_cli_writes_the_restored_psnr":
        "restored_psnr's own tests in the file; test_restore_is_refused_outside_layout (the option)",
}


@pytest.hookimpl(tryfirst=True)  # before -m 'not slow' deselects
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid in MOVED_TO_SLOW:
            item.add_marker(pytest.mark.slow)
