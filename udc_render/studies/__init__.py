"""Error-versus-run-time studies of the approximation knobs (consumers of the pipeline, never used by it).

    psf_knobs.py      pupil samples, precision, wavelength step, field phases, kernel size (`study psf`)
    render_knobs.py   samples per pixel, render paths, bands per render (`study render`)
    capture_knobs.py  band width, per-channel form, field phases, precision, supersampling (`study capture`)
"""
