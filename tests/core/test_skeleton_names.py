"""moglow_eval.core.skeleton_names on Bandai-Namco's skeleton, whose first joint is a root marker (`joint_Root`, left
at the scene's origin in dataset 2 while the body walks metres away: tests/data/bvh's walk), and on one without."""

import numpy as np
import pytest
from helpers.paths import TEST_DATA

from generation.data.motion_files import read_motion
from generation.metrics import c2st
from moglow_eval.core.skeleton_names import body_root, body_skeleton, is_hips, root_markers


@pytest.fixture(scope="module")
def walk():
    return read_motion(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz", fps=20.0)


def test_the_body_hangs_from_the_hips_under_the_marker(walk):
    names, parents = list(walk.names), np.asarray(walk.parents)
    assert root_markers(names, parents) == [0] and names[0] == "joint_Root"
    assert names[body_root(names, parents)] == "Hips"
    keep, body_names, body_parents = body_skeleton(names, parents)
    assert keep == list(range(1, len(names))) and body_names == names[1:]
    assert body_parents[0] == -1 and all(0 <= p < k for k, p in enumerate(body_parents) if k)
    assert [body_names[p] for p in body_parents[1:]] == [names[parents[j]] for j in keep[1:]]  # the same bones


def test_a_skeleton_without_a_marker_is_its_own_body():
    names, parents = ["Hips", "Spine", "Head", "LeftLeg"], [-1, 0, 1, 0]
    assert root_markers(names, parents) == [] and body_root(names, parents) == 0
    assert body_skeleton(names, parents) == ([0, 1, 2, 3], names, parents)


def test_the_c2st_features_of_the_body_leave_out_where_it_walks(walk):
    """Taken on the body (the marker left out, the hips its root), a clip's C2ST features are the same when the
    whole body is 5 m further on and the marker stays at the origin; over every joint, with the marker as the root,
    they changed with the place."""
    names, parents = list(walk.names), np.asarray(walk.parents)
    here = walk.joints.astype(np.float64)
    assert np.abs(here[:, 0]).max() == 0.0  # the marker at the origin, as recorded
    there = here + np.array([5.0, 0.0, 0.0])
    there[:, 0] = 0.0
    keep, _, body_parents = body_skeleton(names, parents)
    on_body = [c2st.clip_features(j[:, keep], 20.0, body_parents) for j in (here, there)]
    np.testing.assert_allclose(on_body[0], on_body[1], atol=1e-9)
    everything = [c2st.clip_features(j, 20.0, parents) for j in (here, there)]
    assert np.abs(everything[0] - everything[1]).max() > 1.0


def test_the_hips_are_told_from_one_sides_hip():
    assert all(is_hips(n) for n in ("Hips", "pelvis", "Pelvis", "b_hips", "mixamorig:Hips", "Hip"))
    assert not any(is_hips(n) for n in ("LeftHip", "RHip", "hip_L", "Spine", "joint_Root", "world"))
