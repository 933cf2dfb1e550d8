"""The datasets of `udc-render results`: the monitor scene through glass, T-OLED and P-OLED, once per
profile (restore.studies.budgets), made or resumed with udc_render.dataset.
"""
from __future__ import annotations

from pathlib import Path

from restore.studies.budgets import DISPLAYS, PROFILES
from udc_render.dataset import DatasetJob, run_dataset
from udc_render.optics.displays import load_displays
from udc_render.pipeline import SynthConfig
from udc_render.profiles import resolve_profile
from udc_render.scene import load_scene
from udc_render.scene.overrides import with_overrides


def dataset_job(profile: str, sensor_px: tuple[int, int], folder: Path, split: tuple[int, int, int],
                images_dir: Path | None = None):
    """The DatasetJob of the monitor scene at sensor_px through glass, T-OLED and P-OLED under `profile`
    (the built-in content, or the images in images_dir)."""
    scene = with_overrides(load_scene("monitor"), sensor_px=sensor_px)
    cfg, displays = resolve_profile(profile, SynthConfig(), load_displays(",".join(DISPLAYS)))
    return DatasetJob(scene, displays, cfg, out=folder, split=split, images_dir=images_dir)


def dataset_folders(out: Path) -> dict[str, Path]:
    """{profile: the folder of its dataset in `out`}."""
    return {p: out / f"dataset_{p}" for p in PROFILES}


def make_dataset(out: Path, b: dict, profile: str, progress: bool) -> Path:
    """The profile's dataset, made or resumed: the built-in images and charts through glass, T-OLED and P-OLED
    at the budget's framing (physical: the tables' train and test pairs; paper: the UNet (Syn) row's training
    pairs, the paper's own synthesis). Returns its folder."""
    folder = dataset_folders(out)[profile]
    run_dataset(dataset_job(profile, b["sensor_px"], folder, tuple(b["items"])), progress=progress)
    return folder
