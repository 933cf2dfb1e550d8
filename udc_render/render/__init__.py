"""The render stage: a Scene ──► BandImage (radiance in K bands at the sensor plane, + depth), with
Mitsuba 3. The only package that imports Mitsuba.

    job.py            render_scene: paths (rgb_matrix, spectral), passes, noise estimate, depth
    band_image.py     BandImage, band_names
    mitsuba_scene.py  Mitsuba scene dicts of the monitor rig and 3D content
    variants.py       the Mitsuba variant (LLVM probe, scalar fallback)
"""
from udc_render.render.band_image import BandImage, band_names
from udc_render.render.job import RenderError, choose_path, render_scene

__all__ = ["BandImage", "RenderError", "band_names", "choose_path", "render_scene"]
