"""Objective motion metrics on real takes and on motion spoiled in known ways."""

import warnings

import numpy as np
import pytest
from helpers.paths import takes

from generation.metrics.objective import (
    CONTACT_HEIGHT,
    bone_length_std,
    clip_metrics,
    control_error,
    foot_skating,
    jerk,
    style_retention,
)
from generation.motion import skeleton
from generation.motion.features import load_take, to_features

pytestmark = pytest.mark.full  # the full tier: real walks from ../shared


@pytest.fixture(scope="module")
def walks():
    """4-s windows (80 frames at 20 fps) of five real straight walks."""
    return [load_take(p, 20.0)[:80] for p in takes("walk", 5)]


def test_metrics_real_walks_are_plausible(walks):
    for j in walks:
        m = clip_metrics(j, 20.0, to_features(j, 20.0)[1])
        speed = np.linalg.norm(j[-1, 0, [0, 2]] - j[0, 0, [0, 2]]) / 4.0
        assert speed > 0.7  # it is a walk...
        assert m["foot_skating"] < 0.2 * speed  # ...and planted feet barely slide
        assert m["bone_length_std"] < 1e-3  # rigid skeleton (resampling keeps bone lengths)
        assert m["control_error"] < 0.02  # the control was measured on this very body
        assert 10 < m["jerk"] < 300


def test_metrics_foot_skating_sees_sliding_feet(walks):
    j = walks[0].astype(np.float64)
    slide = j.copy()
    slide[..., 0] += 0.6 * np.arange(80)[:, None] / 20.0  # the whole body glides sideways at 0.6 m/s
    assert foot_skating(slide, 20.0) > foot_skating(j, 20.0) + 0.45
    assert foot_skating(j, 20.0) < 0.15


def test_metrics_foot_skating_contact_threshold_and_fallback():
    assert CONTACT_HEIGHT == pytest.approx(0.01)
    t = np.arange(40)[:, None] / 20.0
    j = np.zeros((40, skeleton.N_JOINTS, 3))
    j[:, :, 1] = 0.0
    j[:, :, 0] = 2.0 * t  # on the floor, gliding at 2 m/s
    assert foot_skating(j, 20.0) == pytest.approx(2.0)
    # Feet that never rest (bobbing 30 cm, so never two frames within 1 cm of the lowest point): the
    # lowest 10% of frame pairs count as contact; gliding at 1 m/s then shows, standing still does not.
    j[:, :, 1] = 0.5 + 0.3 * np.sin(2 * np.pi * 1.3 * t)
    j[:, :, 0] = 1.0 * t
    assert foot_skating(j, 20.0) == pytest.approx(1.0)
    j[:, :, 0] = 0.0
    assert foot_skating(j, 20.0) == pytest.approx(0.0)
    assert np.isnan(foot_skating(j[:1], 20.0))


def test_metrics_bone_length_and_jerk_see_noise(walks):
    j = walks[1].astype(np.float64)
    noisy = j + np.random.default_rng(0).normal(0, 0.02, j.shape)
    assert bone_length_std(noisy) > 10 * bone_length_std(j)
    assert bone_length_std(noisy) > 0.01
    assert jerk(noisy, 20.0) > 5 * jerk(j, 20.0)
    line = np.zeros((30, skeleton.N_JOINTS, 3))
    line[..., 2] = 1.5 * np.arange(30)[:, None] / 20.0 + 0.1 * (np.arange(30)[:, None] / 20.0) ** 2
    assert jerk(line, 20.0) == pytest.approx(0.0, abs=1e-6)  # constant acceleration: no jerk
    assert np.isnan(jerk(line[:3], 20.0))


def test_metrics_control_error_compares_paths_up_to_placement(walks):
    turn = load_take(takes("walk_turn_left", 1)[0], 20.0)[:80]
    straight = walks[2]
    c_turn, c_straight = to_features(turn)[1], to_features(straight)[1]
    assert control_error(turn, c_turn) < 0.02
    assert control_error(turn, c_straight) > 0.1  # a curved body path against a straight request
    # Placement in the world does not count: rotate and move the clip.
    a = 1.1
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    moved = turn @ rot.T + np.array([4.0, 0.0, -7.0])
    assert control_error(moved, c_turn) == pytest.approx(control_error(turn, c_turn), abs=1e-4)


