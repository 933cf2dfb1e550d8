"""`design --banding-ceiling` (udc_render.design.bands): the torch power against tiling_power (numpy, checked against
the exact power series in test_tiling_power), a D4-symmetric cell's bands alike on both tilings, the hinge in
closed form, the gradient against finite differences, design.json's banding against `study layout`'s committed
draws, and the refusals."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from psf.lens import Lens
from udc_render import cli
from udc_render.design import job
from udc_render.design.bands import BANDING_WEIGHT, BandingCeiling, relative_sd
from udc_render.design.cells import toled_reference
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import RIG_WAVELENGTHS_NM, Designer
from udc_render.design.tiling_power import shift_span_um, tiling_power

CEILED = dict(objective="crop", contrast=1.0, pupil_samples=64, kernel_px=31, scatters=1, steps=1, candidates=2,
              far_veil=True)
DRAWS = Path(__file__).resolve().parents[2] / "docs/figures/design/banding_draws"


def _binary21(k: int, seed: int) -> np.ndarray:
    flat = np.zeros(441)
    flat[np.random.default_rng(seed).permutation(441)[:k]] = 1.0
    return flat.reshape(21, 21)


def _ceiling(ratio: float = 1.0, turned: bool = True) -> BandingCeiling:
    return BandingCeiling(ratio, 21, 168.0, 0.2, RIG_WAVELENGTHS_NM, seed=0, turned=turned)


def _numpy_bands(cell: np.ndarray, ceiling: BandingCeiling, which: str) -> np.ndarray:
    """[channels] the root mean variance over the draws of tiling_power's P / its mean (numpy, 8 µm raster)."""
    span = shift_span_um(Lens(), 2000.0)
    out = []
    for turns in ceiling.transforms(which):
        plan = (lambda n: turns) if turns is not None else None
        powers = [tiling_power(cell, 8.0, Lens(), wl, 2000.0, span, plan, 8.0)[0] for wl in RIG_WAVELENGTHS_NM]
        out.append([p.std() / p.mean() for p in powers])
    return np.sqrt(np.mean(np.square(out), axis=0))


@pytest.mark.parametrize("turned", [True, False])
def test_the_ceilings_power_is_tiling_power_in_torch(turned):
    """P(s) per channel equals tiling_power's on the same window, raster and tiling (float64, 1e-10 of the mean)."""
    ceiling, cell = _ceiling(turned=turned), _binary21(88, 3)
    turns = ceiling.transforms("search")[0]
    span = shift_span_um(Lens(), 2000.0)
    with torch.no_grad():
        got = ceiling.power(torch.tensor(cell), turns)
    for wl, p in zip(RIG_WAVELENGTHS_NM, got):
        plan = None if turns is None else (lambda n: turns)
        expected, step = tiling_power(cell, 8.0, Lens(), wl, 2000.0, span, plan, 8.0)
        assert step == 8.0 and p.shape == expected.shape
        assert np.abs(p.numpy() - expected).max() < 1e-10 * expected.mean()


def _plain_at_the_corner(ceiling: BandingCeiling, cell: np.ndarray) -> np.ndarray:
    """[channels] the relative sd over the span of the plain tiling at one registration (a tile's corner on the
    axis), the turned draws' registration."""
    return np.array([float(relative_sd(p)) for p in ceiling.power(torch.tensor(cell), None)])


def test_a_d4_symmetric_cell_bands_alike_turned_and_plain():
    """A cell unchanged by every D4 element tiles the same display turned or not: at the same registration the
    same bands (an invariant); an asymmetric cell's differ."""
    sym = np.zeros((21, 21))
    sym[7:14, 9:12] = sym[9:12, 7:14] = 1.0
    turned, plain = _ceiling(turned=True), _ceiling(turned=False)
    with torch.no_grad():
        a, b = turned.bands(torch.tensor(sym), "search").numpy(), _plain_at_the_corner(plain, sym)
        c = turned.bands(torch.tensor(_binary21(88, 2)), "search").numpy()
        d = _plain_at_the_corner(plain, _binary21(88, 2))
    assert np.allclose(a, b, rtol=1e-10) and np.all(np.abs(c / d - 1) > 1e-3)


