"""Every bad ratings.csv / metrics.csv gives one clear line naming the file line or column, exit 2, no traceback."""

import subprocess
import sys

import pytest
from helpers.paths import ROOT, TEST_DATA

from analysis.data.load import AnalysisError, load_metrics, load_ratings
from analysis.report import main

HEADER = "rater_id,clip_id,condition,rating,role\n"
GOOD = "r1,a1,NAT,4,test\nr1,b1,MG,3,test\nr1,x1,BAD,1,catch\nr2,a1,NAT,5,test\nr2,b1,MG,2,test\nr2,x1,BAD,2,catch\n"

# (name, file text, regex the one-line message must match)
BAD = [
    ("empty_file", "", r"file is empty"),
    ("whitespace_only", "\n  \n", r"file is empty"),
    ("header_only", HEADER, r"no ratings \(header only\)"),
    ("missing_rating_column", "rater_id,clip_id,condition\nr1,a1,NAT\n", r"missing required column rating"),
    ("missing_two_columns", "rater_id,rating\nr1,3\n", r"missing required columns clip_id, condition"),
    ("non_integer_text", HEADER + GOOD + "r3,a1,NAT,good,test\n", r":8: rating 'good' is not an integer 1-5"),
    ("non_integer_decimal", HEADER + "r3,a1,NAT,3.5,test\n" + GOOD, r":2: rating '3.5' is not an integer"),
    ("integer_written_as_float", HEADER + GOOD + "r3,a1,NAT,4.0,test\n", r":8: rating '4.0' is not an integer"),
    ("empty_rating", HEADER + GOOD + "r3,a1,NAT,,test\n", r":8: rating '' is not an integer"),
    ("rating_zero", HEADER + GOOD + "r3,a1,NAT,0,test\n", r":8: rating 0 is out of range 1-5"),
    ("rating_six", HEADER + "r3,a1,NAT,6,test\n" + GOOD, r":2: rating 6 is out of range 1-5"),
    ("negative_rating", HEADER + GOOD + "r3,a1,NAT,-2,test\n", r":8: rating -2 is out of range"),
    ("unknown_role", HEADER + GOOD + "r3,a1,NAT,3,training\n", r":8: unknown role 'training'"),
    ("empty_role", HEADER + GOOD + "r3,a1,NAT,3,\n", r":8: unknown role ''"),
    ("empty_rater", HEADER + GOOD + ",a1,NAT,3,test\n", r":8: empty rater_id"),
    ("empty_clip", HEADER + GOOD + "r3,,NAT,3,test\n", r":8: empty clip_id"),
    (
        "duplicate_pair",
        HEADER + GOOD + "r1,b1,MG,5,test\n",
        r":8: duplicate rating of clip b1 by rater r1 \(first at line 3\)",
    ),
    (
        "clip_in_two_conditions",
        HEADER + GOOD + "r3,a1,FL,3,test\n",
        r":8: clip a1 has condition 'FL' but 'NAT' at line 2",
    ),
    ("clip_in_two_roles", HEADER + GOOD + "r3,a1,NAT,3,catch\n", r":8: clip a1 has role 'catch' but 'test'"),
    ("only_catch_rows", HEADER + "r1,x1,BAD,1,catch\n", r"no test ratings"),
    ("ragged_row", HEADER + GOOD + "r3,a1,NAT,3,test,extra\n", r"malformed CSV: .*line 8"),
    ("not_utf8", None, r"not UTF-8"),
]


def _write(tmp_path, name, text):
    path = tmp_path / f"{name}.csv"
    if text is None:
        path.write_bytes((HEADER + "r\xe9,a1,NAT,3,test\n").encode("latin-1"))
    else:
        path.write_text(text)
    return path


@pytest.mark.parametrize("name,text,pattern", BAD, ids=[b[0] for b in BAD])
def test_bad_ratings_file_is_one_line_error(tmp_path, name, text, pattern):
    path = _write(tmp_path, name, text)
    with pytest.raises(AnalysisError, match=pattern) as info:
        load_ratings(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path))


