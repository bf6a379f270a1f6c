"""The catch clips the tool makes (generation.stimuli.catch_kinds) on a body whose first joint is a root marker:
Bandai-Namco's `joint_Root`, left at the scene's origin in dataset 2 while the walk of tests/data/bvh goes 8 m.
A frozen pose and a swapped upper body are carried along by the body's root, the hips, not by the marker: else a
frozen walker stands still and a swapped torso floats metres from its legs (the camera then frames both)."""

import numpy as np
import pytest
from helpers.paths import TEST_DATA

from generation.data.motion_files import read_motion
from generation.stimuli.catch_kinds import make_catch, unlike_any_pose
from moglow_eval.core.skeleton_names import body_root


@pytest.fixture(scope="module")
def walk():
    m = read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", fps=20.0)
    assert np.abs(m.joints[:, 0]).max() == 0.0  # the marker at the origin throughout
    return m.joints, body_root(list(m.names), m.parents)


def _spread(clip, hips):
    """The farthest any body joint gets from the hips on the floor, in metres."""
    return float(np.linalg.norm(clip[:, 1:, [0, 2]] - clip[:, hips : hips + 1, [0, 2]], axis=-1).max())


@pytest.mark.parametrize("kind", ["freeze", "swap"])
def test_a_broken_body_stays_together_and_walks_on_with_its_hips(walk, kind):
    joints, hips = walk
    travelled = np.linalg.norm(joints[-1, hips, [0, 2]] - joints[0, hips, [0, 2]])
    assert travelled > 2.0 and _spread(joints, hips) < 1.0  # a real walk, its body together
    broken = make_catch(joints, kind, seed=0, root=hips)
    assert _spread(broken, hips) < 1.0  # the torso over the hips
    np.testing.assert_allclose(broken[:, hips], joints[:, hips], atol=1e-6)  # walking on as recorded
    if kind == "freeze":
        half = broken[len(broken) // 2 :, 1:] - broken[len(broken) // 2 :, hips : hips + 1]
        assert np.abs(np.diff(half, axis=0)).max() < 1e-5  # the pose held


def test_poses_unlike_the_takes_own_tell_a_broken_body_from_the_take_played_otherwise(walk):
    joints, hips = walk
    body = joints[:, 1:]  # without the marker; the hips are body joint hips - 1
    assert np.abs(unlike_any_pose(body[::-1], body, hips - 1)).max() < 1e-6  # its own poses, in another order
    assert np.median(unlike_any_pose(make_catch(joints, "swap", 0, root=hips)[:, 1:], body, hips - 1)) > 0.05
