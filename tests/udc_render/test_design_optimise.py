"""`udc-render design` (udc_render.design.optimise, .job): the objective against the engine, the projection, the
resume, the display file every command takes, and the refusals."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from psf import Lens, compute_kernels
from psf.micrograph import MicrographLayout
from udc_render import cli
from udc_render.design import job, metrics
from udc_render.design.optimise import RIG_WAVELENGTHS_NM, DesignConfig, Designer, project
from udc_render.optics.displays import DisplayError, load_display

TINY = dict(cell_um=40.0, feature_um=8.0, open_fraction=0.24, steps=4, pupil_samples=64, kernel_px=31)


def test_project_opens_the_most_open_squares():
    a = np.array([[0.9, 0.1, 0.5], [0.2, 0.8, 0.3], [0.0, 0.4, 0.7]])
    assert np.array_equal(project(a, 3 / 9), [[1, 0, 0], [0, 1, 0], [0, 0, 1]])


def test_the_wiener_objective_is_the_restorability_of_the_engines_kernels():
    """A binary cell's objective (torch) equals metrics.restorability on psf.compute_kernels' kernels (numpy)."""
    d = Designer(DesignConfig(tiling="repeated", **TINY))
    cell = project(np.random.default_rng(0).random((5, 5)), 0.24)
    _, parts = d.objective(torch.tensor(cell), None)
    ks = compute_kernels(MicrographLayout("cell", 8.0, image=cell), Lens(), RIG_WAVELENGTHS_NM, size_px=31,
                         pupil_samples=64, precision="float64").kernels
    ref = np.mean(metrics.restorability(ks, float(cell.mean()))["wiener_mse"])
    assert abs(parts["objective"] / ref - 1) < 1e-10 and abs(parts["open_area"] - 6 / 25) < 1e-15


def test_an_interrupted_run_resumes_to_the_same_result(tmp_path, monkeypatch):
    config = DesignConfig(**TINY)
    whole = job.run_design(config, tmp_path / "whole", quiet=True)
    monkeypatch.setattr(job, "CHECKPOINT_STEPS", 2)
    real_step = Designer.step

    def interrupt(self):
        if self.step_done == 3:
            raise KeyboardInterrupt
        return real_step(self)
    monkeypatch.setattr(Designer, "step", interrupt)
    with pytest.raises(KeyboardInterrupt):
        job.run_design(config, tmp_path / "cut", quiet=True)
    monkeypatch.setattr(Designer, "step", real_step)
    again = job.run_design(config, tmp_path / "cut", quiet=True)
    assert again["losses"] == whole["losses"] and again["final"] == whole["final"]
    with pytest.raises(Exception, match="other settings"):
        job.run_design(DesignConfig(**{**TINY, "seed": 1}), tmp_path / "cut", quiet=True)


def test_the_designed_display_files_are_displays(tmp_path):
    doc = job.run_design(DesignConfig(**{**TINY, "steps": 2}), tmp_path, quiet=True)
    plain, turned = load_display(str(tmp_path / "design.toml")), load_display(str(tmp_path / "design_turned.toml"))
    assert plain.layout.image.shape == (5, 5) and plain.layout.pixel_um == 8.0 and not plain.layout.random_rotation
    assert turned.layout.random_rotation and abs(plain.layout.open_fraction - doc["open_squares"] / 25) < 1e-15
    assert abs(plain.gain - round(25 / doc["open_squares"], 3)) < 1e-12
    assert json.loads((tmp_path / "design.json").read_text())["cell_px"] == 5
    assert (tmp_path / "design_loss.png").stat().st_size > 0
    bad = tmp_path / "bad.toml"
    bad.write_text((tmp_path / "design_turned.toml").read_text().replace("tile_rotation = true",
                                                                          'tile_rotation = "yes"'))
    with pytest.raises(DisplayError, match="tile_rotation"):
        load_display(str(bad))


@pytest.mark.parametrize("argv, says", [
    (["--open-area", "1.2"], "--open-area 1.2: expected a fraction in (0, 1)"),
    (["--feature-um", "1"], "--feature-um 1.0: below the 1.5 µm"),
    (["--cell-um", "170"], "--cell-um 170.0: the minimum feature size 8.0 µm cannot tile it"),
    (["--open-area", "0.001"], "less than one 8.0 µm square"),
])
def test_design_refuses_in_one_line(tmp_path, capsys, argv, says):
    assert cli.main(["design", *argv, "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "never").exists()


@pytest.mark.slow
def test_the_written_out_adam_is_torchs():
    """Designer._adam against torch.optim.Adam (slow: its first use imports torch._dynamo) on 5 steps."""
    d = Designer(DesignConfig(tiling="repeated", **TINY))
    ref = d.theta.detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([ref], lr=d.config.lr)
    target = torch.tensor(np.random.default_rng(5).random((5, 5)))
    for t in range(1, 6):
        opt.zero_grad()
        ((ref - target) ** 4).sum().backward()
        opt.step()
        d.theta.grad = None
        ((d.theta - target) ** 4).sum().backward()
        d._adam(d.theta.grad, t)
    assert torch.allclose(d.theta, ref, rtol=0, atol=1e-12)
