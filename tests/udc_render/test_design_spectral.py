"""--channel-step: the designer's objective on the camera's channel kernels (torch_psf.channel_sum,
optimise.objective_wavelengths) against the engine's psf.spectral.channel_kernels."""
from __future__ import annotations

import numpy as np
import torch

from psf import Lens
from psf.micrograph import MicrographLayout
from psf.spectral import channel_kernels, channel_weights
from udc_render.design import metrics, torch_psf as tp
from udc_render.design.config import DesignConfig
from udc_render.design.optimise import CHANNEL_ILLUMINANT, Designer
from udc_render.sensor.config import SensorConfig

TINY = dict(cell_um=40.0, feature_um=8.0, open_fraction=0.24, pupil_samples=64, kernel_px=31, scatters=2, seed=3,
            channel_step_nm=40.0)


def _cell() -> np.ndarray:
    flat = np.zeros(25)
    flat[np.random.default_rng(0).permutation(25)[:6]] = 1.0
    return flat.reshape(5, 5)


def _engine(cell: np.ndarray, turned: bool):
    return channel_kernels(MicrographLayout("cell", 8.0, random_rotation=turned, seed=0, image=cell), Lens(),
                           SensorConfig().camera, CHANNEL_ILLUMINANT, step_nm=40.0, size_px=31, pupil_samples=64,
                           precision="float64")


def test_the_summed_kernels_are_the_engines_channel_kernels():
    """kernels_and_window at the camera's band, summed by channel_sum, equal psf.spectral.channel_kernels' kernels
    (to 1e-12 of their peak) and their shares inside the window (1 − energy_outside): with the engine's
    quarter-turns to 1e-12 (the same raster sum per wavelength, test_design_torch_psf); plainly tiled the engine takes
    its exact power series, whose per-wavelength gap test_design_torch_psf measured at 0.2–1.3 %. (A first bound of
    1 % here failed at 1.1 %, inside that range: the bound is the range's 1.3 %.)"""
    cell = _cell()
    for turned, bound in ((False, 0.013), (True, 1e-12)):
        d = Designer(DesignConfig(**TINY, tiling="turned" if turned else "repeated"))
        square = MicrographLayout("c", 8.0, random_rotation=True, seed=0, image=np.ones((5, 5)))
        draw = square.tile_rotations(d.tiles, d.tiles) if turned else None
        k, inside = tp.channel_sum(*tp.kernels_and_window(torch.tensor(cell), d.grid, draw), d.channel_weights)
        engine = _engine(cell, turned)
        assert np.abs(k.numpy() - engine.kernels).max() < 1e-12 * engine.kernels.max()
        assert np.abs(inside.numpy() / (1 - np.asarray(engine.energy_outside)) - 1).max() < bound


def test_the_objective_is_the_restorability_of_the_engines_channel_kernels():
    """The wiener objective at --channel-step equals metrics.restorability of the engine's channel kernels at the open
    area × channel_sum's share inside (as the one-wavelength test in test_design_optimise), to 1e-10; the weights
    are psf.spectral.channel_weights' for the sensor's camera and D65."""
    cell = _cell()
    d = Designer(DesignConfig(**TINY, tiling="repeated"))
    lam, w, _, _ = channel_weights(SensorConfig().camera, "D65", 40.0)
    assert d.grid.wavelengths_nm == tuple(lam) and np.array_equal(d.channel_weights.numpy(), w)
    _, inside = tp.channel_sum(*tp.kernels_and_window(torch.tensor(cell), d.grid, None), d.channel_weights)
    ref = np.mean(metrics.restorability(_engine(cell, False).kernels, 0.24 * inside.numpy())["wiener_mse"])
    assert abs(d.score(cell)["objective"] / ref - 1) < 1e-10


def test_without_a_step_the_objective_is_the_rigs_three_wavelengths():
    d = Designer(DesignConfig(**{**TINY, "channel_step_nm": 0.0}))
    assert d.grid.wavelengths_nm == (640.0, 520.0, 450.0) and d.channel_weights is None
