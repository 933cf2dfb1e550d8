"""The error of udc-render fit (its own module: the readers, inputs and dng, both raise it)."""
from __future__ import annotations

from udc_render.errors import UdcError


class FitError(UdcError):
    """What udc-render fit cannot read or fit; one line naming the file or option, the value and what is allowed."""
