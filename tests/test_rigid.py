"""generation.rigid: generated poses put onto the actor's bones (issue 34, item 1)."""

import numpy as np
import pytest

from generation import pretrained, rigid, skeleton
from generation.dataset import read_arrays
from generation.sample import load_model, sample_windows


def lengths_of(x):
    j = x.reshape(x.shape[:-1] + (skeleton.N_JOINTS, 3)).astype(np.float64)
    return np.linalg.norm(j[..., 1:, :] - j[..., skeleton.PARENTS[1:], :], axis=-1)


@pytest.fixture(scope="module")
def heldout():
    return read_arrays(pretrained.HELDOUT, ["test_x", "test_c", "test_hist", "test_hist_c"])


def test_real_motion_is_left_as_it_is(heldout):
    """Mocap's bones are rigid already: fitting a real window to its own history's bones moves no joint by more
    than float rounding."""
    x, hist = heldout["test_x"][:8], heldout["test_hist"][:8]
    assert np.abs(rigid.fit_to_history(x, hist) - x).max() < 1e-5


def test_sampled_motion_gets_the_actors_bones_and_keeps_its_directions(heldout):
    d = {k: v[::12] for k, v in heldout.items()}
    mg = load_model(pretrained.CHECKPOINTS["mg"], "cpu")
    x = sample_windows(mg, d["test_c"], d["test_hist"], d["test_hist_c"], seed=0)
    assert lengths_of(x).std(axis=1).max() > 0.005  # the model's bones stretch by millimetres to centimetres
    y = rigid.fit_to_history(x, d["test_hist"])
    actor = rigid.bone_lengths(d["test_hist"])[:, None]
    assert np.abs(lengths_of(y) / actor - 1).max() < 1e-5
    # every bone points where the model pointed it, and the hips stay where the model put them
    jx, jy = (a.reshape(a.shape[:-1] + (skeleton.N_JOINTS, 3)) for a in (x, y))
    bx = jx[..., 1:, :] - jx[..., skeleton.PARENTS[1:], :]
    by = jy[..., 1:, :] - jy[..., skeleton.PARENTS[1:], :]
    cos = (bx * by).sum(-1) / np.linalg.norm(bx, axis=-1) / np.linalg.norm(by, axis=-1)
    assert cos.min() > 1 - 1e-5 and np.abs(jy[..., 0, :] - jx[..., 0, :]).max() == 0


def test_a_leg_chain_keeps_its_foot_where_the_leg_reaches_it():
    """The two-bone variant (measured in bench/rigid_bones.py): a foot within reach stays put, the knee bends."""
    rng = np.random.default_rng(0)
    x = (rng.normal(size=(1, 5, skeleton.POSE_DIM)) * 0.05).astype(np.float32)
    j = x.reshape(1, 5, skeleton.N_JOINTS, 3)
    hip, knee, foot = rigid.LEGS[0]
    j[..., hip, :] = j[..., 0, :] + [0.1, 0.0, 0.0]  # the pelvis bone as long as the actor's: the hip stays too
    j[..., knee, :] = j[..., hip, :] + [0.05, -0.2, 0.0]
    j[..., foot, :] = j[..., hip, :] + [0.0, -0.6, 0.0]  # 0.6 m below the hip: reachable with 0.4 + 0.4
    lengths = np.full(skeleton.N_JOINTS - 1, 0.4)
    lengths[hip - 1] = 0.1
    y = rigid.fit_bones(x, lengths, chains=rigid.LEGS).reshape(j.shape)
    assert np.abs(y[..., foot, :] - j[..., foot, :]).max() < 1e-5
    assert np.abs(lengths_of(y.reshape(x.shape)) - lengths).max() < 1e-5
    assert (y[..., knee, 0] - y[..., hip, 0]).min() > 0  # bent forward, as the model bent it


def test_the_default_job_records_the_fit_in_the_manifest(tmp_path):
    import csv

    from generation import make_stimuli

    out = tmp_path / "s"
    args = ["--out", str(out), "--n-items", "2", "--n-catch", "1", "--n-training", "0", "--size", "64"]
    assert make_stimuli.main([*args, "--workers", "1", "--quiet"]) == 0
    with open(out / "manifest.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    post = {(r["condition"], r["postprocess"]) for r in rows}
    assert post == {("NAT", ""), ("MG", rigid.RIGID), ("FL", rigid.RIGID), ("BAD", "")}
