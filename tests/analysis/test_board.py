"""The board (issue 64, part 3): the results of reports published as a static site, `python -m analysis.board`.

One small study (three systems, four items, real MP4s) is answered in every design's export and reported; the boards
are built from those reports. The tables must be stats.json's numbers; a challenge shows nothing of any system before
it publishes and publishes once; a leaderboard keeps every release byte for byte; bad input is one line and exit 2,
and an interrupted build leaves the board as it was. In chromium, at a phone's width, the pages fit, the system
pages play their videos, and nothing is fetched from elsewhere."""

import csv
import hashlib
import html.parser
import json
import os
import re
from pathlib import Path

import pytest
from helpers import board_reports
from helpers.fake_stimuli import write_fake_stimuli
from helpers.paths import ROOT

from analysis.board import TaskSpec, build_board, main
from analysis.board import release as release_module
from analysis.designs.base import ranked
from analysis.page.methods import tool_version
from moglow_eval.core import study

SYSTEMS = ("NAT", "SysAlpha", "SysBravo")
QUALITY = {"NAT": 4.4, "SysAlpha": 3.2, "SysBravo": 1.6, study.CATCH: 1.0}


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """A folder with stimuli/ (its manifest and videos), each design's export DESIGN.csv beside it, and its report
    report_DESIGN/, as `make_stimuli --out stimuli/`, the app's export and `analysis.report` leave them."""
    root = tmp_path_factory.mktemp("board_study")
    manifest = write_fake_stimuli(
        root / "stimuli", n_items=4, conditions=SYSTEMS, catch_nat=True, mismatched=True, metrics=False, n_training=0
    )
    for design in study.DESIGNS:
        export = board_reports.export(design, manifest, root / f"{design}.csv", QUALITY)
        board_reports.report(export, root / f"report_{design}")
    return root


def specs(root, designs):
    return [TaskSpec(d, root / f"report_{d}") for d in designs]


@pytest.fixture(scope="module")
def every_design(reports, tmp_path_factory):
    """A leaderboard of one release with a task per design."""
    out = tmp_path_factory.mktemp("every_design") / "board"
    build_board(specs(reports, study.DESIGNS), out, mode="leaderboard", date="2026-12-01")
    return out


def files_of(folder) -> dict[str, bytes]:
    """{path relative to `folder`: bytes} of every file under it, hidden ones too."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


def run(argv, capsys):
    """(exit code, stderr) of `python -m analysis.board ARGV`, run in this process."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # argparse's one line
        code = e.code
    return code, capsys.readouterr().err


# ------------------------------------------------------------------------------------------- the tables' numbers
def expected(doc) -> dict:
    """{system: (score, low, high, n)} as CONTRACTS §7-8 name them in each design's stats.json."""
    design = doc.get("design", "acr")
    if design == "acr":
        s = doc["condition_summary"]
        return {c: (m, s[c]["boot_low"], s[c]["boot_high"], doc["condition_counts"][c])
                for c, m in doc["condition_means"].items()}  # fmt: skip
    if design == "parallel":
        s = doc["condition_summary"]
        return {c: (m, s[c]["mean_low"], s[c]["mean_high"], doc["condition_counts"][c])
                for c, m in doc["condition_means"].items()}  # fmt: skip
    if design == "pairwise":
        votes = {c: sum(p["n"] for p in doc["pairwise"] if c in (p["condition_a"], p["condition_b"])) for c in SYSTEMS}
        return {r["condition"]: (r["elo"], r["elo_low"], r["elo_high"], votes[r["condition"]]) for r in doc["ranking"]}
    return {c: (m["mas"], m["ci_low"], m["ci_high"], m["n"]) for c, m in doc["mas"].items()}


class Cells(html.parser.HTMLParser):
    """The text of every table cell of a page, row by row."""

    def __init__(self):
        super().__init__()
        self.rows, self.cell = [], None

    def handle_starttag(self, tag, attrs):
        if tag == "tr":
            self.rows.append([])
        elif tag == "td":
            self.cell = ""

    def handle_endtag(self, tag):
        if tag == "td":
            self.rows[-1].append(self.cell)
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data


def cells(path) -> list[list[str]]:
    parser = Cells()
    parser.feed(Path(path).read_text(encoding="utf-8"))
    return [r for r in parser.rows if r]