@pytest.mark.parametrize("name,text,pattern", BAD[:8], ids=[b[0] for b in BAD[:8]])
def test_cli_exit_2_with_error_line(tmp_path, capsys, name, text, pattern):
    path = _write(tmp_path, name, text)
    assert main([str(path), "--out", str(tmp_path / "rep"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and len(err.splitlines()) == 1
    assert not (tmp_path / "rep" / "stats.json").exists()


def test_missing_file(tmp_path, capsys):
    assert main([str(tmp_path / "nope.csv"), "--quiet"]) == 2
    assert "no such file" in capsys.readouterr().err


def test_cli_as_module_never_prints_a_traceback(tmp_path):
    path = _write(tmp_path, "bad", HEADER + GOOD + "r3,a1,NAT,9,test\n")
    proc = subprocess.run(
        [sys.executable, "-m", "analysis.report", str(path), "--quiet"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"error: {path}:8: rating 9 is out of range 1-5"
    assert "Traceback" not in proc.stderr


def test_good_file_loads_with_line_numbers_and_roles(tmp_path):
    path = _write(tmp_path, "good", HEADER + GOOD + "\n")  # a trailing blank line is layout, not data
    df = load_ratings(path)
    assert len(df) == 6 and list(df.index) == [2, 3, 4, 5, 6, 7]
    assert df["rating"].tolist() == [4, 3, 1, 5, 2, 2]
    assert (df["role"] == "catch").sum() == 2


def test_without_role_column_bad_condition_is_catch(tmp_path):
    path = tmp_path / "norole.csv"
    path.write_text("rater_id,clip_id,condition,rating\nr1,a,NAT,4\nr1,x,BAD,3\n")
    assert load_ratings(path)["role"].tolist() == ["test", "catch"]


def test_only_one_condition_left_is_an_error(tmp_path, capsys):
    path = _write(tmp_path, "onecond", HEADER + "r1,a1,NAT,4,test\nr2,a1,NAT,3,test\n")
    assert main([str(path), "--out", str(tmp_path / "rep"), "--quiet"]) == 2
    assert "comparisons need at least 2" in capsys.readouterr().err


def test_every_rater_excluded_is_an_error(tmp_path, capsys):
    path = _write(tmp_path, "allbad", HEADER + GOOD.replace("BAD,1,", "BAD,4,").replace("BAD,2,", "BAD,5,"))
    assert main([str(path), "--out", str(tmp_path / "rep"), "--quiet"]) == 2
    assert "every rater failed the catch trials" in capsys.readouterr().err


@pytest.mark.parametrize("args", [["--threshold", "0"], ["--threshold", "x"], ["--n-boot", "3"], ["--alpha", "2"]])
def test_bad_options_exit_2(tmp_path, capsys, args):
    path = _write(tmp_path, "good", HEADER + GOOD)
    with pytest.raises(SystemExit) as info:
        main([str(path), "--quiet", *args])
    assert info.value.code == 2


@pytest.mark.parametrize("args", [["--reference", "MG"], ["--indifference", "25"]])
def test_a_flag_the_design_does_not_read_is_refused(tmp_path, capsys, args):
    """--reference and --indifference steer the pairwise analysis alone: on another design's export they were
    dropped without a word (the report read as if the anchor had been set)."""
    path = _write(tmp_path, "acr", HEADER + GOOD)
    assert main([str(path), "--quiet", "--out", str(tmp_path / "rep"), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"error: {args[0]}: {path} holds acr answers; {args[0]} is for pairwise exports only", err
    assert not (tmp_path / "rep").exists()


METRICS_HEADER = "clip_id,condition,role,item,foot_skating,jerk\n"


@pytest.mark.parametrize(
    "text,pattern",
    [
        ("", r"file is empty"),
        ("condition,jerk\nNAT,1\n", r"missing required column clip_id"),
        (METRICS_HEADER, r"no rows"),
        (METRICS_HEADER + "a1,NAT,test,1,0.1,2\na1,NAT,test,1,0.2,3\n", r":3: duplicate clip_id a1"),
        (METRICS_HEADER + "a1,NAT,test,1,fast,2\n", r":2: foot_skating 'fast' is not a number"),
        (METRICS_HEADER + "a1,NAT,test,1,0.1,2\nb1,MG,test,1,inf,2\n", r":3: foot_skating 'inf' is not a finite"),
        (METRICS_HEADER + "a1,NAT,test,1,0.1,-1e999\n", r":2: jerk '-1e999' is not a finite number"),
        ("clip_id,condition,role,item\na1,NAT,test,1\n", r"no metric columns"),
    ],
)
def test_bad_metrics_file(tmp_path, text, pattern):
    path = tmp_path / "metrics.csv"
    path.write_text(text)
    with pytest.raises(AnalysisError, match=pattern):
        load_metrics(path)


def test_metrics_empty_cell_is_missing_not_an_error(tmp_path):
    path = tmp_path / "metrics.csv"
    path.write_text(METRICS_HEADER + "a1,NAT,test,1,,2\nb1,MG,test,1,0.3,4\n")
    m = load_metrics(path)
    assert m.loc["b1", "foot_skating"] == 0.3 and m["foot_skating"].isna().sum() == 1


# ---------------------------------------------------------------------------------------------- fuzzing (issue 11)
REAL = (TEST_DATA / "analysis" / "ratings_small.csv").read_bytes()
REAL_LINES = REAL.split(b"\n")[:60]  # the header and enough rows for every kind of line; keeps each example fast


def _corrupt(draw):
    """A real ratings file with a few random edits: bytes replaced, inserted or deleted, lines dropped,
    duplicated or swapped, cells emptied, or the file cut short."""
    from hypothesis import strategies as st

    lines = list(REAL_LINES)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["byte", "insert", "delete", "drop_line", "dup_line", "swap", "cell", "cut"]))
        i = draw(st.integers(0, len(lines) - 1))
        line = lines[i]
        if kind == "byte" and line:
            j = draw(st.integers(0, len(line) - 1))
            lines[i] = line[:j] + bytes([draw(st.integers(0, 255))]) + line[j + 1 :]
        elif kind == "insert":
            j = draw(st.integers(0, len(line)))
            junk = draw(
                st.sampled_from(
                    [
                        b",",
                        b'"',
                        b"\r",
                        b"\x00",
                        b"\xff\xfe",
                        b"NaN",
                        b"-",
                        b"9" * 30,
                        b"\n",
                        "é".encode(),
                        b" ",
                        b"1e3",
                        b"inf",
                    ]
                )
            )
            lines[i] = line[:j] + junk + line[j:]
        elif kind == "delete" and line:
            j = draw(st.integers(0, len(line) - 1))
            lines[i] = line[:j] + line[j + draw(st.integers(1, 5)) :]
        elif kind == "drop_line" and len(lines) > 1:
            del lines[i]
        elif kind == "dup_line":
            lines.insert(i, line)
        elif kind == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "cell":
            cells = line.split(b",")
            cells[draw(st.integers(0, len(cells) - 1))] = draw(
                st.sampled_from([b"", b"x", b"0", b"7", b"3.0", b"catch", b"BAD", b"NAT"])
            )
            lines[i] = b",".join(cells)
        elif kind == "cut":
            text = b"\n".join(lines)
            return text[: draw(st.integers(0, len(text)))]
    return b"\n".join(lines)


def test_fuzzed_ratings_file_is_a_table_or_one_line_error(tmp_path_factory):
    """Property: any corruption of a real ratings.csv gives a valid table or the one-line AnalysisError --
    never another exception, never a table that breaks the contract."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    folder = tmp_path_factory.mktemp("fuzz")

    @settings(
        max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow], database=None, derandomize=True
    )
    @given(st.data())
    def check(data):
        path = folder / "ratings.csv"
        path.write_bytes(_corrupt(data.draw))
        try:
            df = load_ratings(path)
        except AnalysisError as exc:
            msg = str(exc)
            assert msg.startswith(str(path)) and "\n" not in msg and "\r" not in msg, msg
            return
        assert len(df) > 0 and (df["role"] == "test").any()
        assert df["rating"].between(1, 5).all() and set(df["role"]) <= {"test", "catch"}
        for col in ("rater_id", "clip_id", "condition"):
            assert (df[col].astype(str).str.strip() != "").all()
        assert not df.duplicated(["rater_id", "clip_id"]).any()
        assert (df.groupby("clip_id", observed=True)["condition"].nunique() == 1).all()

    check()
