"""bench/RESULTS.md is one page of today's figures (issue 53, item 2): at most 600 lines, and every entry gives its
command, machine, same-run baseline and date; what it replaced is history, in bench/notes/."""

import re

from helpers.paths import ROOT

RESULTS = ROOT / "bench" / "RESULTS.md"
MAX_LINES = 600
FIELDS = ("Command", "Machine", "baseline", "Date")


def entries(text):
    """{id: text} of every `### id` entry."""
    return {m[1]: m[2] for m in re.finditer(r"^### ([\w-]+)\n(.*?)(?=^#{2,3} |\Z)", text, re.M | re.S)}


def test_results_is_one_page():
    n = RESULTS.read_text(encoding="utf-8").count("\n")
    assert n <= MAX_LINES, f"bench/RESULTS.md has {n} lines (at most {MAX_LINES}): move superseded runs to bench/notes/"


def test_every_figure_has_its_command_machine_baseline_and_date():
    found = entries(RESULTS.read_text(encoding="utf-8"))
    assert len(found) >= 20
    missing = {name: [f for f in FIELDS if f not in body] for name, body in found.items()}
    missing = {name: fields for name, fields in missing.items() if fields}
    assert not missing, f"bench/RESULTS.md entries without {missing}"


def test_the_checks_can_fail():
    text = "### a\n- Command: x\n- Machine: y\n- Date: z\n### b\n- Command: x\n"
    assert entries(text) == {"a": "- Command: x\n- Machine: y\n- Date: z\n", "b": "- Command: x\n"}
    assert [f for f in FIELDS if f not in entries(text)["a"]] == ["baseline"]