@pytest.mark.parametrize("design", study.DESIGNS)
def test_the_tables_are_the_reports_numbers(design, reports, every_design):
    doc = json.loads((reports / f"report_{design}" / "stats.json").read_text())
    want = expected(doc)
    rel = every_design / "releases" / "1"
    table = json.loads((rel / "data" / f"{design}.json").read_text())
    assert table["design"] == design and len(table["systems"]) == len(SYSTEMS)
    assert {r["system"]: (r["score"], r["low"], r["high"], r["n"]) for r in table["systems"]} == want
    scores = [r["score"] for r in table["systems"]]
    assert scores == sorted(scores, reverse=True)  # best first
    # the CSV beside it: the same rows, the same numbers to the last digit
    with open(rel / "data" / f"{design}.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["system"], float(r["score"]), float(r["low"]), float(r["high"]), int(r["n"])) for r in rows] == [
        (r["system"], r["score"], r["low"], r["high"], r["n"]) for r in table["systems"]
    ]
    assert [(int(r["rank_low"]), int(r["rank_high"]), int(r["group"])) for r in rows] == [
        (r["rank_low"], r["rank_high"], r["group"]) for r in table["systems"]
    ]
    # the task's page shows them rounded, the rank interval, the group and the count
    places = 0 if max(abs(s) for s in scores) >= 100 else 1 if max(abs(s) for s in scores) >= 10 else 2
    shown = cells(rel / "tasks" / f"{design}.html")[: len(SYSTEMS)]
    for cell, r in zip(shown, table["systems"]):
        rank = str(r["rank_low"]) if r["rank_low"] == r["rank_high"] else f"{r['rank_low']}–{r['rank_high']}"
        score, low, high = (f"{r[k]:.{places}f}" for k in ("score", "low", "high"))
        assert cell == [rank, r["system"], score, f"[{low}, {high}]", str(r["group"]), str(r["n"])]
    # the board's own board.json holds the newest release's tables
    top = json.loads((every_design / "board.json").read_text())
    assert next(t for t in top["tasks"] if t["task"] == design)["systems"] == table["systems"]
    assert next(t for t in top["tasks"] if t["task"] == design)["methods"] == doc["methods"]


def test_the_ranks_follow_each_designs_test(reports, every_design):
    """pairwise: the report's bootstrap rank intervals and groups; acr: every pair told apart by Tukey's HSD here,
    so one rank each, in the order of the means; the mean-score designs: ordered only where intervals are apart."""
    rel = every_design / "releases" / "1" / "data"
    doc = json.loads((reports / "report_pairwise" / "stats.json").read_text())
    table = json.loads((rel / "pairwise.json").read_text())["systems"]
    assert [(r["system"], r["rank_low"], r["rank_high"], r["group"]) for r in table] == [
        (r["condition"], r["rank_low"], r["rank_high"], r["group"]) for r in doc["ranking"]
    ]
    acr = json.loads((reports / "report_acr" / "stats.json").read_text())
    assert all(t["reject"] for t in acr["tukey"])
    table = json.loads((rel / "acr.json").read_text())["systems"]
    assert [(r["system"], r["rank_low"], r["rank_high"], r["group"]) for r in table] == [
        ("NAT", 1, 1, 1), ("SysAlpha", 2, 2, 2), ("SysBravo", 3, 3, 3)
    ]  # fmt: skip
    table = json.loads((rel / "appropriateness.json").read_text())["systems"]
    for a in table:
        above = sum(b["low"] > a["high"] for b in table)
        below = sum(a["low"] > b["high"] for b in table)
        assert (a["rank_low"], a["rank_high"]) == (1 + above, len(table) - below)


def test_rank_intervals_and_groups_from_a_designs_decisions():
    rows = [{"system": s, "score": v, "low": None, "high": None, "n": 1} for s, v in
            (("C", 1.0), ("A", 3.0), ("D", 0.9), ("B", 2.5), ("E", None))]  # fmt: skip
    out = ranked(rows, {("A", "C"), ("A", "D"), ("B", "D")})
    # best score first, no score last; at best 1 + those decided above, at worst 5 - those decided below
    assert [(r["system"], r["rank_low"], r["rank_high"]) for r in out] == [
        ("A", 1, 3), ("B", 1, 4), ("C", 2, 5), ("D", 3, 5), ("E", 1, 5)
    ]  # fmt: skip
    assert {r["group"] for r in out} == {1}  # every interval overlaps the next: no order the data support
    chain = {(a, b) for a in "ABCD" for b in "ABCD" if a < b}
    out = ranked([r for r in rows if r["system"] != "E"], chain)
    assert [(r["system"], r["rank_low"], r["rank_high"], r["group"]) for r in out] == [
        ("A", 1, 1, 1), ("B", 2, 2, 2), ("C", 3, 3, 3), ("D", 4, 4, 4)
    ]  # fmt: skip


