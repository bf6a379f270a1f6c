"""Rendering of motion clips to MP4 videos and PNG contact sheets, in three styles: a stick figure, a solid body
(shaded capsules) or an SMPL-family mesh, one person or two, with captions and sound.

`render` composes `camera` (where the camera looks), `raster` (drawing frames) and `encode` (ffmpeg);
`blinding` makes a stimulus set's files tell nothing outside their pixels. rendering imports only `core`.

The names below are loaded when first asked for, not when the package is: a command that needs one room, such as
`python -m rendering.reencode` (ffmpeg alone, run once a submitted video), would otherwise import the drawing's
scipy and matplotlib, a third of a second of CPU a process.
"""

import importlib

_WHERE = {
    "Camera": "rendering.camera",
    "DEFAULT_CAMERA": "rendering.camera",
    "RenderError": "rendering.errors",
    "Style": "rendering.raster",
    "RenderOptions": "rendering.render",
    "contact_sheet": "rendering.render",
    "render_clip": "rendering.render",
}
__all__ = sorted(_WHERE)


def __getattr__(name):
    if name not in _WHERE:
        raise AttributeError(f"module 'rendering' has no attribute {name!r}")
    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *_WHERE})
