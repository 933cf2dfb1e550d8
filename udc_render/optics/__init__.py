"""The optics stage: kernels applied to band images, times the display's transmission.

    convolution.py  apply_kernels (d = 0: one kernel per band; d > 0: field phases blended), the FFT
                    convolutions behind it, OpticsResult
    displays.py     Display, Transmission, the presets (glass, T-OLED, P-OLED), display TOML files,
                    the analytic γ of a display and the transmission fits
"""
from udc_render.optics.convolution import (BLENDS, BrightPixels, FieldBasis, OpticsError, OpticsResult, apply_kernels, band_spectra,
                                           convolve_bands, field_basis, field_weights, live_phases,
                                           convolve_field, fft_shape, phase_weights)

__all__ = ["BLENDS", "BrightPixels", "FieldBasis", "field_basis", "field_weights", "live_phases", "OpticsError", "OpticsResult", "apply_kernels", "band_spectra", "convolve_bands", "convolve_field", "fft_shape",
           "phase_weights"]
