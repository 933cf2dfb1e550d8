"""The virtual lab: the paper's calibration protocols (γ, noise, laser PSF, MTF) run on the rendered
rig and checked against the truth the simulator knows (protocols.py; `udc-render calibrate`)."""
from udc_render.calibration.protocols import Rig, calibrate, format_table, plot_all

__all__ = ["Rig", "calibrate", "format_table", "plot_all"]
