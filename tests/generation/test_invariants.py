"""generation.motion.invariants: the features' exact invariants found in real windows, and generated poses put back
onto them (the hips on the root)."""

import numpy as np
import pytest

from generation.data.dataset import heldout_windows, read_arrays
from generation.motion import invariants, rigid, skeleton
from generation.sampling import pretrained
from generation.sampling.sample import load_model, sample_windows


@pytest.fixture(scope="module")
def heldout():
    """Every shipped held-out window (real motion, no ../shared): x, control, history, history control."""
    return heldout_windows(pretrained.HELDOUT, ("x", "c", "hist", "hist_c"))


def test_the_check_finds_the_hips_on_the_root_and_nothing_else_in_real_windows(heldout):
    x, _, hist, _ = heldout
    found = invariants.constant_dims(np.concatenate([x, hist], axis=1))
    assert found == dict.fromkeys(invariants.HIPS_XZ, 0.0)
    names = [f"{skeleton.JOINT_NAMES[d // 3]} {'xyz'[d % 3]}" for d in found]
    assert names == ["Hips x", "Hips z"]


def test_the_check_sees_a_planted_constant_and_not_a_value_that_moves_by_a_millimetre():
    x = np.random.default_rng(0).normal(size=(4, 50, 6))
    x[..., 1] = 0.25
    x[..., 4] = 0.5 + 1e-3 * np.sign(x[..., 4])  # two values a millimetre apart: no invariant
    assert invariants.constant_dims(x) == {1: 0.25}
    with pytest.raises(ValueError, match="no frames"):
        invariants.constant_dims(np.zeros((0, 80, 6)))


def test_putting_the_hips_on_the_root_leaves_real_windows_exactly_as_they_are(heldout):
    x, _, hist, _ = heldout
    assert np.array_equal(invariants.root_hips(x), x)
    assert np.abs(invariants.fit_to_actor(x[:16], hist[:16]) - x[:16]).max() < 1e-5  # the bones too (float rounding)


def test_a_sample_loses_its_drift_and_nothing_else(heldout):
    x, c, hist, hist_c = (a[::16] for a in heldout)
    mg = load_model(pretrained.CHECKPOINTS["mg"], "cpu")
    s = sample_windows(mg, c, hist, hist_c, pretrained.TEMPERATURE["MG"], seed=0)
    drift = s[..., list(invariants.HIPS_XZ)]
    assert np.abs(drift).max() > 0 and drift.std(axis=1).max() > 0  # the model leaves the hips off the root
    y = invariants.root_hips(s)
    assert np.all(y[..., list(invariants.HIPS_XZ)] == 0)
    others = np.setdiff1d(np.arange(s.shape[-1]), invariants.HIPS_XZ)
    assert np.array_equal(y[..., others], s[..., others]) and y.dtype == s.dtype
    shipped = invariants.fit_to_actor(s, hist)  # then the actor's bones: the hips stay on the root
    assert np.all(shipped[..., list(invariants.HIPS_XZ)] == 0)
    bones = rigid.frame_bone_lengths(shipped.astype(np.float64))
    assert np.abs(bones / rigid.bone_lengths(hist)[:, None] - 1).max() < 1e-5


def test_the_hips_of_the_features_are_joint_0_in_the_shipped_skeleton():
    names = read_arrays(pretrained.HELDOUT, ["joint_names"])["joint_names"]
    assert [str(names[d // 3]) for d in invariants.HIPS_XZ] == ["Hips", "Hips"] == [skeleton.JOINT_NAMES[0]] * 2


def test_the_command_names_the_invariants_of_a_dataset_and_refuses_one_without_training_windows(
    heldout, tmp_path, capsys
):
    data = tmp_path / "dataset.npz"
    np.savez(data, train_x=heldout[0][:40])
    assert invariants.main([str(data)]) == 0
    assert capsys.readouterr().out.splitlines()[1:] == ["  0: Hips x = 0", "  2: Hips z = 0"]
    assert invariants.main([str(pretrained.HELDOUT)]) == 2
    assert "missing key 'train_x'" in capsys.readouterr().err


def test_the_command_says_in_one_line_what_is_wrong_with_a_file_that_is_not_a_dataset(heldout, tmp_path, capsys):
    """numpy's own words for a text file or a lone array are about pickled data, and the command used to stop on
    them, and on a truncated archive, with a traceback."""
    bvh = tmp_path / "take.bvh"
    bvh.write_text("HIERARCHY\nROOT Hips\n")
    np.save(tmp_path / "lone.npy", heldout[0][:2])
    good = tmp_path / "good.npz"
    np.savez(good, train_x=heldout[0][:2])
    (tmp_path / "cut.npz").write_bytes(good.read_bytes()[:300])
    np.savez(tmp_path / "narrow.npz", train_x=heldout[0][:2, :, :6])
    cases = {
        "take.bvh": "take.bvh: not a readable .npz file (File is not a zip file)",
        "lone.npy": "lone.npy: not a readable .npz file (File is not a zip file)",
        "cut.npz": "cut.npz: not a readable .npz file (",
        "narrow.npz": f"narrow.npz: 'train_x' (2, {heldout[0].shape[1]}, 6) is not [N, T, 63]",
        "absent.npz": "absent.npz: not a readable .npz file (No such file or directory)",
    }
    for name, message in cases.items():
        assert invariants.main([str(tmp_path / name)]) == 2, name
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (name, err)
