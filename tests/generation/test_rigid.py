"""generation.motion.rigid: generated poses put onto the actor's bones (issue 34, item 1)."""

import numpy as np
import pytest

from generation.data.dataset import read_arrays
from generation.metrics.c2st_features import FEATURE_COLUMNS
from generation.motion import invariants, rigid, skeleton
from generation.sampling import pretrained
from generation.sampling.sample import load_model, sample_windows


def lengths_of(x):
    return rigid.frame_bone_lengths(np.asarray(x, dtype=np.float64))


@pytest.fixture(scope="module")
def heldout():
    return read_arrays(pretrained.HELDOUT, ["test_x", "test_c", "test_hist", "test_hist_c"])


def test_real_motion_is_left_as_it_is(heldout):
    """Mocap's bones are rigid already: fitting a real window to its own history's bones moves no joint by more
    than float rounding."""
    x, hist = heldout["test_x"][:8], heldout["test_hist"][:8]
    assert np.abs(rigid.fit_to_history(x, hist) - x).max() < 1e-5


def widths(x):
    """Per frame, the distances between the children of each rigid group: [..., T, pairs]."""
    j = np.asarray(x, dtype=np.float64).reshape(*np.shape(x)[:-1], skeleton.N_JOINTS, 3)
    pairs = [(a, b) for kids in rigid.rigid_groups().values() for i, a in enumerate(kids) for b in kids[i + 1 :]]
    return np.stack([np.linalg.norm(j[..., a, :] - j[..., b, :], axis=-1) for a, b in pairs], axis=-1)


def test_rigid_groups_are_the_hips_and_the_chest():
    names = {skeleton.JOINT_NAMES[p]: [skeleton.JOINT_NAMES[k] for k in ks] for p, ks in rigid.rigid_groups().items()}
    assert names == {"Hips": ["Spine", "UpperLeg_L", "UpperLeg_R"], "Chest": ["Neck", "Shoulder_L", "Shoulder_R"]}


def test_fit_skeleton_holds_the_groups_shape_and_is_a_no_op_on_real_frames(heldout):
    """Real windows hold the hips' and the chest's shapes to float rounding, and fit_skeleton leaves them; windows
    with 1 cm of noise on every joint get the reference's bone lengths and group shapes exactly, stay within the
    noise of where they were, and a whole window turned about the vertical comes back turned, not unturned."""
    x, hist = heldout["test_x"][:8].astype(np.float64), heldout["test_hist"][:8].astype(np.float64)
    assert widths(x).std(axis=1).max() < 1e-6  # the invariant in the data
    assert np.abs(rigid.fit_skeleton(x, hist[:, -1]) - x).max() < 1e-5
    noisy = x + np.random.default_rng(0).normal(0, 0.01, x.shape)
    assert widths(noisy).std(axis=1).max() > 5e-3
    y = rigid.fit_skeleton(noisy, hist[:, -1])
    assert np.abs(widths(y) - widths(hist[:, -1:])).max() < 1e-9
    assert np.abs(lengths_of(y) - lengths_of(hist[:, -1:])).max() < 1e-9
    assert np.abs(y - noisy).reshape(8, -1, 21, 3).max(-1).mean() < 0.03
    turn = np.radians(50.0)
    rot = np.array([[np.cos(turn), 0, np.sin(turn)], [0, 1, 0], [-np.sin(turn), 0, np.cos(turn)]])
    turned = (x.reshape(8, -1, 21, 3) @ rot.T).reshape(x.shape)
    assert np.abs(rigid.fit_skeleton(turned, hist[:, -1]) - turned).max() < 1e-5


def test_sampled_motion_gets_the_actors_bones_and_stays_near_it(heldout):
    d = {k: v[::12] for k, v in heldout.items()}
    mg = load_model(pretrained.CHECKPOINTS["mg"], "cpu")
    x = sample_windows(mg, d["test_c"], d["test_hist"], d["test_hist_c"], seed=0)
    assert lengths_of(x).std(axis=1).max() > 0.005  # the model's bones stretch by millimetres to centimetres
    y = rigid.fit_to_history(x, d["test_hist"])
    actor = rigid.bone_lengths(d["test_hist"])[:, None]
    assert np.abs(lengths_of(y) / actor - 1).max() < 1e-5
    # the hips stay where the model put them, and no joint moves further than the model's bones were off
    jx, jy = (a.reshape(a.shape[:-1] + (skeleton.N_JOINTS, 3)) for a in (x, y))
    assert np.abs(jy[..., 0, :] - jx[..., 0, :]).max() == 0
    moved = np.linalg.norm(jy - jx, axis=-1).max()
    assert moved <= np.abs(lengths_of(x) - actor).max() * 2


def test_a_bone_length_error_does_not_carry_down_the_limb():
    """Each joint goes to the nearest point at its bone's length from its placed parent: a thigh 2 cm too long moves
    the knee, and the shin, aimed at where the model put the foot, brings the foot back to within its own error."""
    j = np.zeros((1, 1, skeleton.N_JOINTS, 3))
    hip, knee, foot = (skeleton.INDEX[n] for n in ("UpperLeg_L", "LowerLeg_L", "Foot_L"))
    j[..., hip, :] = [0.1, 0.0, 0.0]
    j[..., knee, :] = [0.1, -0.42, 0.0]  # the model's thigh: 0.42 m
    j[..., foot, :] = [0.1, -0.82, 0.0]  # its shin 0.40 m, as the actor's
    lengths = rigid.bone_lengths(j.reshape(1, 1, -1))[0]
    lengths[knee - 1] = 0.40  # the actor's thigh
    y = rigid.fit_bones(j, lengths).reshape(j.shape)
    assert np.allclose(y[..., knee, :], [0.1, -0.40, 0.0]) and np.allclose(y[..., foot, :], [0.1, -0.80, 0.0])
    assert np.abs(lengths_of(y.reshape(1, 1, -1)) - lengths).max() < 1e-9


@pytest.mark.full  # the default job run: the full tier (the fast tier stays short)
def test_the_default_job_records_the_fit_in_the_manifest(tmp_path):
    import csv

    from generation import make_stimuli

    out = tmp_path / "s"
    args = ["--out", str(out), "--n-items", "2", "--n-catch", "1", "--n-training", "0", "--size", "64"]
    assert make_stimuli.main([*args, "--workers", "1", "--quiet"]) == 0
    with open(out / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    post = {(r["condition"], r["postprocess"]) for r in rows}
    shipped = invariants.POSTPROCESS  # the hips on the root, then the actor's bones
    assert shipped == "root_hips+rigid_skeleton"
    assert post == {("NAT", ""), ("MG", shipped), ("FL", shipped), ("BAD", "")}
    with open(out / "c2st_features.csv", newline="") as f:  # what tells MG and FL apart, with its groups
        features = list(csv.DictReader(f))
    assert tuple(features[0]) == FEATURE_COLUMNS
    assert {r["condition"] for r in features} >= {"MG", "FL"}
