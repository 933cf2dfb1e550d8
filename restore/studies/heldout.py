"""Held-out photographs: a second test set of natural content that no model trains on.

The datasets cycle through six scikit-image photographs and five charts, then colour dead leaves
(udc_render.dataset.plan), so the val and test splits are all dead leaves. This set asks whether the
paper's orderings depend on that content: the other photographs and micrographs of at least 256 px
that scikit-image ships offline (HELD_OUT: textures, coins, the moon, a cell, a clock, a galaxy field,
a retina and a street scene; left out: the text page and the binary horse, not photographs, and the
102-px microaneurysms). Written as
PNG and rendered through the physical profile by `udc-render dataset --images` at the budget's
framing, test split only. It is a diagnostic beside the paper's test split, not a replacement: the
list is fixed by what scikit-image ships, not chosen by score.
"""
from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio

from restore.studies.datasets import dataset_job
from udc_render.dataset import run_dataset
from udc_render.io.files import atomic_path


def _motorcycle():
    import skimage.data
    return skimage.data.stereo_motorcycle()[0]  # the left view of the stereo pair


HELD_OUT = {name: name for name in ("brick", "grass", "gravel", "coins", "moon", "cell", "clock",
                                    "hubble_deep_field", "retina")} | {"motorcycle": _motorcycle}


def load_held_out(name: str):
    """The uint8 image [rows, cols(, 3)] of HELD_OUT[name] from scikit-image's shipped data."""
    import skimage.data
    source = HELD_OUT[name]
    return getattr(skimage.data, source)() if isinstance(source, str) else source()


def write_held_out(folder: Path, count: int | None = None) -> Path:
    """The first `count` (None: all) HELD_OUT images as PNG in `folder` (atomic writes; existing
    files kept); returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in list(HELD_OUT)[:count]:
        path = folder / f"{name}.png"
        if not path.is_file():
            with atomic_path(path, ".png") as tmp:
                iio.imwrite(tmp, load_held_out(name))
    return folder


def make_held_out_dataset(out: Path, sensor_px: tuple[int, int], count: int | None, progress: bool) -> Path:
    """The held-out photographs through glass, T-OLED and P-OLED, physical profile, test split only,
    made or resumed in out/dataset_heldout (images in out/heldout_images); returns the dataset folder."""
    images = write_held_out(out / "heldout_images", count)
    folder, n = out / "dataset_heldout", len(list(images.glob("*.png")))
    run_dataset(dataset_job("physical", sensor_px, folder, (0, 0, n), images), progress=progress)
    return folder