def test_metrics_clip_metrics_keys_and_bad_shape(walks):
    m = clip_metrics(walks[0], 20.0)
    assert set(m) == {"foot_skating", "bone_length_std", "jerk", "control_error", "control_following", "acceleration"}
    assert np.isnan(m["control_error"]) and np.isnan(m["control_following"])
    with pytest.raises(ValueError, match="21"):
        clip_metrics(np.zeros((10, 22, 3)), 20.0)


def test_control_following_real_walks_follow_and_a_body_on_the_wrong_control_does_not(walks):
    from generation.metrics.objective import control_following
    from generation.motion.features import to_world

    windows = [to_features(j, 20.0) for j in walks]
    for x, c in windows:
        assert control_following(to_world(x, c), c) < 0.05  # feet carry the body along its own control
    # The same bodies driven by another walk's control turned into a side-step: their feet no longer agree.
    x, c = windows[0]
    side = c.copy()
    side[:, :2] = c[:, [1, 0]]
    assert control_following(to_world(x, side), side) > 0.3
    # Zero-mean jitter of 2 cm per frame is foot skating, not a failure to follow: it largely cancels.
    rng = np.random.default_rng(0)
    shaky = to_world(x + rng.normal(0, 0.02, x.shape).astype(np.float32), c)
    assert control_following(shaky, c) < 0.1 and foot_skating(shaky, 20.0) > 0.3
    # A diverged model's clip (one NaN frame) scores NaN rather than stopping the whole table (SVD would raise).
    broken = to_world(x, c)
    broken[40] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # NaN by intent, not by numpy's "mean of empty slice"
        assert np.isnan(control_following(broken, c)) and np.isnan(clip_metrics(broken, 20.0, c)["control_error"])
        assert np.isnan(foot_skating(broken, 20.0))


def test_frechet_distance_matches_the_closed_form_for_diagonal_gaussians():
    from generation.metrics.fmd import frechet_distance

    mu_a, mu_b = np.array([0.0, 1.0, 2.0]), np.array([1.0, 1.0, 0.0])
    var_a, var_b = np.array([1.0, 4.0, 0.25]), np.array([9.0, 1.0, 0.25])
    expected = np.sum((mu_a - mu_b) ** 2) + np.sum((np.sqrt(var_a) - np.sqrt(var_b)) ** 2)
    assert frechet_distance(mu_a, np.diag(var_a), mu_b, np.diag(var_b)) == pytest.approx(expected, rel=1e-9)
    assert frechet_distance(mu_a, np.diag(var_a), mu_a, np.diag(var_a)) == pytest.approx(0, abs=1e-9)


def test_shipped_motion_encoder_ranks_real_held_out_motion_first(small_dataset):
    """The FMD floor (held-out real motion) lies well below the same motion spoiled: frames shuffled in time,
    held still (a standing pose), or shaken by 2 cm of noise per frame."""
    from generation.metrics.fmd import MotionEncoder
    from generation.sampling.pretrained import MOTION_ENCODER

    enc = MotionEncoder.load(MOTION_ENCODER)
    with np.load(small_dataset) as d:
        real, cats = d["test_x"], d["test_labels"]
    rng = np.random.default_rng(0)
    floor = enc.fmd(real, cats)
    assert floor < 0.8 * enc.fmd(real[:, rng.permutation(real.shape[1])], cats)
    assert floor < 0.6 * enc.fmd(np.repeat(real[:, :1], real.shape[1], axis=1), cats)
    assert floor < 0.8 * enc.fmd(real + rng.normal(0, 0.02, real.shape).astype(np.float32), cats)
    # The reference follows the set's category mix: one category alone is scored against that category.
    walk = cats == "walk"
    assert enc.fmd(real[walk], cats[walk]) < enc.fmd(real[walk], ["run"] * int(walk.sum()))


