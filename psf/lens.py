"""The camera lens: circular aperture, focal length, defocus (thin-lens, paraxial pupil phase) and wavefront
aberrations (Zernike terms, psf.zernike)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import zernike
from .geometry import ellipse_areas

__all__ = ["Lens", "LensError"]


class LensError(ValueError):
    """Lens parameters out of range (message is one line for the user)."""


def _inverse_um(distance_mm: float) -> float:
    """1 / distance in 1/µm; 0 at infinity."""
    return 0.0 if math.isinf(distance_mm) else 1.0 / (distance_mm * 1000)


@dataclass(frozen=True)
class Lens:
    """Thin lens with a circular pupil. Defaults are the paper's rig (f = 6 mm, f/1.8), diffraction-limited.

    focus_distance_mm and object_distance_mm are measured from the lens; math.inf is infinity.
    The sensor sits at the image distance of the focus plane, z_i = 1 / (1/f - 1/z_focus).
    zernike_waves: the wavefront error, (n, m, waves RMS at psf.zernike.REFERENCE_NM) per Zernike term
    (psf.zernike: OSA/ANSI normalised, e.g. (4, 0, 0.05): 0.05 waves RMS of spherical aberration), the same
    at every field position and wavelength (as an optical path); () is the diffraction-limited lens.
    """
    focal_length_um: float = 6000.0
    aperture_um: float = 3333.0
    focus_distance_mm: float = math.inf
    object_distance_mm: float = math.inf
    zernike_waves: tuple = ()

    def __post_init__(self):
        for key in ("focal_length_um", "aperture_um", "focus_distance_mm", "object_distance_mm"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and v > 0 and not math.isnan(v)):
                raise LensError(f"lens: {key} must be a positive number, got {v}")
        if self.aperture_um > 2 * self.focal_length_um:
            raise LensError(f"lens: aperture_um = {self.aperture_um:g} is more than twice the focal length "
                            f"({self.focal_length_um:g} µm): f-number {self.focal_length_um / self.aperture_um:.3g} "
                            f"< 0.5, impossible for a lens in air (N ≥ 1 / (2 NA), NA ≤ 1)")
        try:
            object.__setattr__(self, "zernike_waves", zernike.canonical(self.zernike_waves))
        except ValueError as exc:
            raise LensError(str(exc)) from None
        if self.focus_distance_mm * 1000 <= self.focal_length_um:
            raise LensError(f"lens: focus_distance_mm ({self.focus_distance_mm}) must exceed the focal "
                            f"length ({self.focal_length_um / 1000} mm)")

    @property
    def image_distance_um(self) -> float:
        """Lens-to-sensor distance z_i (µm): the Fraunhofer scale is λ·z_i."""
        return 1.0 / (1.0 / self.focal_length_um - _inverse_um(self.focus_distance_mm))

    @property
    def defocus_curvature_per_um(self) -> float:
        """c = 1/z_object - 1/z_focus (1/µm); the pupil phase is π c r² / λ (paraxial defocus)."""
        return _inverse_um(self.object_distance_mm) - _inverse_um(self.focus_distance_mm)

    def aperture_area_fraction(self, x_edges_um, y_edges_um) -> np.ndarray:
        """Exactly area-weighted circular aperture on a grid (fraction of each cell, [ny, nx])."""
        r = self.aperture_um / 2
        cell = np.outer(np.diff(y_edges_um), np.diff(x_edges_um))
        return ellipse_areas(x_edges_um, y_edges_um, 0.0, 0.0, r, r) / cell

    def wavefront_um(self, x_um, y_um) -> np.ndarray:
        """W = (λ_ref / 1000) Σ a Z_n^m(r / (D/2), θ) (µm) on the grid of centres [ny, nx] (psf.zernike)."""
        x, y = np.asarray(x_um, float)[None, :], np.asarray(y_um, float)[:, None]
        rho, theta = np.hypot(x, y) / (self.aperture_um / 2), np.arctan2(y, x)
        return zernike.wavefront(self.zernike_waves, rho, theta) * (zernike.REFERENCE_NM * 1e-3)

    def max_phase_slope(self) -> float:
        """The largest |∇| of the pupil's optical path over the aperture (µm per µm): the aberration's
        (psf.zernike.max_slope) plus the defocus's |c| D / 2 at the rim; 0 without aberrations (the
        defocus alone keeps the sampling it always had)."""
        if not self.zernike_waves:
            return 0.0
        radius = self.aperture_um / 2
        return (zernike.max_slope(self.zernike_waves) * zernike.REFERENCE_NM * 1e-3 / radius
                + abs(self.defocus_curvature_per_um) * radius)

    def pupil_phase(self, x_um, y_um, wavelength_um: float) -> np.ndarray | None:
        """exp(i (π c r² + 2π W) / λ) on the grid of centres (None when in focus and unaberrated)."""
        c = self.defocus_curvature_per_um
        if c == 0.0 and not self.zernike_waves:
            return None
        r2 = x_um[None, :] ** 2 + y_um[:, None] ** 2
        if not self.zernike_waves:
            return np.exp(1j * math.pi * c * r2 / wavelength_um)
        return np.exp(1j * (math.pi * c * r2 + 2 * math.pi * self.wavefront_um(x_um, y_um)) / wavelength_um)

    def describe(self) -> dict:
        """The settings as keyword arguments of Lens (zernike_waves only when there are any)."""
        out = {"focal_length_um": self.focal_length_um, "aperture_um": self.aperture_um,
               "focus_distance_mm": self.focus_distance_mm, "object_distance_mm": self.object_distance_mm}
        if self.zernike_waves:
            out["zernike_waves"] = [list(t) for t in self.zernike_waves]
        return out
