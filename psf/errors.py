"""The psf package's error and warnings (one module, imported by the engine and banding alike)."""

__all__ = ["PSFError", "AliasingWarning", "UnderSamplingWarning"]


class PSFError(ValueError):
    """Parameters the engine cannot honour (message is one line for the user)."""


class AliasingWarning(UserWarning):
    """The kernel window reaches past the alias-free field λz/δ of the pupil sampling."""


class UnderSamplingWarning(UserWarning):
    """The paper's recipe with r < 1: the DFT grid is coarser than the sensor pixel."""