def test_the_data_release_is_the_export_the_manifest_and_the_report(reports, every_design):
    """Each task's export row for row, less the raters' crowd-platform ids; the manifest byte for byte; the report's
    stats.json less the organiser's path; every file with its size and SHA-256 on the Data page and in release.json."""
    rel = every_design / "releases" / "1"
    with open(reports / "acr.csv", newline="") as fh:
        given = list(csv.DictReader(fh))
    with open(rel / "data" / "acr" / "acr.csv", newline="") as fh:
        published = list(csv.DictReader(fh))
    assert "external_id" in given[0] and "external_id" not in published[0]
    assert published == [{k: v for k, v in r.items() if k != "external_id"} for r in given]
    assert not [name for name, data in files_of(every_design).items() if b"PID1" in data]
    assert (rel / "data" / "acr" / "manifest.csv").read_bytes() == (reports / "stimuli" / "manifest.csv").read_bytes()
    stats = json.loads((rel / "data" / "pairwise" / "stats.json").read_text())
    assert stats == {**json.loads((reports / "report_pairwise" / "stats.json").read_text()), "input": "pairwise.csv"}
    release = json.loads((rel / "release.json").read_text())
    data_page = (rel / "data.html").read_text()
    for task in release["tasks"]:
        assert [f["path"].rsplit("/", 1)[-1] for f in task["files"]] == [
            f"{task['task']}.csv", f"{task['task']}.json", f"{task['task']}.csv", "manifest.csv", "stats.json",
            "methods.txt",
        ]  # fmt: skip
        for f in task["files"]:
            data = (rel / f["path"]).read_bytes()
            assert (len(data), hashlib.sha256(data).hexdigest()) == (f["bytes"], f["sha256"])
            assert f'href="{f["path"]}"' in data_page and f["sha256"][:16] in data_page


# ------------------------------------------------------------------------------------------- the two uses
def test_a_challenge_shows_no_system_before_it_publishes_and_publishes_once(reports, tmp_path, capsys):
    out = tmp_path / "challenge"
    tasks = ["--task", f"realism={reports / 'report_acr'}", "--task", f"speech={reports / 'report_appropriateness'}"]
    assert run([*tasks, "--out", out, "--date", "2026-12-01", "--quiet"], capsys) == (0, "")
    site = files_of(out)
    assert set(site) == {"board.json", "index.html"}  # no data, no video, no page of a system
    for name, data in site.items():
        for system in SYSTEMS:
            assert system.encode() not in data, f"{name} names {system} before the board publishes"
    page = site["index.html"].decode()
    assert "realism" in page and "speech" in page and "2026-12-01" in page and tool_version() in page
    assert "five-point scale" in page and "not published" in page  # how each task is evaluated, and that it is not
    assert json.loads(site["board.json"])["published"] is False

    assert run([*tasks, "--out", out, "--date", "2026-12-02", "--publish"], capsys) == (0, "")
    top = json.loads((out / "board.json").read_text())
    assert top["published"] is True and top["release"] == 1 and top["date"] == "2026-12-02"
    assert "SysAlpha" in (out / "index.html").read_text()
    assert len(list((out / "releases" / "1" / "videos").glob("*.mp4"))) == 3 * len(SYSTEMS)  # 3 items each
    before = files_of(out)
    code, err = run([*tasks, "--out", out, "--publish"], capsys)
    assert code == 2 and err.count("\n") == 1 and "a challenge publishes once" in err and str(out) in err
    assert files_of(out) == before


