"""Files a user names are read without running code in them (torch's weights-only reader, data.torch_files).

A checkpoint that pickles an object whose `__reduce__` opens (creates) a marker file stands in for a malicious
download: every command that reads a user's checkpoint must refuse it with one line and exit 2, and the marker
must not exist afterwards (loading it with torch's default pickle reader would create it).
"""

import numpy as np
import pytest
import torch

from generation import make_stimuli
from generation.data.torch_files import load_torch_file
from generation.metrics import fmd
from generation.sampling import pretrained, sample
from generation.training import train
from moglow_eval.core.cli import UserError

pytestmark = pytest.mark.usefixtures("torch_one_thread")


class _Payload:
    """Unpickling this calls open(marker, "w"): the file appears if the reader runs the file's code."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


@pytest.fixture
def evil(tmp_path):
    """(a checkpoint-shaped file with the payload in its weights, the marker's path)."""
    marker = tmp_path / "marker"
    path = tmp_path / "evil.pt"
    torch.save(dict(kind="mg", model_config={}, state=_Payload(marker), step=1, fps=20.0, window=80), path)
    return path, marker


def _refused(code, capsys, path, marker):
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert len(err) == 1 and err[0].startswith(f"error: {path}: holds Python objects"), err
    assert not marker.exists()


def test_sample_refuses_a_pickled_object(evil, small_dataset, tmp_path, capsys):
    path, marker = evil
    code = sample.main(["--checkpoint", str(path), "--data", str(small_dataset), "--out", str(tmp_path / "o")])
    _refused(code, capsys, path, marker)


def test_train_resume_refuses_a_pickled_object(evil, small_dataset, tmp_path, capsys):
    path, marker = evil
    out = tmp_path / "run"
    out.mkdir()
    path.rename(out / "resume.pt")
    argv = ["--model", "mg", "--config", "tiny", "--data", str(small_dataset), "--out", str(out), "--resume"]
    code = train.main([*argv, "--threads", "1", "--quiet"])
    _refused(code, capsys, out / "resume.pt", marker)


def test_make_stimuli_refuses_a_pickled_object(evil, tmp_path, capsys):
    path, marker = evil
    argv = ["--mg-checkpoint", str(path), "--fl-checkpoint", str(pretrained.CHECKPOINTS["fl"])]
    argv += ["--bad-checkpoint", str(pretrained.CHECKPOINTS["bad"]), "--out", str(tmp_path / "stimuli")]
    argv += ["--n-items", "2", "--n-catch", "1", "--n-training", "1", "--workers", "1", "--quiet"]
    code = make_stimuli.main(argv)
    _refused(code, capsys, path, marker)


def test_export_and_the_motion_encoder_refuse_a_pickled_object(evil, tmp_path):
    path, marker = evil
    with pytest.raises(UserError, match="holds Python objects beyond tensors and plain data"):
        pretrained.export_checkpoint(path, tmp_path / "out.pt")
    torch.save({"state": {}, "x_mean": _Payload(marker)}, tmp_path / "encoder.pt")
    with pytest.raises(UserError, match="encoder.pt: holds Python objects"):
        fmd.MotionEncoder.load(tmp_path / "encoder.pt")
    assert not marker.exists() and not (tmp_path / "out.pt").exists()


def test_a_resume_state_of_another_model_is_one_line(small_dataset, tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    torch.save({"state": {"weight": torch.zeros(2)}, "opt": {}, "step": 3}, out / "resume.pt")
    argv = ["--model", "fl", "--config", "tiny", "--data", str(small_dataset), "--out", str(out), "--resume"]
    assert train.main([*argv, "--threads", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {out / 'resume.pt'}: not a resume state of this run's model")


def test_a_file_that_is_no_checkpoint_is_one_line(tmp_path, capsys):
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint")
    with pytest.raises(UserError, match=r"junk.pt: not a readable torch file") as e:
        load_torch_file(junk)
    assert "\n" not in str(e.value)
    with pytest.raises(UserError, match=r"nothing.pt: no such file"):
        load_torch_file(tmp_path / "nothing.pt")


def test_shipped_encoder_holds_tensors_and_an_old_numpy_one_still_reads(tmp_path):
    """The shipped encoder loads weights-only; a file of the older format (the same values as numpy arrays)
    gives the same FMD, and an object array in that format is still refused."""
    state = torch.load(pretrained.MOTION_ENCODER, weights_only=True)
    assert torch.is_tensor(state["x_mean"]) and all(torch.is_tensor(m) for m in state["moments"][fmd.ALL])
    old = {**state, "x_mean": state["x_mean"].numpy(), "x_std": state["x_std"].numpy()}
    old["moments"] = {k: (m1.numpy(), m2.numpy()) for k, (m1, m2) in state["moments"].items()}
    torch.save(old, tmp_path / "old.pt")
    d = np.load(pretrained.HELDOUT)
    x, labels = d["test_x"][:24], d["test_labels"][:24]
    shipped, older = fmd.MotionEncoder.load(pretrained.MOTION_ENCODER), fmd.MotionEncoder.load(tmp_path / "old.pt")
    assert shipped.fmd(x, labels) == older.fmd(x, labels)
    marker = tmp_path / "marker"
    torch.save({**old, "x_mean": np.array([_Payload(marker)], dtype=object)}, tmp_path / "objects.pt")
    with pytest.raises(UserError, match="objects.pt: holds Python objects"):
        fmd.MotionEncoder.load(tmp_path / "objects.pt")
    assert not marker.exists()
