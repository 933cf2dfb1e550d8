"""`udc-render calibrate`: the paper's calibration protocols run on the virtual rig (docs/PHYSICS.md §2).

    udc-render calibrate --display {toled,poled,PATH} [--out DIR] [--quick] [--noise-model M]

The monitor scene is rendered on the reduced rig (rig.py) through glass and through the display, and
each protocol recovers a quantity and compares it with the configured truth: γ per RGGB channel
(gamma.py), (λ_read, λ_shot) per channel (noise.py), the PSF from a virtual laser (psf.py) and the
MTF from sine gratings (mtf.py). The table and the plots: report.py.

Exit status: 0 when every check passes, 1 when any check misses its tolerance (printed as FAIL;
for CI-like use), 2 for bad arguments.
"""
from __future__ import annotations

import time
from pathlib import Path

from udc_render.calibration.gamma import calibrate_gamma
from udc_render.calibration.mtf import calibrate_mtf
from udc_render.calibration.noise import calibrate_noise
from udc_render.calibration.psf import calibrate_psf
from udc_render.calibration.report import format_table, plot_all
from udc_render.calibration.rig import Rig

__all__ = ["calibrate", "format_table", "plot_all"]


def calibrate(display, out: Path, quick: bool = False, cfg=None) -> dict:
    """Every protocol for `display` (a displays.Display at d = 0); returns the results (arrays as numpy)."""
    t0 = time.perf_counter()
    rig = Rig(display, quick, cfg, out)
    gamma = calibrate_gamma(rig)
    noise = calibrate_noise(rig)
    psf = calibrate_psf(rig)
    mtf = calibrate_mtf(rig)
    spec = rig.spec
    return {"display": display.name, "display_description": display.describe(), "mode": "quick" if quick else "default",
            "rig": {"sensor_px": [spec.width_px, spec.height_px], "pitch_um": 1.55, "framing": "fill",
                    "margin_um": spec.margin_um, "kernel_px": 2 * rig.half_kernel() + 1, "bands_nm": spec.bands_nm,
                    "spp": spec.spp, "pattern_spp": spec.pattern_spp, "monitor_px": list(rig.monitor_px()),
                    "exposure_s": rig.sensors[display.name].exposure_s, "gain": display.gain,
                    "noise": rig.sensors[display.name].noise, "form": "spectral"},
            "gamma": gamma, "noise": noise, "psf": psf, "mtf": mtf,
            "checks": gamma["checks"] + noise["checks"] + psf["checks"] + mtf["checks"],
            "seconds": {**{k: round(v, 1) for k, v in rig.seconds.items()},
                        "total": round(time.perf_counter() - t0, 1)}}
