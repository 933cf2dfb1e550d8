"""The camera lens: circular aperture, focal length and defocus (thin-lens, paraxial pupil phase)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import ellipse_areas

__all__ = ["Lens", "LensError"]


class LensError(ValueError):
    """Lens parameters out of range (message is one line for the user)."""


@dataclass(frozen=True)
class Lens:
    """Thin lens with a circular pupil. Defaults are the paper's rig (f = 6 mm, f/1.8).

    focus_distance_mm and object_distance_mm are measured from the lens; math.inf is infinity.
    The sensor sits at the image distance of the focus plane, z_i = 1 / (1/f - 1/z_focus).
    """
    focal_length_um: float = 6000.0
    aperture_um: float = 3333.0
    focus_distance_mm: float = math.inf
    object_distance_mm: float = math.inf

    def __post_init__(self):
        for key in ("focal_length_um", "aperture_um", "focus_distance_mm", "object_distance_mm"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and v > 0 and not math.isnan(v)):
                raise LensError(f"lens: {key} must be a positive number, got {v}")
        if self.aperture_um > 2 * self.focal_length_um:
            raise LensError(f"lens: aperture_um = {self.aperture_um:g} is more than twice the focal length "
                            f"({self.focal_length_um:g} µm): f-number {self.focal_length_um / self.aperture_um:.3g} "
                            f"< 0.5, impossible for a lens in air (N ≥ 1 / (2 NA), NA ≤ 1)")
        if self.focus_distance_mm * 1000 <= self.focal_length_um:
            raise LensError(f"lens: focus_distance_mm ({self.focus_distance_mm}) must exceed the focal "
                            f"length ({self.focal_length_um / 1000} mm)")

    @property
    def image_distance_um(self) -> float:
        """Lens-to-sensor distance z_i (µm): the Fraunhofer scale is λ·z_i."""
        inv_focus = 0.0 if math.isinf(self.focus_distance_mm) else 1.0 / (self.focus_distance_mm * 1000)
        return 1.0 / (1.0 / self.focal_length_um - inv_focus)

    @property
    def defocus_curvature_per_um(self) -> float:
        """c = 1/z_object - 1/z_focus (1/µm); the pupil phase is π c r² / λ (paraxial defocus)."""
        inv = lambda mm: 0.0 if math.isinf(mm) else 1.0 / (mm * 1000)
        return inv(self.object_distance_mm) - inv(self.focus_distance_mm)

    def aperture_area_fraction(self, x_edges_um, y_edges_um) -> np.ndarray:
        """Exactly area-weighted circular aperture on a grid (fraction of each cell, [ny, nx])."""
        r = self.aperture_um / 2
        cell = np.outer(np.diff(y_edges_um), np.diff(x_edges_um))
        return ellipse_areas(x_edges_um, y_edges_um, 0.0, 0.0, r, r) / cell

    def pupil_phase(self, x_um, y_um, wavelength_um: float) -> np.ndarray | None:
        """exp(i π c r² / λ) on the grid of centres (None when in focus)."""
        c = self.defocus_curvature_per_um
        if c == 0.0:
            return None
        r2 = x_um[None, :] ** 2 + y_um[:, None] ** 2
        return np.exp(1j * math.pi * c * r2 / wavelength_um)

    def describe(self) -> dict:
        return {"focal_length_um": self.focal_length_um, "aperture_um": self.aperture_um,
                "focus_distance_mm": self.focus_distance_mm, "object_distance_mm": self.object_distance_mm}
