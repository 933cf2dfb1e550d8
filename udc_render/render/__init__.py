"""The render stage: a Scene ──► BandImage (radiance in K bands at the sensor plane, + depth), with
Mitsuba 3 (the only package that imports it), or exactly where the scene allows (analytic.py).

    job.py            render_scene: paths (analytic, rgb_matrix, spectral), passes, samplers, noise estimate, depth
    analytic.py       the monitor alone: exact pixel-area means of the panel (no Monte Carlo)
    band_image.py     BandImage, band_names
    mitsuba_scene.py  Mitsuba scene dicts of the monitor rig and 3D content
    variants.py       the Mitsuba variant (LLVM probe, scalar fallback)
    xml_camera.py     a user's Mitsuba XML: loading it once, resolve_xml_camera (its sensor's pose into the scene)
"""
from udc_render.render.band_image import BandImage, band_names
from udc_render.render.errors import RenderError
from udc_render.render.job import choose_path, render_scene
from udc_render.render.xml_camera import resolve_xml_camera

__all__ = ["BandImage", "RenderError", "band_names", "choose_path", "render_scene", "resolve_xml_camera"]