def test_a_leaderboard_keeps_every_release(reports, tmp_path, capsys):
    out = tmp_path / "leaderboard"
    first = ["--task", f"realism={reports / 'report_acr'}"]
    assert run([*first, "--out", out, "--mode", "leaderboard", "--date", "2026-12-01"], capsys) == (0, "")
    release_1 = files_of(out / "releases" / "1")
    second = ["--task", f"realism={reports / 'report_pairwise'}", "--task", f"dyadic={reports / 'report_dyadic'}"]
    assert run([*second, "--out", out, "--date", "2026-12-03", "--quiet"], capsys) == (0, "")  # its own mode
    assert files_of(out / "releases" / "1") == release_1  # byte for byte, nothing added
    top = json.loads((out / "board.json").read_text())
    assert (top["release"], top["latest"], top["date"]) == (2, "releases/2/", "2026-12-03")
    assert top["releases"] == [
        {"release": 1, "date": "2026-12-01", "path": "releases/1/"},
        {"release": 2, "date": "2026-12-03", "path": "releases/2/"},
    ]
    assert [t["task"] for t in top["tasks"]] == ["realism", "dyadic"] and top["tasks"][0]["score"] == "Elo"
    index = (out / "index.html").read_text()
    assert 'href="releases/1/index.html"' in index and 'href="releases/2/index.html"' in index
    # every page says its release, its date and the tool's version
    for k, date in ((1, "2026-12-01"), (2, "2026-12-03")):
        for page in (out / "releases" / str(k)).rglob("*.html"):
            assert f"release {k} of {date} · made with moglow-eval {tool_version()}" in page.read_text(), page
    assert f"release 2 of 2026-12-03 · made with moglow-eval {tool_version()}" in index
    # a release dated before the one before is refused, the board left as it was
    before = files_of(out)
    code, err = run([*second, "--out", out, "--date", "2026-12-02"], capsys)
    assert code == 2 and err == "error: --date 2026-12-02: before release 2's date 2026-12-03; a board's releases go "\
        "forward\n", err  # fmt: skip
    assert files_of(out) == before


# ------------------------------------------------------------------------------------------- bad input
def _stats(reports, tmp_path, edit):
    """A report folder whose stats.json is the acr report's after `edit` (a function of the text)."""
    folder = tmp_path / "bad_report"
    folder.mkdir()
    (folder / "stats.json").write_text(edit((reports / "report_acr" / "stats.json").read_text()))
    return folder


def _without(key):
    def edit(text):
        doc = json.loads(text)
        del doc[key]
        return json.dumps(doc)

    return edit


def _with_design(name):
    def edit(text):
        return json.dumps({**json.loads(text), "design": name})

    return edit


def _manifest_repeating_a_clip(reports, tmp_path):
    """The study's stimulus folder with its first test clip's row repeated under another condition."""
    import shutil

    folder = tmp_path / "repeated"
    shutil.copytree(reports / "stimuli", folder)
    text = (folder / "manifest.csv").read_text()
    first = next(line for line in text.splitlines()[1:] if ",test," in line)
    other = next(c for c in SYSTEMS if f",{c}," not in first)
    condition = next(c for c in SYSTEMS if f",{c}," in first)
    (folder / "manifest.csv").write_text(text + first.replace(f",{condition},", f",{other},") + "\n")
    return folder


BAD = {
    "missing report": (lambda r, t: ["--task", f"a={t / 'nowhere'}"], "no such report folder"),
    "stats.json not JSON": (lambda r, t: ["--task", f"a={_stats(r, t, lambda s: s[:50])}"], "stats.json:"),
    "stats.json not a report's": (
        lambda r, t: ["--task", f"a={_stats(r, t, lambda s: json.dumps({'methods': 1}))}"],
        "not a report's stats.json",
    ),
    "stats.json without its design's keys": (
        lambda r, t: ["--task", f"a={_stats(r, t, _without('condition_summary'))}"],
        "not a acr report's stats.json (no 'condition_summary')",
    ),
    "stats.json of no design": (
        lambda r, t: ["--task", f"a={_stats(r, t, _with_design('quiz'))}"],
        "design 'quiz' is none of",
    ),
    "unknown mode": (
        lambda r, t: ["--task", f"a={r / 'report_acr'}", "--mode", "tournament"],
        "--mode: invalid choice",
    ),
    "a task that is no NAME=REPORT": (lambda r, t: ["--task", str(r / "report_acr")], "expected NAME=REPORT"),
    "a task given twice": (lambda r, t: ["--task", f"a={r / 'report_acr'}"] * 2, "--task a: given twice"),
    "stimuli of no task": (
        lambda r, t: ["--task", f"a={r / 'report_acr'}", "--stimuli", f"b={r / 'stimuli'}"],
        "no --task b",
    ),
    "a bad date": (lambda r, t: ["--task", f"a={r / 'report_acr'}", "--date", "2026-13-01"], "expected a date"),
    "a title with a terminal's escape": (
        lambda r, t: ["--task", f"a={r / 'report_acr'}", "--title", "Results\x1b[31m"],
        "--title: expected one line of printable text, got the control character U+001B",
    ),
    "no stimulus folder": (
        lambda r, t: ["--task", f"a={r / 'report_acr'}", "--stimuli", f"a={t}"],
        "no stimulus manifest; give --stimuli a=FOLDER",
    ),
    "a manifest repeating a clip": (
        lambda r, t: ["--task", f"a={r / 'report_acr'}", "--stimuli", f"a={_manifest_repeating_a_clip(r, t)}"],
        "again (line",
    ),
    "another study's export": (
        lambda r, t: ["--task", f"a={r / 'report_acr'}", "--export", f"a={r / 'pairwise.csv'}"],
        "not the export this report was made from",
    ),
    "another study's stimuli": (
        lambda r, t: [
            "--task",
            f"a={r / 'report_acr'}",
            "--stimuli",
            f"a={write_fake_stimuli(t / 'other', n_items=1, n_catch=0, n_training=0, metrics=False).parent}",
        ],
        "no test clips of SysAlpha",
    ),  # fmt: skip
    "another study's stimuli of the same systems": (  # its clip ids are its own, so the videos would be another's
        lambda r, t: [
            "--task",
            f"a={r / 'report_acr'}",
            "--stimuli",
            f"a={write_fake_stimuli(t / 'other', n_items=4, conditions=SYSTEMS, metrics=False, n_training=0).parent}",
        ],
        "not the stimuli of",
    ),  # fmt: skip
}


