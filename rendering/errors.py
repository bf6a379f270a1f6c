"""The one error type of rendering."""

from moglow_eval.core.cli import UserError


class RenderError(UserError):
    """A clip that cannot be rendered, or ffmpeg failing; the message names the file."""
