"""The files of `udc-render psf`: a KernelSet as psf.npz (arrays + every parameter), psf.exr (named
float32 channels any EXR viewer opens), psf.json, and the PSF, MTF and (d > 0) banding plots.

    psf.npz   kernels [K, S, S] (unit sum, centre S//2), wavelengths_nm, pixel_um, energy_outside,
              transmittance, ratio_r, every parameter as its own key and all as params_json;
              d > 0: field_kernels, field_power, field_shifts_um, field_positions_um, banding profiles
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from udc_render.io.exr import save_exr
from udc_render.io.files import save_json, save_npz
from udc_render.io.plots import plot_banding, plot_kernels, plot_mtf


def kernel_arrays(ks) -> dict:
    """The arrays and scalar parameters of psf.npz (less the field and banding parts)."""
    arrays = dict(kernels=ks.kernels, wavelengths_nm=ks.wavelengths_nm, pixel_um=np.float64(ks.pixel_um),
                  energy_outside=ks.energy_outside, transmittance=ks.transmittance, ratio_r=ks.ratio_r,
                  params_json=np.array(json.dumps(ks.params)))
    for key in ("size_px", "distance_mm", "method", "pupil_samples", "precision", "field_phases"):
        arrays[key] = np.array(ks.params[key])
    for key, value in ks.params["lens"].items():  # zernike_waves: [terms, 3] (n, m, waves), when there are any
        arrays[key] = np.asarray(value, dtype=np.float64)
    return arrays


def banding_arrays(display, lens, ks, distance_mm: float, out: Path) -> dict:
    """Banding profiles along x and y at each wavelength (psf.banding, exact series), plotted to
    out/banding.png; the period on the sensor is z_i · p / d."""
    from psf.banding import banding_profile
    arrays, profiles = {}, {}
    for axis in ("x", "y"):
        powers = []
        for w in ks.wavelengths_nm:
            x, p = banding_profile(display, lens, float(w), distance_mm, axis=axis)
            profiles[(axis, f"{w:.0f} nm")] = (x, p)
            powers.append(p)
        arrays[f"banding_{axis}_um"], arrays[f"banding_{axis}_power"] = x, np.stack(powers)
    z = lens.image_distance_um
    period = tuple(z * p / (distance_mm * 1000) for p in display.period_um)
    arrays["banding_period_um"] = np.array(period)
    plot_banding(profiles, period, out / "banding.png")
    return arrays


def write_kernel_files(out: Path, ks, display, lens, distance_mm: float, from_cache: bool) -> list[str]:
    """Write psf.npz, psf.json, psf.exr, psf.png, mtf.png (and banding.png when d > 0 with a
    periodic display) into `out`; returns the names written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    arrays = kernel_arrays(ks)
    written = ["psf.npz", "psf.exr", "psf.png", "mtf.png"]
    if ks.field_kernels is not None:
        arrays.update(field_kernels=ks.field_kernels, field_power=ks.field_power, field_shifts_um=ks.field_shifts_um)
        arrays["field_positions_um"] = ks.field_shifts_um * lens.image_distance_um / (distance_mm * 1000)
        if getattr(display, "periodic", True):
            arrays.update(banding_arrays(display, lens, ks, distance_mm, out))
            written.append("banding.png")
    save_npz(out / "psf.npz", **arrays)
    save_json(out / "psf.json", {**ks.params, "energy_outside": ks.energy_outside, "transmittance": ks.transmittance,
                                 "ratio_r": ks.ratio_r, "notes": ks.notes, "from_cache": from_cache})
    names = ks.params.get("channels") or [f"{w:g}nm".replace(".", "p") for w in ks.wavelengths_nm]
    save_exr(out / "psf.exr", {f"psf_{n}": k for n, k in zip(names, ks.kernels)})
    plot_kernels(ks, out / "psf.png")
    plot_mtf(ks, out / "mtf.png")
    return written
