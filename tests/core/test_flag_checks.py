"""moglow_eval.core.cli: the checks of an output path (--out) that every command makes before its work, and of a flag
given an empty value."""

from pathlib import Path

import pytest

from moglow_eval.core.cli import ArgumentParser, UserError, file_to_write, folder_to_write


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


def _parser():
    """A command with a subcommand, as rating_app's: flags, a required flag, a path-typed flag, arguments."""
    ap = ArgumentParser(prog="python -m tool")
    ap.add_argument("--study", default=None)
    ap.add_argument("--out", type=Path, default=Path("set"))
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("backup")
    b.add_argument("db")
    b.add_argument("--out", required=True, type=Path)
    b.add_argument("--only", nargs="*", default=[])
    return ap


def test_a_flag_or_argument_given_an_empty_value_is_refused_by_every_commands_parser(capsys):
    """`--study "$STUDY"` with the variable unset built the built-in study in place of the user's; `backup --out ""`
    wrote into the current folder, as Path("") is "."; one rule in the parser every command uses."""
    ap = _parser()
    cases = {
        ("--study", "", "backup", "d", "--out", "f"): "argument --study: empty; give a value, or leave the flag out",
        ("--out", " ", "backup", "d", "--out", "f"): "argument --out: empty; give a value, or leave the flag out",
        ("backup", "d", "--out", ""): "python -m tool backup: argument --out: empty; give a value (see --help)",
        ("backup", "", "--out", "f"): "python -m tool backup: argument db: empty; give a value (see --help)",
        ("backup", "d", "--out", "f", "--only", "a", ""): "argument --only: empty; give a value, or leave",
    }
    for argv, says in cases.items():
        with pytest.raises(SystemExit) as e:
            ap.parse_args(list(argv))
        err = capsys.readouterr().err
        assert e.value.code == 2 and says in err and len(err.splitlines()) == 1, (argv, err)
    args = ap.parse_args(["--study", "s.toml", "backup", "-", "--out", "f", "--only", "a"])  # "-" is a value
    assert (args.study, args.db, args.out, args.only) == ("s.toml", "-", Path("f"), ["a"])
    assert ap.parse_args(["backup", "d", "--out", "f"]).study is None  # a flag left out keeps its default
