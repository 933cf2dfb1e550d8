"""The virtual lab: the paper's calibration protocols (γ, noise, laser PSF, MTF) run on the rendered
rig and checked against the truth the simulator knows (`udc-render calibrate`).

    rig.py        the reduced rig: scene, glass and display views, sensors (Rig)
    gamma.py, noise.py, psf.py, mtf.py   one protocol each
    fit_gains.py  the kernel gains the presets' T(λ) are fitted on: what the γ protocol's square collects
    report.py     the checks' text table and the plots
    protocols.py  calibrate(): every protocol in turn
"""
from udc_render.calibration.protocols import calibrate
from udc_render.calibration.report import format_table, plot_all
from udc_render.calibration.rig import Rig

__all__ = ["Rig", "calibrate", "format_table", "plot_all"]
