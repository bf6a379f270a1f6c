"""yuv420p back to RGB (contact sheets, the pixel tests): BT.601 limited range, pixel by pixel as written in the
standard's form, for square and wide frames."""

import numpy as np
import pytest

from rendering.camera import frame_size
from rendering.yuv import yuv_to_rgb


def per_pixel(frame, size):
    """The conversion written out plainly: each pixel's luma with its 2x2 block's chroma, full-size planes."""
    w, h = frame_size(size)
    n = w * h
    y = frame[:n].reshape(h, w).astype(np.float32) - 16
    u = frame[n : n + n // 4].reshape(h // 2, w // 2).repeat(2, 0).repeat(2, 1).astype(np.float32) - 128
    v = frame[n + n // 4 :].reshape(h // 2, w // 2).repeat(2, 0).repeat(2, 1).astype(np.float32) - 128
    rgb = np.stack([1.164 * y + 1.596 * v, 1.164 * y - 0.392 * u - 0.813 * v, 1.164 * y + 2.017 * u], -1)
    return np.clip(rgb + 0.5, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("size", [2, 64, (96, 32), (1536, 512)])
def test_the_blockwise_conversion_is_the_per_pixel_one_to_the_bit(size):
    w, h = frame_size(size)
    frame = np.random.default_rng(w + h).integers(0, 256, w * h * 3 // 2, dtype=np.uint8)
    got = yuv_to_rgb(frame, size)
    assert got.shape == (h, w, 3) and got.dtype == np.uint8
    assert np.array_equal(got, per_pixel(frame, size))


def test_limited_range_black_white_and_a_colour():
    w = h = 4
    n = w * h
    frame = np.empty(n * 3 // 2, np.uint8)
    frame[:n], frame[n:] = 16, 128  # black: the bottom of the luma range, no chroma
    assert (yuv_to_rgb(frame, 4) == 0).all()
    frame[:n] = 235  # white
    assert (yuv_to_rgb(frame, 4) == 255).all()
    frame[:n], frame[n : n + n // 4], frame[n + n // 4 :] = 81, 90, 240  # BT.601's red
    assert np.abs(yuv_to_rgb(frame, 4).astype(int) - [255, 0, 0]).max() <= 2
