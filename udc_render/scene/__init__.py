"""The scene stage: a TOML file ──► a frozen, validated Scene (rig, lens, sensor, bands, render, content).

    model.py      the dataclasses (Scene, Lens, Sensor, Bands, Render, Monitor, Room, HDRRoom, MitsubaXML)
    parse.py      TOML ──► Scene with one-line errors; the built-in scenes; --bands-nm syntax
    overrides.py  the command-line overrides (spp, noise, seed, bands, image, sensor size, pitch)
    geometry.py   facts derived from a scene: camera pose, render grid, the psf lens
"""
from udc_render.scene.model import (
    RENDER_PATHS,
    SAMPLERS,
    Bands,
    Camera,
    HDRRoom,
    Lens,
    MitsubaXML,
    Monitor,
    Render,
    Room,
    Scene,
    SceneError,
    Sensor,
    XMLCamera,
)
from udc_render.scene.parse import load_scene, parse_bands, parse_scene, scenes_dir

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "parse_bands", "scenes_dir", "Monitor", "Room",
           "HDRRoom", "MitsubaXML", "XMLCamera", "Camera", "Lens", "Sensor", "Bands", "Render", "RENDER_PATHS",
           "SAMPLERS"]
