"""Running a command's main in-process, as the tests of one-line errors do."""


def one_line_error(main, argv, capsys):
    """Run a CLI's main in-process; returns (exit code, the one stderr line). argparse's exit counts as a return;
    a traceback, or more than one line of error (notes aside), fails the test."""
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("note:")]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return code, lines[0]


def fails_with(main, argv, capsys, needle):
    """The one stderr line of `main(argv)`, which must exit 2 and say `needle`."""
    code, line = one_line_error(main, argv, capsys)
    assert code == 2 and needle in line, line
    return line


def as_a_plain_user(argv: list[str]) -> list[str]:
    """`argv` run with a plain user's rights over files: as root, without the capabilities that let root read and
    write any file (util-linux's setpriv drops them), so that a file of mode 000 cannot be read, nor a folder of mode
    555 written in, as for any user."""
    import os
    import shutil

    import pytest

    if os.geteuid() != 0:
        return argv
    if not shutil.which("setpriv"):
        pytest.fail("setpriv (util-linux) is needed to run a command without root's rights over files")
    drop = "-dac_override,-dac_read_search"
    return ["setpriv", f"--bounding-set={drop}", f"--inh-caps={drop}", *argv]
