"""udc-render: physically based simulation of under-display camera capture.

The folders follow one capture's data flow (docs/ARCHITECTURE.md):

    scene/     TOML ──► Scene (rig, lens, sensor, bands, content); the render grid and the psf lens
    content/   what the monitor shows; spectra
    render/    Scene ──► BandImage (Mitsuba 3)
    optics/    kernels (from psf) applied to the band images; the displays
    sensor/    radiance ──► RGGB RAW (radiometry, noise, Bayer)
    pipeline.py  plan_kernels(scene) ∥ render_scene(scene) ──► synthesize
    io/        every file format, reader beside writer
    dataset/   many items, resumable, on a process pool or Dask
    studies/, calibration/   experiments on the pipeline
    cli/       the `udc-render` commands, one thin module each
"""
__version__ = "0.1.0"
