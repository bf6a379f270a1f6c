"""Every CSV, JSON or TOML file a command reads from a user is read as hostile (issue 55 item 5,
moglow_eval.core.user_files): only a regular file, a size cap, a line and cell cap, shallow nesting, one line and
exit code 2 for anything else, never a traceback or a read without end."""

import os
import subprocess
import sys

import pytest
from helpers.cli import fails_with
from helpers.memory import run_under_address_cap
from helpers.paths import ROOT

from analysis import report
from moglow_eval.core import user_files
from moglow_eval.core.cli import UserError
from rating_app.store.config import load_study_file
from rating_app.store.manifest import AppError, load_manifest


def run(module, *args, timeout=60):
    """A command as a process, with a deadline: a file it would read without end fails the test, not the suite."""
    try:
        return subprocess.run(
            [sys.executable, "-m", module, *map(str, args)],
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            cwd=ROOT,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{module} {args}: still reading after {timeout} s")


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "fifo.csv"
    os.mkfifo(path)  # no writer: opening it to read would wait for ever
    return path


def test_only_a_regular_file_is_read(tmp_path, fifo):
    for path in ("/dev/zero", fifo, tmp_path):
        with pytest.raises(UserError, match="not a regular file"):
            with user_files.open_regular(path, 100):
                pass
    (tmp_path / "big").write_bytes(b"x" * 101)
    with pytest.raises(UserError, match=r"big: 101 bytes is larger than a file can be \(100 bytes\)"):
        with user_files.open_regular(tmp_path / "big", 100):
            pass
    with pytest.raises(UserError, match="none: no such file"):
        with user_files.open_regular(tmp_path / "none", 100):
            pass


@pytest.mark.parametrize(
    "body, needle",
    [
        (b"a,b\n1," + b"x" * 70_000 + b"\n", "t.csv:2: a cell of 70000 characters"),
        (b"a,b\n1,2\n3," + b"y" * (2 << 20), "t.csv:3: line longer than"),
        (b"a,b\n1,\xff\n", "t.csv:2: not UTF-8 text"),
        (b"a,b\n1,2,3\n", "t.csv:2: 3 cells, the header has 2"),
        (b"", "t.csv: empty"),
    ],
)
def test_csv_rows_stop_at_the_first_bad_line(tmp_path, body, needle):
    path = tmp_path / "t.csv"
    path.write_bytes(body)
    with pytest.raises(UserError, match=needle):
        with user_files.csv_rows(path, 10 << 20) as (_, rows):
            list(rows)


def test_csv_rows_strip_every_cell_once_and_skip_blank_lines(tmp_path):
    path = tmp_path / "t.csv"
    path.write_bytes(b"\xef\xbb\xbf a , b \n x ,\n\n y , z \n")
    with user_files.csv_rows(path, 1000) as (header, rows):
        assert header == ["a", "b"] and list(rows) == [(2, {"a": "x", "b": ""}), (4, {"a": "y", "b": "z"})]


def test_json_nesting_and_formula_cells():
    assert user_files.json_value('["a", {"b": "[[[["}]', "w") == ["a", {"b": "[[[["}]
    with pytest.raises(UserError, match="w: JSON nested deeper than 8 levels"):
        user_files.json_value("[" * 5000 + "]" * 5000, "w")
    with pytest.raises(UserError, match="w: not JSON"):
        user_files.json_value("[oops", "w")
    assert [user_files.defuse(v) for v in ("=1", "+1", "-1", "@A", "\tx", "ok", 3)] == [
        "'=1",
        "'+1",
        "'-1",
        "'@A",
        "'\tx",
        "ok",
        3,
    ]


@pytest.mark.full  # the report as a process: the full tier
def test_the_report_refuses_what_is_not_a_regular_file(tmp_path, fifo):
    for path in ("/dev/zero", fifo):
        r = run("analysis.report", path, "--out", tmp_path / "rep", "--quiet")
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and "not a regular file" in r.stderr, r.stderr[-400:]


def test_deep_study_and_config_files_are_one_line(tmp_path, capsys):
    deep = tmp_path / "deep.toml"
    deep.write_text("reference = " + "[" * 3000 + "]" * 3000 + "\n")
    with pytest.raises(AppError, match="deep.toml: not a TOML file: nested too deep"):
        load_study_file(deep)
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("rater_id,item,clip_a,clip_b,condition_a,condition_b,preference,role\n")
    fails_with(report.main, [str(pairs), "--study", str(deep), "--out", str(tmp_path / "r")], capsys, "nested too deep")


def test_a_manifest_that_is_not_a_regular_file_is_one_line(tmp_path, fifo):
    with pytest.raises(AppError, match="not a regular manifest"):
        load_manifest(fifo)


def test_a_small_file_under_a_large_cap_is_read_without_reserving_the_cap(tmp_path):
    """A few bytes of JSON under a cap of 256 MB (the board's for a report's stats.json): one read of the cap asked the
    allocator for all of it, which a host that does not overcommit memory refuses (here an address-space cap 128 MB
    above the process's imports, in a process of its own); it reads in chunks."""
    path = tmp_path / "stats.json"
    path.write_text('{"design": "acr"}')
    r = run_under_address_cap(
        "import sys\nfrom moglow_eval.core import user_files", "print(user_files.read_json(sys.argv[1], 256 << 20))",
        128 << 20, path,
    )  # fmt: skip
    assert r.returncode == 0 and r.stdout.strip() == "{'design': 'acr'}", r.stderr[-2000:]
