"""Rendering of motion clips to MP4 videos and PNG contact sheets, in three styles: a stick figure, a solid body
(shaded capsules) or an SMPL-family mesh, one person or two, with captions and sound.

`render` composes `camera` (where the camera looks), `raster` (drawing frames) and `encode` (ffmpeg);
`blinding` makes a stimulus set's files tell nothing outside their pixels. rendering imports only `core`.
"""

from rendering.camera import DEFAULT_CAMERA, Camera
from rendering.errors import RenderError
from rendering.raster import Style
from rendering.render import RenderOptions, contact_sheet, render_clip

__all__ = ["Camera", "DEFAULT_CAMERA", "RenderError", "RenderOptions", "Style", "contact_sheet", "render_clip"]