def test_an_empty_out_is_refused_naming_the_flag(reports, capsys):
    code, err = run(["--task", f"a={reports / 'report_acr'}", "--out", ""], capsys)
    assert code == 2 and err == (
        "error: python -m analysis.board: argument --out: empty; give a value, or leave the flag out (see --help)\n"
    ), err


def test_an_out_under_a_file_names_the_board_and_the_file(reports, tmp_path, capsys):
    """The build's hidden folder is the board's business: a board that cannot be made names the folder asked for
    and what is in its way (it said "afile: File exists", or named the hidden folder)."""
    (tmp_path / "afile").write_text("x")
    code, err = run(["--task", f"a={reports / 'report_acr'}", "--out", tmp_path / "afile" / "board"], capsys)
    assert code == 2 and err.startswith(f"error: {tmp_path / 'afile' / 'board'}: cannot be made there"), err
    assert ".building" not in err and err.count("\n") == 1, err


@pytest.mark.parametrize("case", BAD)
def test_bad_input_is_one_line_and_exit_2(case, reports, tmp_path, capsys):
    argv, message = BAD[case]
    out = tmp_path / "board"
    code, err = run([*argv(reports, tmp_path), "--out", out], capsys)
    assert code == 2 and err.count("\n") == 1 and err.startswith("error: "), err
    assert message in err, err
    assert not out.exists()


@pytest.mark.parametrize("case", ["a file", "a folder of something else", "a board of the other mode"])
def test_an_out_that_is_not_this_board_is_refused(case, reports, tmp_path, capsys):
    out = tmp_path / "board"
    task = ["--task", f"a={reports / 'report_acr'}"]
    if case == "a file":
        out.write_text("x")
    elif case == "a folder of something else":
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    else:
        assert run([*task, "--out", out, "--quiet"], capsys) == (0, "")  # a challenge, not yet published
    before = files_of(out) if out.is_dir() else out.read_bytes()
    code, err = run([*task, "--out", out, "--mode", "leaderboard"], capsys)
    assert code == 2 and err.count("\n") == 1 and str(out) in err, err
    assert {"a file": "is a file", "a folder of something else": "is not a board"}.get(case, "a challenge board") in err
    assert (files_of(out) if out.is_dir() else out.read_bytes()) == before


