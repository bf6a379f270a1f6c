"""The frame's colour planes: BT.601 limited range as ffmpeg converts RGB to yuv420p, and a yuv420p frame back to
RGB (contact sheets, tests)."""

import numpy as np

from .camera import frame_size

# BT.601 limited range, what ffmpeg's own rgb -> yuv420p conversion uses.
TO_Y = np.array([0.2568, 0.5041, 0.0979], np.float32)
TO_U = np.array([-0.1482, -0.2910, 0.4392], np.float32)
TO_V = np.array([0.4392, -0.3678, -0.0714], np.float32)
RGBA_TO_Y = np.append(TO_Y, np.float32(0))  # rgba @ RGBA_TO_Y = Y - 16
# A 2x2 block's 4 rgba pixels in a row [16] @ BLOCK_TO_UV = the block's mean (U - 128, V - 128).
BLOCK_TO_UV = np.tile(np.vstack([np.stack([TO_U, TO_V], 1), np.zeros((1, 2), np.float32)]) / 4, (4, 1))


def grey_to_y(g):
    """Luma of a grey level g in [0, 1]."""
    return 16.0 + 219.0 * g


def yuv_to_rgb(frame, size, half=False):
    """A yuv420p frame (flat uint8, as FrameDrawer.draw returns) of `size` (a side, or (width, height)) -> RGB
    uint8 [height, width, 3]; with `half`, at half the width and height: each 2x2 block's mean luma with its chroma
    sample, a quarter of the work, for a picture that is to be shrunk anyway (a contact sheet's tile)."""
    w, h = frame_size(size)
    n = w * h
    if half:
        # The block's four lumas summed as integers (exact), then a quarter of that: the bytes of a float32 mean
        # over the block's axes, at a tenth of its cost (numpy reduces over strided axes slowly).
        q = frame[:n].reshape(h // 2, 2, w // 2, 2)
        s = q[:, 0, :, 0].astype(np.uint16)
        s += q[:, 0, :, 1]
        s += q[:, 1, :, 0]
        s += q[:, 1, :, 1]
        y = 1.164 * (s.astype(np.float32) * np.float32(0.25) - 16)
        u = frame[n : n + n // 4].reshape(h // 2, w // 2).astype(np.float32) - 128
        v = frame[n + n // 4 :].reshape(h // 2, w // 2).astype(np.float32) - 128
        return _to_bytes(y, u, v, (h // 2, w // 2, 3))
    # Viewed as [h/2, 2, w/2, 2], each 2x2 block's luma meets its one chroma sample by broadcasting: the chroma terms
    # are computed once a block, not once a pixel, and no full-size chroma plane is made (a contact sheet converts
    # 8 frames a clip). Every sum is formed in the same order as pixel by pixel, so the bytes are the same.
    y = 1.164 * (frame[:n].reshape(h // 2, 2, w // 2, 2).astype(np.float32) - 16)
    u = frame[n : n + n // 4].reshape(h // 2, 1, w // 2, 1).astype(np.float32) - 128
    v = frame[n + n // 4 :].reshape(h // 2, 1, w // 2, 1).astype(np.float32) - 128
    return _to_bytes(y, u, v, (h // 2, 2, w // 2, 2, 3)).reshape(h, w, 3)


def _to_bytes(y, u, v, shape):
    """RGB uint8 of `shape` from the scaled luma and the centred chroma (broadcast to the luma's shape)."""
    rgb = np.empty(shape, np.uint8)
    for c, plane in enumerate((y + 1.596 * v, y - 0.392 * u - 0.813 * v, y + 2.017 * u)):
        plane += 0.5
        rgb[..., c] = np.clip(plane, 0, 255, out=plane)
    return rgb