def test_late_stepping_sees_a_gait_that_dies_out(walks):
    from generation.metrics.objective import late_stepping

    for j in walks:
        x = to_features(j, 20.0)[0]
        assert 0.1 < late_stepping(x, 20.0) < 0.8  # real walks swing their feet by tens of centimetres
        # The same walk frozen in its pose at 2 s: the last 2 s stand still.
        frozen = x.copy()
        frozen[40:] = x[40]
        assert late_stepping(frozen, 20.0) < 1e-6
        assert late_stepping(frozen, 20.0, seconds=3.0) > 0.05  # a longer span still sees the steps before
    # Side-steps count: the same steps turned a quarter turn, so that the feet swing sideways, score the same.
    joints = x.reshape(80, skeleton.N_JOINTS, 3)
    sideways = np.stack([joints[..., 2], joints[..., 1], -joints[..., 0]], axis=-1)
    assert late_stepping(sideways, 20.0) == pytest.approx(late_stepping(x, 20.0), rel=1e-6)


def test_style_retention_tells_a_take_kept_from_an_average_walker():
    """generation.metrics.objective.style_retention on the shipped held-out windows (styled takes): a take's own earlier
    stretch keeps its style (NAT's first half against its second), another take of the same category does not,
    and neither does the category's average; a reference pool gives the same answer as the windows themselves
    when it holds the same windows."""
    from generation.data.dataset import heldout_windows
    from generation.sampling.pretrained import HELDOUT

    x, takes, cats = heldout_windows(HELDOUT, ("x", "take", "labels"))
    half = x.shape[1] // 2
    share, ratio = style_retention(x[:, :half], x, takes, cats)
    assert share >= 0.9 and ratio < 0.7, (share, ratio)
    # Each window replaced by a window of another take in its category: an average walker of that category.
    swapped = x.copy()
    for i in range(len(x)):
        others = np.flatnonzero((cats == cats[i]) & (takes != takes[i]))
        swapped[i] = x[others[i % len(others)]]
    share_swapped, ratio_swapped = style_retention(swapped, x, takes, cats, start=half)
    assert share_swapped <= 0.4 and ratio_swapped > 1, (share_swapped, ratio_swapped)
    every = style_retention(x[:, :half], x, takes, cats, reference=(x, takes, cats))
    assert every == (share, ratio)
    # Half the windows scored against all of them as the pool: the same as scoring each against the same pool.
    part = style_retention(x[::2, :half], x[::2], takes[::2], cats[::2], reference=(x, takes, cats))
    assert 0.8 <= part[0] <= 1


def test_any_skeletons_metrics_leave_a_root_marker_out():
    """A real Bandai-Namco take whose joint_Root stays at the scene's origin while the body walks: the marker is no
    bone of the body, so the rigid mocap's bone-length variation is ~0, and wherever the marker is, every metric is
    the same (the old metrics stretched a "bone" from the origin to the hips by metres)."""
    from helpers.paths import TEST_DATA

    from generation.data.motion_files import read_motion
    from generation.metrics.objective import any_clip_metrics, find_feet

    m = read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", fps=20.0)
    assert m.names[0] == "joint_Root" and m.names[1] == "Hips"
    assert np.ptp(m.joints[:, 0], axis=0).max() < 1e-6 < np.ptp(m.joints[:, 1, [0, 2]], axis=0).max() - 1.0
    feet = find_feet(m.names)
    still = any_clip_metrics(m.joints, 20.0, m.names, m.parents, feet)
    assert still["bone_length_std"] < 1e-5
    moved = m.joints.copy()
    moved[:, 0] = m.joints[:, 1] * [1.0, 0.0, 1.0]  # the marker carried under the hips instead
    assert any_clip_metrics(moved, 20.0, m.names, m.parents, feet) == pytest.approx(still, nan_ok=True)
