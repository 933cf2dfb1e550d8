"""The PSF study's rig (Lens(), 3.1 µm pixels, T-OLED / P-OLED), its grids (FULL, QUICK) and its CSV columns."""
from __future__ import annotations

from dataclasses import dataclass

PIXEL_UM = 3.1
SIZE_PX = 255
WAVELENGTHS_NM = (450.0, 520.0, 640.0)
BANDS_NM = ((400.0, 500.0), (500.0, 600.0), (600.0, 700.0))
TOLERANCE_L1 = 1e-3  # "good enough" line used for the recommendation per table

KNOB_TITLES = {
    "pupil_samples": "1. Pupil samples N (mask_raster band_limited vs area)",
    "method": "2. Fraunhofer method (mft / czt / paper)",
    "precision": "3. Precision (float32 vs float64)",
    "band_step_nm": "4. Wavelength samples per band (band_kernels step_nm)",
    "field_phases": "5. Field phases P at d = 1 mm",
    "size_px": "6. Kernel size S",
}

COLUMNS = ["knob", "display", "series", "value", "error_L1", "error_max_rel", "energy_outside", "time_s",
           "time_min_s", "repeats", "is_default", "warning", "pupil_samples_used", "pupil_shape",
           "samples_per_band", "field_kernel_L1_interp", "banding_err_interp", "banding_err_matched",
           "L1_vs_full_ref", "energy_outside_check", "L1_same_N_ref"]


@dataclass
class Config:
    """The grid of one study run (full or quick)."""
    quick: bool
    repeats: int
    size_px: int
    pupil_n: tuple
    pupil_ref_n: int
    method_n: tuple
    default_n: int  # the pupil_samples value that equals the engine's auto choice for this rig
    band_size: int
    band_n: int | None  # None: auto
    band_steps: tuple
    band_ref_step: float  # steps: None is the engine's auto step λ_lo / S (the default)
    field_size: int
    field_n: int
    field_p: tuple
    field_ref_p: int
    default_p: int
    field_distance_mm: float
    field_wavelength_nm: float
    sizes: tuple
    size_ref: int
    size_n: int | None  # None: auto (the engine default) for every size
    default_size: int


FULL = Config(quick=False, repeats=3, size_px=SIZE_PX, pupil_n=(768, 1024, 1536, 2048, 3072), pupil_ref_n=4096,
              method_n=(1024, 2048), default_n=1024, band_size=SIZE_PX, band_n=None, band_steps=(20, 10, 6, 3, 2, None),
              band_ref_step=1.0, field_size=127, field_n=1024, field_p=(1, 2, 3, 4, 6),
              field_ref_p=8, default_p=4, field_distance_mm=1.0, field_wavelength_nm=520.0,
              sizes=(63, 127, 255, 511), size_ref=1023, size_n=None, default_size=255)

QUICK = Config(quick=True, repeats=1, size_px=63, pupil_n=(256, 384), pupil_ref_n=512, method_n=(256,),
               default_n=256, band_size=63, band_n=256, band_steps=(50, None), band_ref_step=10.0,
               field_size=63, field_n=256, field_p=(1, 2), field_ref_p=4, default_p=2, field_distance_mm=1.0,
               field_wavelength_nm=520.0, sizes=(31, 63), size_ref=127, size_n=512, default_size=63)
