"""The one base of every user-facing error of udc_render: a bad file, key, option or value.

Each stage raises its own subclass (SceneError, RenderError, DisplayError, OpticsError, SensorError,
SynthError, DatasetError, …) with one line naming the file, key or option, the value and what is
allowed; the command line catches UdcError (and the psf and restore errors) and prints that line.
"""
from __future__ import annotations


class UdcError(ValueError):
    """A user error: the message is one line naming what is wrong and what is allowed."""
