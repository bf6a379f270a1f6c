"""Resampling local rotations (generation.motion.resample): worked a block of frames at a time, its values are those
of the whole take done at once, at every block's edge and the take's own ends."""

import numpy as np
import pytest
from helpers.paths import TEST_DATA
from scipy.ndimage import gaussian_filter1d

from generation.motion import resample
from generation.motion.bvh import read_bvh


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
    flips = resample.continuity_flips(q)
    out = np.where(flips[..., None], -q, q)
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) >= 0)  # each frame in the hemisphere of the one before
    assert not flips[0].any() and flips.any()  # the first frame as it is; random rotations change sign somewhere


def test_a_bvh_take_is_resampled_a_block_at_a_time_as_its_whole_rotations_are(monkeypatch):
    """local_quaternions_at, which reads a take's rotations a block at a time, gives resample_local's values on the
    whole take's rotations, on a real take at 120 fps decimated and at 30 fps interpolated."""
    takes = [("pfnn_locomotion_flat04_head.bvh.gz", (30.0, 7.0)), ("bandai_walk_angry_002.bvh.gz", (20.0, 50.0))]
    monkeypatch.setattr(resample, "CHUNK_FRAMES", 8)  # several blocks in each take
    for name, rates in takes:
        bvh = read_bvh(TEST_DATA / "bvh" / name)
        q, trans = resample.local_quaternions(bvh)
        fps_in = resample.clean_fps(bvh.fps)
        for fps in rates:
            want = resample.resample_local(q, trans, fps_in, fps)
            got = resample.local_quaternions_at(bvh, fps_in, fps)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), (name, fps)
