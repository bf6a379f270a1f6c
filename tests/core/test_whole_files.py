"""moglow_eval.core.whole_files: an output is written whole or not at all, and leaves nothing beside it."""

import os
import stat

import pytest

from moglow_eval.core import whole_files


def test_a_file_is_written_exactly_as_given(tmp_path):
    path = tmp_path / "table.csv"
    whole_files.write_whole(path, "a,b\r\nü,2\n")
    assert path.read_bytes() == "a,b\r\nü,2\n".encode()  # no newline translation, UTF-8
    whole_files.write_whole(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert os.listdir(tmp_path) == ["table.csv"]


def test_a_writer_that_fails_half_way_leaves_the_old_file_and_no_temporary_one(tmp_path):
    path = tmp_path / "stats.json"
    path.write_text("old")
    with pytest.raises(RuntimeError), whole_files.writing(path) as tmp:
        tmp.write_text("half of a new")
        raise RuntimeError("a full disk")
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["stats.json"]
    with pytest.raises(RuntimeError), whole_files.writing(tmp_path / "new.json") as tmp:
        tmp.write_text("half")
        raise RuntimeError("killed")
    assert os.listdir(tmp_path) == ["stats.json"]  # a file that did not exist does not appear


def test_the_temporary_file_is_hidden_beside_the_output_and_fresh_for_each_writer(tmp_path):
    path = tmp_path / "pairs.csv"
    with whole_files.writing(path) as a, whole_files.writing(path) as b:  # two writers at once
        assert a.parent == b.parent == tmp_path and a != b
        assert a.name.startswith(".pairs.csv.") and b.name.startswith(".pairs.csv.")
        a.write_text("a")
        b.write_text("b")
    assert path.read_text() == "a"  # the last to finish; neither wrote into the other's file
    with whole_files.writing(tmp_path / "dataset.npz", suffix=".npz") as tmp:
        assert tmp.suffix == ".npz"  # numpy's savez adds nothing to such a name
        tmp.write_bytes(b"npz")
    assert sorted(os.listdir(tmp_path)) == ["dataset.npz", "pairs.csv"]


def test_a_new_file_gets_the_permissions_of_any_new_file(tmp_path):
    old = os.umask(0o027)
    try:
        whole_files.write_whole(tmp_path / "report.html", "<p>")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "report.html").stat().st_mode) == 0o640  # not a temporary file's 0600
