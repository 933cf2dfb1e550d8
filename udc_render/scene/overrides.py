"""Overrides of a scene's settings (what the command line's --spp, --image, … change), without argparse.

    scene = with_overrides(load_scene("monitor"), spp=16, image="builtin:camera", sensor_px=(512, 256))

Every bad value raises SceneError naming the option, the value and what is allowed.
"""
from __future__ import annotations

from dataclasses import replace

from udc_render.scene.model import Monitor, Scene, SceneError
from udc_render.scene.parse import parse_bands


def with_overrides(scene: Scene, *, spp: int | None = None, noise: float | None = None, seed: int | None = None,
                   path: str | None = None, bands_nm: str | None = None, image: str | None = None,
                   sensor_px: tuple[float, float] | None = None, pitch_um: float | None = None,
                   sampler: str | None = None) -> Scene:
    """The scene with each given setting replaced (None: the scene's own)."""
    if spp is not None and noise is not None:
        raise SceneError(f"--spp = {spp} and --noise = {noise}: give one of them")
    if spp is not None:
        scene = scene.with_render(spp=spp, noise=None)
    if noise is not None:
        scene = scene.with_render(spp=None, noise=noise)
    if seed is not None:
        if not 0 <= seed < 2**32:
            raise SceneError(f"--seed = {seed}: expected 0 <= seed < 2^32")
        scene = scene.with_render(seed=seed)
    if path is not None:
        if path == "rgb_matrix" and not isinstance(scene.content, Monitor):
            raise SceneError(f"--path rgb_matrix: only for the monitor alone; {scene.source} has "
                             f"{scene.content_type} content")
        if path == "analytic" and not (isinstance(scene.content, Monitor) and scene.lens.model == "pinhole"):
            raise SceneError(f"--path analytic: only for the monitor alone through a pinhole lens; {scene.source} has "
                             f"{scene.content_type} content and lens.model = {scene.lens.model!r}")
        scene = scene.with_render(path=path)
    if sampler is not None:
        scene = scene.with_render(sampler=sampler)
    if bands_nm is not None:
        scene = scene.with_bands(parse_bands(bands_nm))
    if image is not None:
        if not isinstance(scene.content, Monitor):
            raise SceneError(f"--image: only for monitor scenes; {scene.source} has {scene.content_type} content")
        scene = replace(scene, content=replace(scene.content, image=image))
    if sensor_px is not None:
        scene = _with_sensor_px(scene, sensor_px)
    if pitch_um is not None:
        scene = replace(scene, sensor=replace(scene.sensor, pitch_um=pitch_um))
    return scene


def _with_sensor_px(scene: Scene, sensor_px: tuple[float, float]) -> Scene:
    w, h = sensor_px
    if w != int(w) or h != int(h):
        raise SceneError(f"--sensor-px = {w:g},{h:g}: expected whole numbers of pixels")
    return replace(scene, sensor=replace(scene.sensor, width_px=int(w), height_px=int(h)))
