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


def without_reading_rights(argv: list[str]) -> list[str]:
    """`argv` run as a user who cannot read what is not theirs to read: as root, with the capabilities that let root
    read any file dropped (util-linux's setpriv), so that a file of mode 000 is unreadable as it is to a user."""
    import os
    import shutil

    import pytest

    if os.geteuid() != 0:
        return argv
    if not shutil.which("setpriv"):
        pytest.fail("setpriv (util-linux) is needed to run a command without root's reading rights")
    drop = "-dac_override,-dac_read_search"
    return ["setpriv", f"--bounding-set={drop}", f"--inh-caps={drop}", *argv]
