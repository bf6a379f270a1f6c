"""Resampling local rotations (generation.motion.resample): worked a block of frames at a time, its values are those
of the whole take done at once, at every block's edge and the take's own ends."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from generation.motion import resample


def unit_quaternions(rng, frames, joints):
    q = rng.normal(size=(frames, joints, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def whole_take_at_once(q, trans, fps_in, fps_out):
    """The resampler's steps on every frame at once: signs made continuous frame by frame, the anti-aliasing
    Gaussian over the whole take, then slerp and lerp at the output times."""
    q = q.copy()
    for t in range(1, len(q)):
        for j in range(q.shape[1]):
            if q[t, j] @ q[t - 1, j] < 0:
                q[t, j] *= -1
    ratio = fps_in / fps_out
    if ratio >= 2:
        q = gaussian_filter1d(q, ratio / 2, axis=0, mode="nearest")
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        trans = gaussian_filter1d(trans, ratio / 2, axis=0, mode="nearest")
    i0, i1, w = resample.lerp_indices(len(q), fps_in, fps_out)
    ww = np.broadcast_to(w[:, None], (len(w), q.shape[1]))
    return resample.slerp(q[i0], q[i1], ww), trans[i0] * (1 - ww[..., None]) + trans[i1] * ww[..., None]


@pytest.mark.parametrize("fps_in, fps_out", [(120, 30), (100, 7), (120, 20), (30, 20), (25, 30), (30, 120)])
def test_blocks_give_the_whole_takes_values(monkeypatch, fps_in, fps_out):
    rng = np.random.default_rng(fps_in * 1000 + fps_out)
    q, trans = unit_quaternions(rng, 301, 3), rng.normal(size=(301, 3, 3))
    expected = whole_take_at_once(q, trans, fps_in, fps_out)
    monkeypatch.setattr(resample, "CHUNK_FRAMES", 7)  # many blocks, each shorter than the filter's reach
    q_out, t_out = resample.resample_local(q, trans, fps_in, fps_out)
    assert q_out.shape == expected[0].shape and t_out.shape == expected[1].shape
    np.testing.assert_allclose(q_out, expected[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(t_out, expected[1], rtol=0, atol=1e-12)
    monkeypatch.setattr(resample, "CHUNK_FRAMES", 4096)  # the whole take in one block: the same bytes
    one_block = resample.resample_local(q, trans, fps_in, fps_out)
    assert np.array_equal(one_block[0], q_out) and np.array_equal(one_block[1], t_out)


def test_signs_are_made_continuous_across_blocks(monkeypatch):
    rng = np.random.default_rng(3)
    q = unit_quaternions(rng, 50, 4)
    monkeypatch.setattr(resample, "CHUNK_FRAMES", 5)
    out = resample.make_continuous(q)
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) >= 0)  # each frame in the hemisphere of the one before
    assert np.array_equal(np.abs(out), np.abs(q)) and np.array_equal(out[0], q[0])  # only signs changed
    assert np.array_equal(resample.continuity_flips(q), np.any(out != q, axis=-1))
