"""generation.metrics.c2st_features: the C2ST one feature and one feature group at a time, for any skeleton."""

import numpy as np
import pytest

from generation.data.dataset import heldout_windows
from generation.metrics import c2st
from generation.metrics.c2st_features import (
    FEATURE_COLUMNS,
    GROUPS,
    feature_names,
    feature_report,
    feature_table,
    feature_text,
)
from generation.motion import skeleton
from generation.motion.features import to_world
from generation.sampling import pretrained

FPS = 20.0


@pytest.fixture(scope="module")
def real_clips():
    """40 real held-out windows in world coordinates (shipped with the repository; no ../shared)."""
    x, c = heldout_windows(pretrained.HELDOUT, ("x", "c"))
    return to_world(x[::4][:40], c[::4][:40])


def test_the_names_follow_the_features_layout_for_any_skeleton(real_clips):
    names, groups = feature_names(skeleton.JOINT_NAMES, skeleton.PARENTS)
    assert len(names) == len(groups) == len(c2st.clip_features(real_clips[0], FPS, skeleton.PARENTS))
    assert len(set(names)) == len(names) and set(groups) == set(GROUPS)
    assert names[:2] == ["Hips x mean", "Hips y mean"] and names[-1] == "Foot_R-Toes_R length spread"
    # a 3-joint chain: a root, its child, a grandchild
    chain = np.random.default_rng(0).normal(size=(30, 3, 3))
    names, groups = feature_names(["a", "b", "c"], [-1, 0, 1])
    assert len(names) == len(c2st.clip_features(chain, FPS, [-1, 0, 1]))
    assert "b-c length" in names and "c jerk" in names and groups[names.index("c y spread")] == "position spread"


def test_the_report_names_the_feature_that_differs_and_which_way(real_clips):
    """The same real windows with the right hand shaking by 5 mm: the jerk group tells them apart, the hand's jerk
    leads the features (higher in the condition), and a joint that did not change is near chance."""
    rng = np.random.default_rng(1)
    hand = skeleton.INDEX["Hand_R"]
    shaken = real_clips.copy()
    shaken[:, :, hand] += rng.normal(scale=0.005, size=shaken[:, :, hand].shape)
    ref = {f"r{i}": c2st.clip_features(j, FPS, skeleton.PARENTS) for i, j in enumerate(real_clips[::2])}
    other = {f"s{i}": c2st.clip_features(j, FPS, skeleton.PARENTS) for i, j in enumerate(shaken[1::2])}
    names, groups = feature_names(skeleton.JOINT_NAMES, skeleton.PARENTS)
    rows = feature_report(ref, other, names, groups, seeds=2)
    by_group = {r["group"]: r["auc"] for r in rows if r["kind"] == "group"}
    assert by_group["jerk"] >= 0.95
    feats = [r for r in rows if r["kind"] == "feature"]
    assert feats[0]["auc"] == 1.0 and feats[0]["direction"] == "higher" and "Hand_R" in feats[0]["feature"]
    assert {r["feature"]: r["auc"] for r in feats}["Head jerk"] < 0.8  # other windows, the same motion
    assert all(0.5 <= r["auc"] <= 1 for r in feats)  # direction-free; a group's classifier may do worse than chance
    assert [r["auc"] for r in feats] == sorted((r["auc"] for r in feats), reverse=True)


def test_the_table_has_a_row_per_condition_feature_and_group(real_clips):
    feats = {}
    for i, j in enumerate(real_clips[:20]):
        c2st.collect(feats, "NAT", "test", f"item{i}", j, FPS, skeleton.PARENTS)
        c2st.collect(feats, "MG", "test", f"item{i}", j + [0, 0.05, 0], FPS, skeleton.PARENTS)  # 5 cm up
    table = feature_table(feats, skeleton.JOINT_NAMES, skeleton.PARENTS)
    assert all(tuple(r) == FEATURE_COLUMNS for r in table) and {r["condition"] for r in table} == {"MG"}
    names, _ = feature_names(skeleton.JOINT_NAMES, skeleton.PARENTS)
    kinds = [r["kind"] for r in table]
    assert kinds.count("group") == len(GROUPS) and kinds.count("feature") <= len(names)
    assert table[len(GROUPS)]["feature"].endswith("y mean") and table[len(GROUPS)]["direction"] == "higher"
    line = feature_text(table).splitlines()[1]
    assert line.split()[0] == "MG" and "position mean" in line and "y mean" in line
