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


def yuv_rgb(frame, size):
    """A yuv420p frame (flat uint8, as the rasteriser writes it) as RGB [size, size, 3] uint8."""
    from rendering.raster import yuv_to_rgb

    return yuv_to_rgb(frame, size)


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


def partner(frame):
    """Boolean mask of the second person of a two-person video: one muted green (rendering.raster.PARTNER_COLOUR),
    shaded or not; not the caption text tinted like it, which is far lighter."""
    rgb = frame.astype(np.int16)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (g - r > 25) & (g - b > 15) & (g < 215) & (g > 60)


def agent(frame):
    """Boolean mask of the agent of a two-person video: its trunk, left and right colours."""
    trunk, left, right = classes(frame)
    return trunk | left | right


def highlight(frame):
    """Boolean mask of a caption's highlighted keyword: its yellow box (rendering.captions.KEY_FILL)."""
    rgb = frame.astype(np.int16)
    return (rgb[..., 0] > 200) & (rgb[..., 1] > 160) & (rgb[..., 2] < 90)


def caption_rows(frame):
    """Indices of the rows crossed by a caption's band: dark and grey over more than 40% of the frame's height (no
    body is that wide; the text is a share of the height, in a wide frame too)."""
    rgb = frame.astype(np.int16)
    dark = (rgb.max(-1) < 90) & (rgb.max(-1) - rgb.min(-1) < 25)
    return np.flatnonzero(dark.sum(1) > 0.4 * frame.shape[0])


def caption_text(frame):
    """Boolean mask of caption text: bright pixels on the rows of a caption's band, between its dark ends."""
    rows = caption_rows(frame)
    mask = np.zeros(frame.shape[:2], bool)
    if len(rows):
        band = frame[rows].astype(np.int16)
        mask[rows] = band.min(-1) > 170
        dark = (band.max(-1) < 90).any(0)
        cols = np.flatnonzero(dark)
        mask[:, : cols.min()] = False
        mask[:, cols.max() + 1 :] = False
    return mask


def near_share(a, b, pixels=2):
    """The share of mask a's pixels within `pixels` of one of mask b's: near 1 where two videos show the same
    drawing, whatever the encoder did to its thin edges."""
    from scipy.ndimage import binary_dilation

    if not a.any():
        return 0.0
    return float((a & binary_dilation(b, iterations=pixels)).sum() / a.sum())


def partner_near(first, second, frames):
    """[near share of the two videos' partners, the smaller of either way] at each of `frames`: the same second
    person in both wherever the values are near 1. One frame's thin edges can lose much to the random rate per
    frame (rendering.encode.rate_dither), so the tests take the mean over a clip."""
    out = []
    for t in frames:
        a, b = partner(first[t]), partner(second[t])
        out.append(min(near_share(a, b), near_share(b, a)))
    return out
