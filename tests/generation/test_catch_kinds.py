"""The catch clips the tool makes (generation.stimuli.catch_kinds) on a body whose first joint is a root marker:
Bandai-Namco's `joint_Root`, left at the scene's origin in dataset 2 while the walk of tests/data/bvh goes 8 m.
A frozen pose and a swapped upper body are carried along by the body's root, the hips, not by the marker: else a
frozen walker stands still and a swapped torso floats metres from its legs (the camera then frames both). A kind that
would not be seen on a take (a freeze of one still after its first quarter) gives way to the study's next kind."""

import logging
import shutil
from types import SimpleNamespace

import numpy as np
import pytest
from helpers.own_study_data import ACTIONS
from helpers.paths import TEST_DATA

from generation.data.motion_files import read_motion
from generation.own_study.builder import catch_clips
from generation.own_study.inputs import read_options
from generation.own_study.study_file import read_study_file
from generation.stimuli.catch_kinds import VISIBLE, make_catch, make_visible_catch, strays, unlike_any_pose
from moglow_eval.core import study
from moglow_eval.core.cli import UserError
from moglow_eval.core.skeleton_names import body_root

STILL = "dataset-1_byebye_not-confident_001.bvh.gz"  # a wave goodbye, still after its first quarter


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


def test_a_freeze_that_would_look_like_the_take_gives_way_to_the_studys_next_kind(walk, caplog, shared_dir):
    """A rater who rated such a freeze as real would be excluded for seeing rightly; so the study's next kind breaks
    the take, the manifest records the kind made, and a study whose kinds none break it stops with one line."""
    still = read_motion(ACTIONS / STILL, fps=20.0)
    root = body_root(still.names, still.parents)
    assert strays(make_catch(still.joints, "freeze", 0, root), still.joints, root) < VISIBLE
    joints, hips = walk
    assert strays(make_catch(joints, "freeze", 0, hips), joints, hips) > 2 * VISIBLE  # a walk frozen: seen
    assert make_visible_catch(joints, ["freeze", "swap"], 0, hips)[1] == "freeze"
    broken, kind = make_visible_catch(still.joints, ["freeze", "swap"], 0, root)
    assert kind == "swap" and strays(broken, still.joints, root) >= VISIBLE
    assert make_visible_catch(still.joints, ["freeze"], 0, root) is None

    motions = {study.NATURAL: {"bye": still}}
    spec = SimpleNamespace(catch_folder=None, catch_make=["freeze", "jitter"], seed=0)
    with caplog.at_level(logging.INFO):
        assert catch_clips(spec, motions, ["bye"], progress=False)["bye"][1] == "jitter"
    assert "catch item bye: made a jitter, as a freeze of it would look like the motion itself" in caplog.text
    spec.catch_make = ["freeze"]
    with pytest.raises(UserError, match=f"^{still.path}: catch item bye: a freeze of it would look like the motion"):
        catch_clips(spec, motions, ["bye"], progress=False)
    # the advice names the kinds the study left out: a pose held two frames, which neither a freeze nor a swap moves
    held = SimpleNamespace(
        joints=still.joints[:1].repeat(2, axis=0), names=still.names, parents=still.parents, path="h"
    )
    spec.catch_make = ["freeze", "swap"]
    with pytest.raises(UserError, match="; add jitter to \\[catch\\] make, or give the catch clips yourself"):
        catch_clips(spec, {study.NATURAL: {"bye": held}}, ["bye"], progress=False)


def test_a_studys_own_catch_clip_that_barely_differs_from_the_reference_is_warned_of(tmp_path, caplog, shared_dir):
    """A catch folder holding the reference's own file (a copy made by mistake) would exclude attentive raters; the
    build keeps the user's choice and says so. A clip of another take passes without a word."""
    for folder in ("real", "sys", "bad"):
        (tmp_path / folder).mkdir()
    shutil.copy(ACTIONS / STILL, tmp_path / "real" / "bye.bvh.gz")
    study_toml = tmp_path / "study.toml"
    conditions = '[conditions]\nreal = "real"\nSYS = "sys"\n'
    study_toml.write_text(f'reference = "real"\nfps = 20\n{conditions}[catch]\nfolder = "bad"\n')
    spec = read_study_file(study_toml)
    motions = {study.NATURAL: {"bye": read_motion(tmp_path / "real" / "bye.bvh.gz", **read_options(spec))}}
    for source, warned in ((ACTIONS / STILL, True), (ACTIONS / "dataset-1_punch_normal_001.bvh.gz", False)):
        shutil.copy(source, tmp_path / "bad" / "bye.bvh.gz")
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            assert catch_clips(spec, motions, ["bye"], progress=False)["bye"][1] == "own"
        said = f"bye.bvh.gz: catch clip of item bye strays under {VISIBLE * 100:g} cm from its reference clip"
        assert (said in caplog.text) == warned, caplog.text