def test_the_turned_bands_in_the_cameras_channels_are_the_rigs():
    """The camera's channels (the band at 40 nm, S_c(λ) D65(λ) δλ: the bank's) print the bands of the rig's three
    wavelengths: the power adds over λ, and a turned tiling's bands are its dipole's, geometric to leading order
    (docs/guides/design.md). Two committed veil designs and the T-OLED, one draw, 8 µm squares: each channel's sd and
    the design-to-T-OLED ratio within 2 % (a bound set before this raster was run; the 2 µm raster over draws 0-4
    gave at most 1.5 % and 1.0 %)."""
    from psf.spectral import channel_weights
    from udc_render.design.cells import read_cell
    from udc_render.design.optimise import CHANNEL_ILLUMINANT
    from udc_render.sensor.config import SensorConfig
    lam, w, _, _ = channel_weights(SensorConfig().camera, CHANNEL_ILLUMINANT, 40.0)
    camera = BandingCeiling(1.0, 21, 168.0, 0.2, tuple(lam), seed=0, turned=True)
    rig = _ceiling()
    turns = rig.transforms("search")[0]
    root = DRAWS.parents[0]
    cells = {"toled": toled_reference(168.0, 0.2)}
    for name in ("design_veil", "channel_step/spec_veil_b100"):
        cells[name] = read_cell(str(root / name / "cell.png"), 21, 88)
    sd = {}
    with torch.no_grad():
        for name, cell in cells.items():
            per_lam = torch.stack(camera.power(torch.tensor(cell), turns))
            summed = torch.einsum("ck,kyx->cyx", torch.tensor(w), per_lam)
            sd[name] = (np.array([float(p.std() / p.mean()) for p in summed]),
                        np.array([float(p.std() / p.mean()) for p in rig.power(torch.tensor(cell), turns)]))
    for name, (cam, three) in sd.items():
        assert np.all(np.abs(cam / three - 1) < 0.02), (name, cam, three)
        ratio_cam, ratio_rig = cam / sd["toled"][0], three / sd["toled"][1]
        assert np.all(np.abs(ratio_cam / ratio_rig - 1) < 0.02), (name, ratio_cam, ratio_rig)


def test_the_ceiling_multiplies_the_objective_by_its_hinge():
    """searched = J (1 + BANDING_WEIGHT Σ_c max(0, log ratio_c − log R)), ratio_c from tiling_power (numpy): J at or
    below the ceiling, the closed form above it; the T-OLED over itself is 1."""
    cell = _binary21(88, 5)
    x = torch.tensor(cell)
    probe = _ceiling()
    ratio = _numpy_bands(cell, probe, "search") / _numpy_bands(toled_reference(168.0, 0.2), probe, "search")
    with torch.no_grad():
        assert np.allclose(probe.ratios(x, "search").numpy(), ratio, rtol=1e-10)
        assert np.allclose(probe.ratios(torch.tensor(toled_reference(168.0, 0.2)), "final").numpy(), 1, rtol=1e-12)
    plain = Designer(DesignConfig(**CEILED))
    with torch.no_grad():
        j = float(plain.objective(x, plain.transforms("search")))
        for r, factor in ((2.0 * ratio.max(), 1.0), (0.5 * ratio.min(), None)):
            expected = factor or 1 + BANDING_WEIGHT * np.sum(np.log(ratio) - np.log(r))
            ceiled = Designer(DesignConfig(**CEILED, banding_ceiling=float(r)))
            assert abs(float(ceiled.searched(x, "search")) / (j * expected) - 1) < 1e-9
            assert np.allclose(ceiled.score(cell, "search")["banding_ratios"], ratio, rtol=1e-10)


