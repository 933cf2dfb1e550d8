"""The optics stage: kernels applied to band images, times the display's transmission.

    apply.py        apply_kernels (d = 0: one kernel per band; d > 0: field phases blended), OpticsResult
    convolution.py  the FFT convolution per band (convolve_bands, band_spectra, fft_shape), OpticsError
    field.py        the field-dependent blur (d > 0): phase weights, rank-r phase bases, convolve_field
    field_power.py  the exact transmitted power at every pixel's mask shift (PowerMap, field_power_map)
    bright.py       very bright pixels, convolved apart in float64 (BrightPixels)
    far_field.py    the light past the kernel window: the far field of the two-scale kernel (FarField)
    displays.py     Display, Transmission, the presets (glass, T-OLED, P-OLED), display TOML files,
                    the analytic γ of a display and the transmission fits
"""
from udc_render.optics.apply import OpticsResult, apply_kernels
from udc_render.optics.bright import BrightPixels
from udc_render.optics.convolution import OpticsError, band_spectra, convolve_bands, fft_shape
from udc_render.optics.field import (
    BLENDS,
    FieldBasis,
    convolve_field,
    field_basis,
    field_weights,
    live_phases,
    phase_weights,
)
from udc_render.optics.field_power import PowerMap, field_power_map

__all__ = ["BLENDS", "BrightPixels", "FieldBasis", "field_basis", "field_weights", "live_phases", "OpticsError",
           "OpticsResult", "apply_kernels", "band_spectra", "convolve_bands", "convolve_field", "fft_shape",
           "phase_weights", "PowerMap", "field_power_map"]
