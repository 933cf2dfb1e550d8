"""Planning a dataset job: which image each item shows (a monitor scene) or from where it sees the scene
(a 3D scene: Views), its split, folder and render seed."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from udc_render.content.monitor_image import BUILTIN_IMAGES
from udc_render.errors import UdcError
from udc_render.streams import stream

SPLITS = ("train", "val", "test")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")
BUILTIN_CHARTS = ("pattern:slanted_edge", "pattern:sine_x", "pattern:sine_y", "pattern:siemens",
                  "pattern:dead_leaves:0")
# after the built-in list, item by item: dead leaves in the colours of a built-in photograph (the grey ones
# taught restorers a grey world: on a colour chart they painted grey discs, README "Status")
BUILTIN_THEN = "pattern:dead_leaves_colour"
# a 3D scene's per-item camera moves (± metres per world axis x, y, z): small against the built-in rooms
# (4 × 2.6 × 5.5 m, the camera 5.4 m from its target), so every view stays inside the room and on its objects
DEFAULT_ORIGIN_JITTER_M = (0.15, 0.1, 0.15)
DEFAULT_TARGET_JITTER_M = (0.3, 0.2, 0.0)


class DatasetError(UdcError):
    """A dataset job that cannot run as asked; one line."""


Pose = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]


@dataclass(frozen=True)
class Task:
    """One item: its id, split, folder (relative to OUT), image (spec and label; a monitor scene) or camera
    pose (origin, target, up in metres; a 3D scene), render seed, and its panel (a randomized job's)."""
    item: int
    split: str
    folder: str
    image: str | None  # what the monitor shows: an absolute file path, builtin:NAME or pattern:NAME
    label: str | None  # the image as recorded: a path relative to --images, or the spec
    render_seed: int
    pose: Pose | None = None  # a 3D scene's camera for this item (Views.pose); None: a monitor item
    panel: int | None = None  # --randomize: the item's panel (randomize.capture_panel); None: not randomized


@dataclass(frozen=True)
class Views:
    """A 3D scene's items: item 0 sees the scene from its own pose (origin, target, up); item i > 0 moves
    the origin by u[0:3] · origin_jitter_m and the target by u[3:6] · target_jitter_m (per world axis),
    u = streams.stream(base seed, 'pose', i).uniform(−1, 1, 6) (not SeedSequence([base seed, i]), which
    render_seed turns into the item's Mitsuba seed: one stream for two draws); the up vector is kept. The focus
    distance is not part of a pose: the job fixes it at the base pose's (same kernels for every item)."""
    origin_m: tuple[float, float, float]
    target_m: tuple[float, float, float]
    up: tuple[float, float, float]
    origin_jitter_m: tuple[float, float, float] = DEFAULT_ORIGIN_JITTER_M
    target_jitter_m: tuple[float, float, float] = DEFAULT_TARGET_JITTER_M

    def pose(self, base_seed: int, item: int) -> Pose:
        if item == 0:
            return self.origin_m, self.target_m, self.up
        u = stream(base_seed, "pose", item).uniform(-1.0, 1.0, 6)
        origin = tuple(float(v) for v in np.add(self.origin_m, u[:3] * np.asarray(self.origin_jitter_m, float)))
        target = tuple(float(v) for v in np.add(self.target_m, u[3:] * np.asarray(self.target_jitter_m, float)))
        axis = np.subtract(target, origin)
        n = float(np.linalg.norm(axis))
        if not n > 1e-6 or float(np.linalg.norm(np.cross(axis / n, self.up))) < 1e-3:
            raise DatasetError(f"item {item}: the jittered camera at {_fmt(origin)} looking at {_fmt(target)} has no "
                               f"view direction apart from up {_fmt(self.up)}; use a smaller --pose-jitter-m or "
                               f"--target-jitter-m")
        return origin, target, self.up

    def describe(self) -> dict:
        return {"base": {"origin_m": list(self.origin_m), "target_m": list(self.target_m), "up": list(self.up)},
                "origin_jitter_m": list(self.origin_jitter_m), "target_jitter_m": list(self.target_jitter_m),
                "draw": "item 0: the base pose; item i: origin += u[0:3]·origin_jitter_m, target += "
                        "u[3:6]·target_jitter_m, u = udc_render.streams.stream(render_seed, 'pose', i)"
                        ".uniform(-1, 1, 6)"}


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def pose_record(pose: Pose) -> dict:
    """An item's pose as item.json and the manifest record it."""
    origin, target, up = pose
    return {"origin_m": list(origin), "target_m": list(target), "up": list(up)}


def image_list(images_dir: Path | None) -> tuple[list[tuple[str, str]], str]:
    """[(spec, label)] of the images to cycle through, and their source (the folder or 'builtin');
    images_dir None: the built-in images and charts."""
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
    """Item i's image: the list cycled, or (builtin) after the list a new seed of BUILTIN_THEN per item."""
    if builtin and i >= len(images):
        spec = f"{BUILTIN_THEN}:{i - len(images) + 1}"
        return spec, spec
    return images[i % len(images)]


def render_seed(base: int, item: int) -> int:
    """Mitsuba's uint32 base seed of item `item`: SeedSequence([base, item]).generate_state(1)[0]. Item 0's is
    SeedSequence(base)'s (numpy pads the entropy with zeros), which no other draw of a job uses: the passes
    draw from SeedSequence([this seed, group, pass]) (render.job.pass_seed), a pose from stream(base, 'pose', i)."""
    return int(np.random.SeedSequence([base, item]).generate_state(1)[0])


def plan_tasks(count: int, split: tuple[int, int, int], shard_size: int, images, builtin: bool, base_seed: int,
               views: Views | None = None) -> list[Task]:
    """Every item's Task: with `views` (a 3D scene) each has its pose and no image, else its image."""
    tasks = []
    for name, n in zip(SPLITS, split):
        for pos in range(n):
            i = len(tasks)
            spec, label = image_of(images, builtin, i) if views is None else (None, None)
            tasks.append(Task(i, name, f"{name}/shard_{pos // shard_size:04d}/item_{i:06d}", spec, label,
                              render_seed(base_seed, i), None if views is None else views.pose(base_seed, i)))
    return tasks