def test_the_ceilings_gradient_matches_finite_differences():
    """d ratios / d cell along a swap direction (one square closed, one opened) against central differences."""
    ceiling, cell = _ceiling(), _binary21(88, 6)
    flat = cell.ravel()
    direction = np.zeros(441)
    direction[np.flatnonzero(flat)[0]], direction[np.flatnonzero(flat == 0)[0]] = -1.0, 1.0
    x = torch.tensor(cell, requires_grad=True)
    ceiling.ratios(x, "search").sum().backward()
    analytic = float(x.grad.numpy().ravel() @ direction)
    h = 1e-5
    with torch.no_grad():
        f = [float(ceiling.ratios(torch.tensor(cell + s * h * direction.reshape(21, 21)), "search").sum())
             for s in (1, -1)]
    assert abs(analytic - (f[0] - f[1]) / (2 * h)) < 1e-6 * max(1.0, abs(analytic))


def _study_sd(folder: str, wavelength: int) -> float:
    """The turned tiling's sd at the wavelength in a committed `study layout` report (3 significant digits)."""
    text = (DRAWS / folder / "study_layout.md").read_text()
    text = text[text.index("P(s) sampled"):]
    return float(re.search(rf"\| {wavelength} \| [^|]+\| [^,]+, ([0-9.e+-]+) \|", text).group(1))


def test_design_json_banding_is_study_layouts_on_the_same_draw():
    """banding_comparison on draw 1: the `crop` design's and the T-OLED's sd as `study layout --tile-seed 1` printed
    them (the committed reports, to their 3 digits), and the ratio theirs."""
    from udc_render.design.cells import read_cell
    cell = read_cell(str(DRAWS.parents[0] / "design_crop/cell.png"), 21, 88)
    doc = job.banding_comparison(cell, DesignConfig(), seeds=(1,))
    for name, folder in (("design", "crop_s1"), ("toled_edge", "toled_s1")):
        for c, wl in enumerate((640, 520, 450)):
            printed = _study_sd(folder, wl)
            assert abs(doc["sd"][name][0][c] - printed) <= 0.5001 * 10 ** (np.floor(np.log10(printed)) - 2)
    assert np.allclose(doc["ratio"][0], np.divide(doc["sd"]["design"][0], doc["sd"]["toled_edge"][0]))
    assert doc["below"] == [1, 1, 1] and doc["seeds"] == [1]


@pytest.mark.slow  # 20-80 s on a core: out of CI's 20 min
def test_a_design_run_with_the_ceiling_writes_its_banding(tmp_path, monkeypatch):
    """The run's design.json holds the held-out banding on the study's draws and the ceiling's ratios in its scores."""
    monkeypatch.setattr(job, "BANDING_SEEDS", (0,))
    assert cli.main(["design", "--objective", "crop", "--far-veil", "--pupil-samples", "64", "--kernel-px", "31",
                     "--scatters", "1", "--steps", "1", "--candidates", "2", "--banding-ceiling", "0.9", "--quiet",
                     "--out", str(tmp_path / "run")]) == 0
    doc = json.loads((tmp_path / "run/design.json").read_text())
    assert doc["banding"]["seeds"] == [0] and len(doc["banding"]["ratio"][0]) == 3
    assert len(doc["final"]["banding_ratios"]) == 3 and doc["config"]["banding_ceiling"] == 0.9


@pytest.mark.parametrize("argv, says", [
    (["--banding-ceiling", "0"], "--banding-ceiling"),
    (["--objective", "rings", "--banding-ceiling", "1"], "--banding-ceiling: takes --objective wiener or crop"),
    (["--optics", "upc", "--objective", "upc", "--banding-ceiling", "1"], "--banding-ceiling: takes --objective"),
])
def test_the_ceiling_refuses_in_one_line(tmp_path, capsys, argv, says):
    assert cli.main(["design", *argv, "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "never").exists()
