"""Planning a dataset job: which image each item shows, its split, folder and render seed."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from udc_render.errors import UdcError

SPLITS = ("train", "val", "test")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")
BUILTIN_CHARTS = ("pattern:slanted_edge", "pattern:sine_x", "pattern:sine_y", "pattern:siemens",
                  "pattern:dead_leaves:0")


class DatasetError(UdcError):
    """A dataset job that cannot run as asked; one line."""


@dataclass(frozen=True)
class Task:
    """One item: its id, split, folder (relative to OUT), image (spec and label) and render seed."""
    item: int
    split: str
    folder: str
    image: str  # what the monitor shows: an absolute file path, builtin:NAME or pattern:NAME
    label: str  # the image as recorded: a path relative to --images, or the spec
    render_seed: int


def image_list(images_dir: Path | None) -> tuple[list[tuple[str, str]], str]:
    """[(spec, label)] of the images to cycle through, and their source (the folder or 'builtin');
    images_dir None: the built-in images and charts."""
    from udc_render.content.monitor_image import BUILTIN_IMAGES
    if images_dir is None:
        return [(s, s) for s in [f"builtin:{n}" for n in BUILTIN_IMAGES] + list(BUILTIN_CHARTS)], "builtin"
    folder = Path(images_dir).resolve()
    if not folder.is_dir():
        raise DatasetError(f"--images {images_dir}: no such folder")
    files = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")
                   if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
                   and not any(part.startswith(".") for part in p.relative_to(folder).parts))
    if not files:
        raise DatasetError(f"--images {images_dir}: no images ({', '.join(IMAGE_SUFFIXES)}) in the folder")
    return [(str(folder / f), f) for f in files], str(folder)


def image_of(images: list[tuple[str, str]], builtin: bool, i: int) -> tuple[str, str]:
    """Item i's image: the list cycled, or (builtin) new dead-leaves seeds after the list."""
    if builtin and i >= len(images):
        spec = f"pattern:dead_leaves:{i - len(images) + 1}"
        return spec, spec
    return images[i % len(images)]


def render_seed(base: int, item: int) -> int:
    """Mitsuba's uint32 base seed of item `item`."""
    return int(np.random.SeedSequence([base, item]).generate_state(1)[0])


def plan_tasks(count: int, split: tuple[int, int, int], shard_size: int, images, builtin: bool, base_seed: int) -> list[Task]:
    tasks = []
    for name, n in zip(SPLITS, split):
        for pos in range(n):
            i = len(tasks)
            spec, label = image_of(images, builtin, i)
            tasks.append(Task(i, name, f"{name}/shard_{pos // shard_size:04d}/item_{i:06d}", spec, label,
                              render_seed(base_seed, i)))
    return tasks
