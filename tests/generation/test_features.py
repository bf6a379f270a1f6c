"""Features (issue 2): exact round trip on every real take, augmentation identities, physical sanity."""

import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from helpers.paths import BANDAI, PFNN
from helpers.small_bvh import bvh_text, motion_values
from reference.bvh_fk import fk_positions

from generation.data.prepare import category_of, find_takes
from generation.motion import skeleton
from generation.motion.bvh import BvhError, read_bvh
from generation.motion.features import SKELETON_MAPS, load_take, mirror, reverse, root_trajectory, to_features, to_world

pytestmark = pytest.mark.full  # the full tier: every take of ../shared

FPS = 20.0
PFNN_TAKES = sorted((PFNN / "animations").glob("Locomotion*.bvh.gz")) + sorted(
    (PFNN / "animations").glob("NewCaptures*.bvh.gz")
)


@pytest.fixture(scope="module")
def all_takes():
    """{path: joints [T, 21, 3]} for every Bandai-Namco and PFNN take, loaded on all cores."""
    files = find_takes(BANDAI) + PFNN_TAKES
    assert len(files) == 1067 + 3
    with ProcessPoolExecutor(min(4, os.cpu_count() or 1)) as pool:
        joints = list(pool.map(load_take, files, chunksize=32))
    return dict(zip(files, joints))


def _by_category(all_takes):
    out = {}
    for f, j in all_takes.items():
        if f.is_relative_to(BANDAI):
            out.setdefault(category_of(f), []).append(j)
    return out


def test_round_trip_every_take(all_takes):
    """BVH -> features -> world reproduces the resampled FK positions: < 1 mm mean, < 5 mm max."""
    worst_mean = worst_max = 0.0
    for f, joints in all_takes.items():
        x, c = to_features(joints, FPS)
        assert x.shape == (len(joints), 63) and c.shape == (len(joints), 3), f
        assert x.dtype == np.float32 and c.dtype == np.float32
        root, yaw = root_trajectory(joints, FPS)
        world = to_world(x, c, start_xz=root[0], start_yaw=yaw[0])
        err = np.linalg.norm(world - joints, axis=-1)
        assert err.mean() < 1e-3 and err.max() < 5e-3, f"{f.name}: {err.mean()=}, {err.max()=}"
        worst_mean, worst_max = max(worst_mean, err.mean()), max(worst_max, err.max())
    print(f"round trip: worst mean {worst_mean * 1e3:.4f} mm, worst max {worst_max * 1e3:.4f} mm")


def test_bone_lengths_constant_every_take(all_takes):
    for f, joints in all_takes.items():
        bones = np.linalg.norm(joints[:, 1:] - joints[:, skeleton.PARENTS[1:]], axis=-1)
        assert np.ptp(bones, axis=0).max() < 1e-3, f.name
        # every bone of the body has a length (the CMU map puts Shoulder on the clavicle)
        assert bones.min() > 0.01, f.name


def test_units_and_floor(all_takes):
    for f, joints in all_takes.items():
        assert joints.dtype == np.float32 and np.isfinite(joints).all(), f.name
        hips = joints[:, skeleton.INDEX["Hips"], 1]
        head = joints[:, skeleton.INDEX["Head"], 1]
        feet = joints[:, skeleton.FEET, 1].min(axis=1)
        assert 0.6 < np.median(hips) < 1.2 and np.median(head) > np.median(hips) + 0.2, f.name  # metres, Y up
        assert -0.05 < np.median(feet) < 0.15, f.name  # a foot near the floor


def test_walk_speeds_and_runs_faster(all_takes):
    speed = {
        cat: np.mean([to_features(j, FPS)[1][1:, 0].mean() * FPS for j in js])
        for cat, js in _by_category(all_takes).items()
    }
    for walk in ("walk", "walk_turn_left", "walk_turn_right"):
        assert 0.8 <= speed[walk] <= 2.0, speed
        assert speed["run"] > speed[walk] + 0.5, speed
    assert speed["run_fast"] > speed["run"], speed
    assert speed["walk_backward"] < -0.3, speed  # backwards is negative forward


