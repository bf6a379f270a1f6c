"""Stick-figure rendering of motion clips to MP4 videos and PNG contact sheets."""

from rendering.render import DEFAULT_CAMERA, Camera, RenderError, Style, contact_sheet, render_clip

__all__ = ["Camera", "DEFAULT_CAMERA", "RenderError", "Style", "contact_sheet", "render_clip"]
