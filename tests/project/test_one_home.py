"""Every measured figure has one home, bench/RESULTS.md: the product and the docs link to its entries instead of
restating them (a copy goes stale the next time a model is retrained), and neither cites an issue number, which
no reader of a release can follow."""

import re

import pytest
from helpers.paths import PARTS, ROOT

# A measured ratio: "1.34x", "2x", "1.0-1.5x", "40×" (not "0x1F", "2x512", "2×512 LSTMs", "x264").
RATIO = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)?[x×](?![\w×])")
ISSUE = re.compile(r"\bissues? #?\d+", re.I)


def product_files():
    for part in PARTS:
        folder = ROOT / part
        yield from folder.rglob("*.py")
        yield from folder.rglob("*.json")
        yield from folder.rglob("*.html")
        yield from folder.rglob("*.js")


def doc_files():
    yield ROOT / "README.md"
    yield ROOT / "CONTRIBUTING.md"
    yield from (p for p in (ROOT / "docs").glob("*.md") if p.name != "results.md")  # results.md is RESULTS itself


def offences(paths, root=ROOT):
    """['file:line: the match'] for every measured ratio or issue number in the files."""
    found = []
    for path in paths:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for m in (*RATIO.finditer(line), *ISSUE.finditer(line)):
                found.append(f"{path.relative_to(root)}:{n}: {m.group(0)!r}")
    return found


def test_product_code_quotes_no_figure_and_no_issue():
    bad = offences(product_files())
    assert not bad, "link the bench/RESULTS.md entry instead:\n" + "\n".join(bad)


def test_the_docs_quote_no_figure_and_no_issue():
    bad = offences(doc_files())
    assert not bad, "link the results.md entry instead:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    "text, hits",
    [
        ("MG jerks 1.34x NAT's", 1),
        ("skating 1.0-1.5x on walks, 40× faster", 2),
        ("meets issue 15's targets (Issues #37)", 2),
        ("0x1F, 2x512 LSTMs, 2×512, x264, 16 ms", 0),
    ],
)
def test_the_checker_sees_ratios_and_issue_numbers(tmp_path, text, hits):
    f = tmp_path / "a.py"
    f.write_text(f"# {text}\n", encoding="utf-8")
    found = offences([f], tmp_path)
    assert len(found) == hits, found


def test_every_config_value_has_one_short_comment():
    """The JSON configs are data with a one-line note and a short comment per value; why the values are what they
    are is a table in docs/models.md, and what they gave is in bench/RESULTS.md."""
    import json

    for path in sorted((ROOT / "generation" / "configs").glob("*.json")):
        config = json.loads(path.read_text(encoding="utf-8"))
        values = set(config) - {"note", "comments"}
        assert set(config.get("comments", {})) == values, f"{path.name}: comment every value, and only those"
        assert len(config["note"]) <= 120 and "\n" not in config["note"], f"{path.name}: note: one short line"
        assert path.stem in (ROOT / "docs" / "models.md").read_text(encoding="utf-8"), f"{path.name}: not in models.md"
