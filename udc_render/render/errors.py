"""The render stage's one-line error."""
from udc_render.errors import UdcError


class RenderError(UdcError):
    """A scene that cannot be rendered as asked; one line."""