def test_control_signs_match_labels(all_takes):
    """Left is positive: turning left gives yaw > 0, side-stepping left gives sideways > 0."""
    mean_c = {
        cat: np.array([to_features(j, FPS)[1][1:].mean(0) for j in js]) for cat, js in _by_category(all_takes).items()
    }
    assert (mean_c["walk_turn_left"][:, 2] > 0).mean() > 0.95
    assert (mean_c["walk_turn_right"][:, 2] < 0).mean() > 0.95
    assert (mean_c["sidestep_left"][:, 1] > 0).all() and (mean_c["sidestep_right"][:, 1] < 0).all()


def test_facing_is_forward(all_takes):
    """In the root frame, toes are ahead of the ankles (z > 0) and left joints have x > 0 (walks)."""
    index = skeleton.INDEX
    for cat, js in _by_category(all_takes).items():
        if not cat.startswith(("walk", "sidestep")):
            continue  # sprinting feet point backwards much of the time
        for j in js[:20]:
            p = to_features(j, FPS)[0].reshape(-1, 21, 3).mean(0)
            assert p[index["Toes_L"], 2] > p[index["Foot_L"], 2] and p[index["Toes_R"], 2] > p[index["Foot_R"], 2], cat
            assert p[index["UpperLeg_L"], 0] > 0 > p[index["UpperLeg_R"], 0], cat


def _turn_left_take(all_takes):
    return next(j for f, j in all_takes.items() if "walk-turn-left" in f.name)


def test_mirror_and_reverse_are_involutions(all_takes):
    x, c = to_features(_turn_left_take(all_takes), FPS)
    xm, cm = mirror(*mirror(x, c))
    np.testing.assert_array_equal(xm, x)
    np.testing.assert_array_equal(cm, c)
    xr, cr = reverse(*reverse(x, c))
    np.testing.assert_array_equal(xr, x)
    np.testing.assert_allclose(cr, c, atol=1e-6)
    assert not np.allclose(mirror(x, c)[0], x) and not np.allclose(reverse(x, c)[1], c)
    # batched leading dimensions work the same
    xb, cb = reverse(np.stack([x, xm]), np.stack([c, cm]))
    np.testing.assert_array_equal(xb[1], reverse(xm, cm)[0])


def test_mirrored_left_turn_is_a_right_turn(all_takes):
    joints = _turn_left_take(all_takes)
    x, c = to_features(joints, FPS)
    xm, cm = mirror(x, c)
    assert c[1:, 2].mean() * FPS > 0.1 and cm[1:, 2].mean() * FPS < -0.1  # rad/s
    np.testing.assert_allclose(cm[:, 2], -c[:, 2])
    # mirroring features == features of the world-space reflection (x -> -x, left <-> right)
    reflected = joints[:, skeleton.MIRROR] * np.array([-1, 1, 1], np.float32)
    xw, cw = to_features(reflected, FPS)
    np.testing.assert_allclose(xw, xm, atol=1e-5)
    np.testing.assert_allclose(cw, cm, atol=1e-5)


def test_reverse_plays_the_motion_backwards(all_takes):
    joints = _turn_left_take(all_takes)
    x, c = to_features(joints, FPS)
    xr, cr = reverse(x, c)
    root, yaw = root_trajectory(joints, FPS)
    world = to_world(xr, cr, start_xz=root[-1], start_yaw=yaw[-1])
    np.testing.assert_allclose(world, joints[::-1], atol=1e-4)
    assert cr[1:, 2].mean() < 0  # a left turn played backwards turns right (facing unchanged)


def test_to_world_batched_and_start():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(2, 3, 30, 63)).astype(np.float32)
    c = rng.normal(scale=0.1, size=(2, 3, 30, 3)).astype(np.float32)
    w = to_world(x, c, start_xz=(1.0, -2.0), start_yaw=0.5)
    assert w.shape == (2, 3, 30, 21, 3)
    np.testing.assert_allclose(w[1, 2], to_world(x[1, 2], c[1, 2], (1.0, -2.0), 0.5), atol=1e-6)
    # frame 0: the pose rotated by the start heading about the start point; c[0] is ignored
    c2 = c.copy()
    c2[..., 0, :] = 5.0
    np.testing.assert_array_equal(to_world(x, c2, (1.0, -2.0), 0.5), w)
    p = x[0, 0, 0].reshape(21, 3)
    expect = np.stack(
        [
            np.cos(0.5) * p[:, 0] + np.sin(0.5) * p[:, 2] + 1,
            p[:, 1],
            -np.sin(0.5) * p[:, 0] + np.cos(0.5) * p[:, 2] - 2,
        ],
        -1,
    )
    np.testing.assert_allclose(w[0, 0, 0], expect, atol=1e-5)


