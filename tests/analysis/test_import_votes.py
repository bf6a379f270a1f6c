"""analysis.import_votes: the GENEA leaderboard's battle files (read in ../shared, never copied) into pairs.csv,
keeping the 5 levels and the reasons; bad files give one line and write nothing."""

import csv
import json
import os
import subprocess
import sys
import tracemalloc

import pytest
from helpers.paths import LEADERBOARD, ROOT

from analysis import import_votes as iv
from analysis import report
from analysis.designs import Options
from moglow_eval.core import votes

HEAD = "user,input_code,model_a,model_b,winner,is_strong,juiceOptions,juiceOtherReason\n"


def rows(path):
    return list(csv.DictReader(open(path, newline="", encoding="utf-8")))


@pytest.mark.full
def test_the_realism_votes_keep_levels_reasons_and_text(tmp_path):
    out = tmp_path / "pairs.csv"
    summary = iv.import_votes(LEADERBOARD / "battles_elo.csv", out)
    assert summary["design"] == "pairwise" and summary["n_votes"] == 500 and summary["n_raters"] == 20
    got, src = rows(out), rows(LEADERBOARD / "battles_elo.csv")
    assert len(got) == len(src) == 500
    prefs = [int(r["preference"]) for r in got]
    # the counts README.md gives: model_a 203, model_b 197, tie 100; strong/slight 179/221
    assert sum(p > 0 for p in prefs) == 203 and sum(p < 0 for p in prefs) == 197 and prefs.count(0) == 100
    assert sum(abs(p) == 2 for p in prefs) == 179 and sum(abs(p) == 1 for p in prefs) == 221
    for g, s in zip(got, src):
        assert g["condition_a"] == s["model_a"] and g["item"] == s["input_code"] and g["rater_id"] == s["user"]
        assert int(g["preference"]) == votes.battle_to_preference(s["winner"], s["is_strong"] or "False")
        ticked = [] if s["juiceOptions"].strip() in ("{}", "[]", "") else json.loads(s["juiceOptions"])
        assert (g["reasons"].split(";") if g["reasons"] else []) == list(dict.fromkeys(ticked))
        text = json.loads(s["juiceOtherReason"]) if s["juiceOtherReason"] else ""
        assert g["reason_text"] == text
    # the same clip gets the same id wherever it appears
    ids = {(r["item"], r["condition_a"]): r["clip_a"] for r in got}
    assert all(ids.get((r["item"], r["condition_b"]), r["clip_b"]) == r["clip_b"] for r in got)


@pytest.mark.full
def test_the_mismatch_votes_become_an_appropriateness_export(tmp_path):
    out = tmp_path / "pairs.csv"
    assert iv.import_votes(LEADERBOARD / "battles_mismatch.csv", out)["design"] == "appropriateness"
    got = rows(out)
    assert all(r["condition_a"] == r["condition_b"] and r["matched"] in "ab" for r in got)
    assert sum(r["matched"] == "b" for r in got) == 22  # README: the mismatched clip is on the left in 22 rows
    doc = report.build_report(out, tmp_path / "rep", Options(n_boot=50), progress=False, quiet=True)
    assert doc["design"] == "appropriateness" and sum(v["n"] for v in doc["mas"].values()) == 50


def write(tmp_path, body):
    path = tmp_path / "battles.csv"
    path.write_text(HEAD + body)
    return path


