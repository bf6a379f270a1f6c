"""moglow_eval.core.cli: the checks of an output path (--out) that every command makes before its work, and of a flag
given an empty value."""

import argparse

import pytest

from moglow_eval.core.cli import UserError, file_to_write, folder_to_write, refuse_empty


def test_a_folder_to_write_is_refused_when_empty_or_a_file_is_in_its_way(tmp_path):
    (tmp_path / "afile").write_text("x")
    assert folder_to_write(tmp_path / "new" / "deeper", "the folder") == tmp_path / "new" / "deeper"
    assert folder_to_write(str(tmp_path), "the folder") == tmp_path  # an existing folder is the command's to judge
    cases = {
        "": "--out: empty; give the folder",  # Path("") would be the current folder
        " ": "--out: empty; give the folder",
        str(tmp_path / "afile"): f"--out {tmp_path / 'afile'}: a file, not a folder",
        str(tmp_path / "afile" / "sub"): f"--out {tmp_path / 'afile' / 'sub'}: {tmp_path / 'afile'} is a file",
    }
    for out, message in cases.items():
        with pytest.raises(UserError) as e:
            folder_to_write(out, "the folder")
        assert str(e.value) == message
    assert (tmp_path / "afile").read_text() == "x" and not (tmp_path / "new").exists()


def test_a_file_to_write_is_refused_when_empty_a_folder_or_under_a_file(tmp_path):
    (tmp_path / "afile").write_text("x")
    assert file_to_write(tmp_path / "new" / "data.npz", "the file") == tmp_path / "new" / "data.npz"
    assert file_to_write(tmp_path / "afile", "the file") == tmp_path / "afile"  # replaced whole, as asked
    cases = {
        "": "--data-out: empty; give the file",
        str(tmp_path): f"--data-out {tmp_path}: a folder; give the file",
        str(tmp_path / "afile" / "x.npz"): f"--data-out {tmp_path / 'afile' / 'x.npz'}: {tmp_path / 'afile'} is a file",
    }
    for out, message in cases.items():
        with pytest.raises(UserError) as e:
            file_to_write(out, "the file", flag="--data-out")
        assert str(e.value) == message


def test_a_flag_given_an_empty_value_is_named_not_read_as_left_out():
    args = argparse.Namespace(study=" ", out="", seed=0, data=None, mg_checkpoint="")
    with pytest.raises(UserError, match="^--study: empty; give a value, or leave the flag out$"):
        refuse_empty(args, but=("out",))
    args.study = "study.toml"
    with pytest.raises(UserError, match="^--mg-checkpoint: empty"):
        refuse_empty(args, but=("out",))
    args.mg_checkpoint = "mg.pt"
    refuse_empty(args, but=("out",))  # None (left out), numbers and the command's own "out" pass