def test_resampling_30_to_20_interpolates():
    """30 -> 20 fps: output frame 2k is input frame 3k exactly; the frames between are new poses."""
    take = next(BANDAI.glob("dataset-2/data/dataset-2_run_*.bvh.gz"))
    b = read_bvh(take)
    fk = fk_positions(b)[:, 1:] * 0.01  # drop joint_Root: the 21 body joints in order
    j20 = load_take(take, 20.0)
    assert len(j20) == (b.n_frames - 1) * 2 // 3 + 1
    np.testing.assert_allclose(j20[::2], fk[::3][: len(j20[::2])], atol=1e-5)
    mid = j20[1::2]
    n = len(mid)
    lo, hi = fk[1::3][:n], fk[2::3][:n]  # output frame 2k+1 sits at input frame 3k+1.5
    assert np.abs(mid - lo).max() > 1e-3 and np.abs(mid - hi).max() > 1e-3  # not a dropped/copied frame
    np.testing.assert_allclose(mid, (lo + hi) / 2, atol=0.02)  # and close to halfway


@pytest.mark.parametrize("take", PFNN_TAKES, ids=lambda p: p.name.split(".")[0])
def test_pfnn_takes(take):
    b = read_bvh(take)
    assert len(b.names) == 31 and round(b.fps) == 120 and all(len(ch) == 3 for ch in b.channels[1:])
    j = load_take(take, FPS)
    assert j.shape == (int((b.n_frames - 1) / 6) + 1, 21, 3)
    # low-passed then decimated: close to the raw FK at the same instants, but not identical
    raw = fk_positions(b)[::6] * SKELETON_MAPS["cmu"]["scale"]
    for ours, theirs in (("Hips", "Hips"), ("Head", "Head"), ("Foot_L", "LeftFoot")):
        err = np.linalg.norm(j[:, skeleton.INDEX[ours]] - raw[: len(j), b.names.index(theirs)], axis=-1)
        assert err.mean() < 0.02, (ours, err.mean())
    x, c = to_features(j, FPS)
    assert np.isfinite(x).all() and np.isfinite(c).all()
    speed = np.linalg.norm(c[1:, :2], axis=1) * FPS
    assert 0.3 < np.median(speed) < 4.0  # a mix of standing, walking, jogging and running
    assert np.abs(c[1:, 2]).max() * FPS < 2 * np.pi  # under one turn per second between frames


def test_pfnn_lowpass_removes_jitter():
    """Decimating 120 -> 20 low-passes first: the 20 fps take is smoother than plain decimation."""
    take = PFNN_TAKES[0]
    b = read_bvh(take)
    scale = SKELETON_MAPS["cmu"]["scale"]
    hand = b.names.index("LeftHand")
    plain = fk_positions(b)[::6, hand] * scale
    filtered = load_take(take, FPS)[:, skeleton.INDEX["Hand_L"]]

    def accel(p):
        return np.abs(np.diff(p, 2, axis=0)).mean()

    assert accel(filtered) < accel(plain[: len(filtered)])


def test_unknown_skeleton_is_a_clear_error(tmp_path):
    path = tmp_path / "odd.bvh"
    path.write_text(bvh_text(motion_values()))
    with pytest.raises(BvhError, match=r"odd\.bvh:1: unknown skeleton"):
        load_take(path)


def test_accepts_torch_tensors():
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(2)
    x = rng.normal(size=(2, 10, 63)).astype(np.float32)
    c = rng.normal(scale=0.1, size=(2, 10, 3)).astype(np.float32)
    np.testing.assert_array_equal(to_world(torch.from_numpy(x), torch.from_numpy(c)), to_world(x, c))
    np.testing.assert_array_equal(mirror(torch.from_numpy(x), torch.from_numpy(c))[0], mirror(x, c)[0])
