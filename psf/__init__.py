"""Wave-optics PSFs of a camera behind a display (udc-render's physics core).

    from psf import Lens, compute_kernels, layouts
    ks = compute_kernels(layouts.toled(), Lens(), wavelengths_nm=[450, 520, 640])
    ks.kernels  # [3, 255, 255], unit sum, centred at 127

numpy and scipy only; see README.md and docs/PHYSICS.md for the model.
"""
from . import layouts
from .engine import AliasingWarning, KernelSet, PSFError, UnderSamplingWarning, auto_pupil_samples, compute_kernels
from .layouts import LayoutError
from .lens import Lens, LensError
from .micrograph import MicrographLayout

__all__ = ["layouts", "Lens", "LensError", "LayoutError", "MicrographLayout", "KernelSet", "PSFError",
           "AliasingWarning", "UnderSamplingWarning", "compute_kernels", "auto_pupil_samples"]
