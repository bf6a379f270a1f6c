"""Pixel checks on decoded video frames of a drawn body: which pixels are the trunk (dark grey), the left side
(blue) and the right side (red), the figure's height share from the hips to the top of the head, and whether
a side's pixels touch the frame's edge."""

import imageio_ffmpeg
import numpy as np


def decode(path):
    """(frames [T, H, W, 3] uint8, fps) of a video, decoded by ffmpeg."""
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    frames = np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader])
    return frames, float(meta["fps"])


def classes(frame):
    """Boolean masks (trunk, left, right) of one RGB frame: the trunk's dark grey, the left's blue, the right's
    red (rendering.raster.Style), shaded or not. The floor, grid and shadow are lighter greys."""
    rgb = frame.astype(np.int16)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    spread = rgb.max(-1) - rgb.min(-1)
    trunk = (rgb.max(-1) < 110) & (spread < 30)
    left = (b - r > 50) & (b > g)
    right = (r - b > 50) & (r > g)
    return trunk, left, right


def height_share(frame):
    """(the lowest trunk row - the figure's highest row) / the frame's height: from the hips (where the trunk's
    dark spine ends; the pelvis's bones are a side's) to the top of the head. None where no trunk is seen."""
    trunk, left, right = classes(frame)
    rows = np.flatnonzero(trunk.any(1))
    figure = np.flatnonzero((trunk | left | right).any(1))
    if not len(rows):
        return None
    return (rows.max() - figure.min()) / frame.shape[0]


def touches_edge(mask, border=1):
    """True where `mask` has pixels within `border` of the frame's left, right or top edge."""
    return bool(mask[:border].any() or mask[:, :border].any() or mask[:, -border:].any())