def test_an_interrupted_build_leaves_the_board_as_it_was(reports, tmp_path, capsys, monkeypatch):
    """The disk fills while the third video is copied: a new board never appears, and a board that exists keeps
    exactly its files, with nothing of the build left behind."""
    copy = release_module.copy_file
    calls = []

    def full_disk(src, dst, max_bytes, what):
        calls.append(what)
        if calls.count("video") == 3:
            raise OSError(28, "No space left on device", str(dst))
        return copy(src, dst, max_bytes, what)

    task = ["--task", f"realism={reports / 'report_acr'}"]
    monkeypatch.setattr(release_module, "copy_file", full_disk)
    new = tmp_path / "new" / "board"
    code, err = run([*task, "--out", new, "--mode", "leaderboard"], capsys)
    assert code == 2 and err.count("\n") == 1 and "No space left on device" in err
    assert list((tmp_path / "new").iterdir()) == []

    monkeypatch.setattr(release_module, "copy_file", copy)
    out = tmp_path / "board"
    assert run([*task, "--out", out, "--mode", "leaderboard", "--quiet"], capsys) == (0, "")
    before = files_of(out)
    monkeypatch.setattr(release_module, "copy_file", full_disk)
    calls.clear()
    code, err = run([*task, "--out", out], capsys)
    assert code == 2 and "No space left on device" in err
    assert files_of(out) == before and sorted(p.name for p in (out / "releases").iterdir()) == ["1"]


# ------------------------------------------------------------------------------------------- the pages
class Links(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.refs, self.tags = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.refs += [v for k, v in attrs if k in ("href", "src") and v]


def test_every_page_is_self_contained_and_every_link_leads_to_a_file(every_design):
    """No script, nothing from another host, and every link and video inside the board."""
    pages = sorted(every_design.rglob("*.html"))
    assert len(pages) > 10
    for page in pages:
        text = page.read_text(encoding="utf-8")
        links = Links()
        links.feed(text)
        assert "script" not in links.tags and "<script" not in text.lower(), page
        assert '<meta name="viewport" content="width=device-width, initial-scale=1">' in text
        for ref in links.refs:
            assert not re.match(r"(?i)^([a-z]+:|//)", ref), f"{page}: {ref} leaves the board"
            target = (page.parent / ref.split("#")[0]).resolve()
            assert target.is_file() and target.is_relative_to(every_design.resolve()), f"{page}: {ref}"
    videos = list((every_design / "releases" / "1" / "videos").iterdir())
    assert videos and all(v.is_file() and not v.is_symlink() for v in videos)  # copies, never links


@pytest.mark.browser
def test_the_board_in_chromium_at_a_phones_width(every_design, reports, browser, tmp_path):
    """Each kind of page at 390 px: the page never scrolls sideways (wide tables scroll in their own box), a system
    page's videos load, and every resource the browser fetched is a file of the board."""
    browser.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride", {"width": 390, "height": 844, "deviceScaleFactor": 1, "mobile": True}
    )
    board = every_design.resolve()
    rel = board / "releases" / "1"
    pages = [board / "index.html", rel / "index.html", rel / "tasks" / "pairwise.html", rel / "data.html"]
    pages += [rel / "systems" / f"{s}.html" for s in SYSTEMS]
    state = (
        "return {inner: window.innerWidth, wide: document.documentElement.scrollWidth,"
        " body: document.body.scrollWidth, scripts: document.scripts.length,"
        " fetched: performance.getEntriesByType('resource').map(function(e){return e.name}),"
        " videos: Array.prototype.map.call(document.querySelectorAll('video'),"
        "   function(v){return {src: v.currentSrc, ready: v.readyState, width: v.videoWidth}})};"
    )
    from helpers.browser import waiting

    for page in pages:
        browser.get(page.as_uri())
        if "systems" in page.parts:
            waiting(browser, 20).until(lambda d: all(v["ready"] >= 1 for v in d.execute_script(state)["videos"]))
        s = browser.execute_script(state)
        assert s["inner"] == 390 and s["wide"] <= 390 and s["body"] <= 390, (page, s)
        assert s["scripts"] == 0
        assert all(u.startswith(board.as_uri() + "/") for u in s["fetched"] + [v["src"] for v in s["videos"]]), s
        if "systems" in page.parts:  # 3 items in each of the six tasks, each a blinded clip of the board, decoded
            assert len(s["videos"]) == 3 * len(study.DESIGNS) and all(v["width"] > 0 for v in s["videos"])
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
    if os.environ.get("SAVE_SCREENSHOTS") == "1":  # docs/challenge.md's picture: a board of two tasks on a phone
        shown = tmp_path / "shown"
        tasks = [TaskSpec("realism", reports / "report_acr"), TaskSpec("speech", reports / "report_appropriateness")]
        build_board(tasks, shown, mode="challenge", publish=True, date="2026-12-01", title="Gesture challenge 2026")
        browser.get((shown / "index.html").as_uri())
        browser.save_screenshot(str(ROOT / "docs" / "img" / "board_phone.png"))
