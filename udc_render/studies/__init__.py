"""Error-versus-run-time studies of the approximation knobs (consumers of the pipeline, never used by it).

    psf_knobs.py      pupil samples, precision, wavelength step, field phases, kernel size (`study psf`);
                      psf_config.py (grids), psf_metrics.py (kernel errors), psf_report.py (md, png)
    render_knobs.py   samples per pixel, render paths, bands per render (`study render`);
                      render_config.py (grids, scenes), render_analysis.py (fits, recommendations),
                      render_report.py (md, json, png)
    capture_knobs.py  band width, per-channel form, field phases, precision, supersampling (`study capture`)
    report.py         the shared formatting, table, timing, file and plot helpers
"""
