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


@pytest.mark.parametrize("size", [2, 64, (96, 32)])
def test_the_half_size_conversion_is_each_blocks_mean_luma_with_its_chroma(size):
    """A frame whose luma is one value in every 2x2 block converts at half size to every other pixel of the full
    conversion, to the bit; otherwise each half-size pixel takes its block's mean luma."""
    w, h = frame_size(size)
    rng = np.random.default_rng(w * h)
    frame = rng.integers(0, 256, w * h * 3 // 2, dtype=np.uint8)
    n = w * h
    frame[:n] = rng.integers(0, 256, (h // 2, w // 2), dtype=np.uint8).repeat(2, 0).repeat(2, 1).ravel()
    half = yuv_to_rgb(frame, size, half=True)
    assert half.shape == (h // 2, w // 2, 3) and half.dtype == np.uint8
    assert np.array_equal(half, per_pixel(frame, size)[::2, ::2])
    frame[:n:2] = 16  # half the luma black: the mean moves each block's grey by a known amount
    frame[n:] = 128
    y = frame[:n].reshape(h // 2, 2, w // 2, 2).astype(float).mean(axis=(1, 3))
    assert np.abs(yuv_to_rgb(frame, size, half=True)[..., 0] - np.clip(1.164 * (y - 16), 0, 255)).max() <= 1


def test_a_contact_sheet_never_enlarges_its_frames(tmp_path):
    """Tiles are 240 px high, or the frames' own height when lower: a small video's sheet is its own pixels."""
    from PIL import Image

    from rendering.render import contact_sheet

    small = [(t, np.full((96, 160, 3), 40 * t, np.uint8)) for t in range(5)]
    contact_sheet(small, 30.0, tmp_path / "small.png")
    assert Image.open(tmp_path / "small.png").size == (4 * 160, 2 * (96 + 18))  # 18: the time under each tile
    tile = np.asarray(Image.open(tmp_path / "small.png"))[:96, 160:320]
    assert (tile == 40).all()  # frame 1 as it was, not resampled
    large = [(t, np.zeros((480, 480, 3), np.uint8)) for t in range(4)]
    contact_sheet(large, 30.0, tmp_path / "large.png")
    assert Image.open(tmp_path / "large.png").size == (4 * 240, 240 + 18)