@pytest.mark.parametrize(
    "body, needle",
    [
        ("u1,i1,A,B,model_c,True,{},\n", "battles.csv:2: winner is 'model_c'"),
        ("u1,i1,A,B,model_a,maybe,{},\n", "battles.csv:2: is_strong is 'maybe'"),
        ('u1,i1,A,B,model_a,True,"[""a b""]",\n', "battles.csv:2: juiceOptions"),
        ("u1,i1,A,B,model_a,True,[oops,\n", "battles.csv:2: juiceOptions"),
        ("u1,i1,A,A,model_a,True,{},\n", "battles.csv:2: model A on both sides"),
        (",i1,A,B,model_a,True,{},\n", "battles.csv:2: empty user"),
        # a name with a terminal's escape, which would reach the report's console and page
        ("u1,i1,A\x1b[2J,B,model_a,True,{},\n", "battles.csv:2: model_a 'A\\x1b[2J' holds a control character"),
        ("u1,i1,A,A_Mismatched,model_a,True,{},\nu1,i2,A,B,tie,,{},\n", "battles.csv:3: A against B"),
        ("", "no votes"),
    ],
)
def test_bad_battle_files_are_one_line_and_write_nothing(tmp_path, capsys, body, needle):
    path = write(tmp_path, body)
    out = tmp_path / "pairs.csv"
    assert iv.main([str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1
    assert not out.exists() and sorted(tmp_path.iterdir()) == [path]  # nor a partial file beside it


@pytest.mark.parametrize("out", ["battles.csv", "."], ids=["the-input", "a-folder"])
def test_an_output_that_is_the_battle_file_or_a_folder_is_refused(tmp_path, capsys, out):
    path = write(tmp_path, "u1,i1,A,B,model_a,True,{},\n")
    before = path.read_bytes()
    assert iv.main([str(path), "--out", str(tmp_path / out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: --out") and len(err.splitlines()) == 1, err
    assert path.read_bytes() == before  # the votes are still there


def test_not_a_battle_file(tmp_path, capsys):
    path = tmp_path / "other.csv"
    path.write_text("a,b\n1,2\n")
    assert iv.main([str(path), "--out", str(tmp_path / "p.csv")]) == 2
    assert "not a battle file: no column user" in capsys.readouterr().err


def test_a_file_too_large_is_refused_before_reading(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(iv, "MAX_BYTES", 100)
    path = write(tmp_path, "u1,i1,A,B,model_a,True,{},\n" * 10)
    assert iv.main([str(path), "--out", str(tmp_path / "p.csv")]) == 2
    assert "larger than a battle file can be" in capsys.readouterr().err


def test_free_text_is_unquoted_and_a_hostile_text_stays_a_defused_text(tmp_path):
    body = (
        'u1,i1,A,B,model_a,True,"[""MotionSmoothness""]","""It\'s in the hands, <b>really</b>"""\n'
        'u2,i1,A,B,model_b,False,{},=HYPERLINK("x")\n'
    )
    out = tmp_path / "pairs.csv"
    iv.import_votes(write(tmp_path, body), out)
    got = rows(out)
    assert got[0]["reasons"] == "MotionSmoothness" and got[0]["reason_text"] == "It's in the hands, <b>really</b>"
    assert got[1]["reason_text"] == '\'=HYPERLINK("x")' and int(got[1]["preference"]) == -1
    doc = report.build_report(out, tmp_path / "rep", Options(n_boot=20), progress=False, quiet=True)
    assert doc["design"] == "pairwise"
    assert "<b>really</b>" not in (tmp_path / "rep" / "report.html").read_text()


# ---------------------------------------------------------------- hostile battle files (issue 55, failures 5-7)
def test_formula_cells_are_defused_as_the_exports_defuse_them(tmp_path):
    body = (
        '"=HYPERLINK(""http://x"",""y"")",@SUM(1),A,B,model_a,True,{},+1+1\n-2,\tcmd,A,B,model_b,True,{},"""=1+1"""\n'
    )
    out = tmp_path / "pairs.csv"
    iv.import_votes(write(tmp_path, body), out)
    got = rows(out)
    assert [(r["rater_id"], r["item"], r["reason_text"]) for r in got] == [
        ('\'=HYPERLINK("http://x","y")', "'@SUM(1)", "'+1+1"),
        ("'-2", "cmd", "'=1+1"),  # a cell is stripped of blanks first, as every reader strips it
    ]
    assert not any(v.startswith(("=", "+", "-", "@")) for r in got for k, v in r.items() if k != "preference")


@pytest.mark.parametrize("depth", [1500, 50_000])
def test_deep_nesting_is_one_line(tmp_path, capsys, depth):
    path = write(tmp_path, f'u1,i1,A,B,model_a,True,"{"[" * depth}{"]" * depth}",\n')
    assert iv.main([str(path), "--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "battles.csv:2:" in err
    assert ("nested deeper" if depth < iv.MAX_CELL else "a cell of") in err


def test_a_huge_line_is_one_line(tmp_path, capsys):
    path = tmp_path / "battles.csv"
    path.write_bytes(HEAD.encode() + b"u1,i1,A,B,model_a,True,{}," + b"x" * (3 << 20))
    assert iv.main([str(path), "--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "battles.csv:2: line longer than" in err and len(err.splitlines()) == 1


@pytest.mark.full  # a large file written and read: the full tier
def test_a_large_file_is_read_in_a_stream_and_stops_at_its_first_bad_line(tmp_path, capsys):
    path = tmp_path / "battles.csv"
    good = "u1,i1,A,B,model_a,True,{},\n"
    with open(path, "w") as fh:  # 25 MB: a good vote, then garbage rows
        fh.write(HEAD + good + ("garbage," * 8 + "\n") * 400_000)
    assert path.stat().st_size > 25e6
    tracemalloc.start()
    try:
        assert iv.main([str(path), "--out", str(tmp_path / "p.csv")]) == 2
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "battles.csv:3: 9 cells, the header has 8" in capsys.readouterr().err
    assert peak < 4e6, peak  # a few lines at a time, not the file

    # A large good file: memory stays flat as it is converted. 50,000 votes held at once would be several times the
    # bound (a row's dict alone is some hundreds of bytes); tracemalloc makes each one slow to read, so no more.
    with open(path, "w") as fh:
        fh.write(HEAD + "".join(f"u{i % 50},i{i % 40},A,B,model_a,True,{{}},\n" for i in range(50_000)))
    tracemalloc.start()
    try:
        assert iv.import_votes(path, tmp_path / "p.csv")["n_votes"] == 50_000
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4e6, peak


def run_cli(path, tmp_path):
    """The importer as a process, with a deadline: a file it would read without end fails the test, not the suite."""
    try:
        r = subprocess.run(
            [sys.executable, "-m", "analysis.import_votes", str(path), "--out", str(tmp_path / "p.csv")],
            capture_output=True,
            text=True,
            timeout=60,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            cwd=ROOT,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{path}: still reading after 60 s")
    return r


def test_anything_but_a_regular_file_is_refused(tmp_path):
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)  # no writer: opening it to read would wait for ever
    for path in ("/dev/zero", fifo, tmp_path):
        r = run_cli(path, tmp_path)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, (path, r.stderr[-500:])
        assert "not a regular battle file" in r.stderr
    assert not (tmp_path / "p.csv").exists()
