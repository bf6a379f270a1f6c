"""The scripting API page (docs/api.md) documents what it names, and its examples are true.

Every `::: dotted.name` on the page is a function that imports, is defined where the page says, and has a numpy
docstring with Parameters (matching its signature, each with a type) and Returns. The `>>>` examples of those
docstrings run here as doctests. mkdocs build --strict (tests/project/test_docs.py) checks the rendering; this checks
the content without mkdocs, and fast: no example renders, trains or fits a slow model.
"""

import doctest
import importlib
import inspect
import re

import pytest
from helpers.paths import ROOT

PAGE = ROOT / "docs" / "api.md"


def documented_names():
    return re.findall(r"^::: ([\w.]+)\s*$", PAGE.read_text(encoding="utf-8"), re.M)


def resolve(name):
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def sections(doc):
    """{section title: its lines} of a numpy docstring (a title is underlined with dashes of its length)."""
    lines = doc.splitlines()
    starts = [
        i
        for i in range(len(lines) - 1)
        if lines[i].strip() and re.fullmatch(r"-+", lines[i + 1]) and len(lines[i + 1]) == len(lines[i])
    ]
    return {lines[i]: lines[i + 2 : (starts + [len(lines) + 1])[k + 1] - 1] for k, i in enumerate(starts)}


def docstring_problems(func):
    """What is wrong with `func`'s docstring for the API page; [] when nothing is."""
    doc = inspect.getdoc(func)
    if not doc:
        return ["no docstring"]
    found = sections(doc)
    problems = [f"no {title} section" for title in ("Parameters", "Returns") if title not in found]
    entries = [line for line in found.get("Parameters", []) if line.strip() and not line.startswith(" ")]
    documented = [n for line in entries for n in line.partition(" : ")[0].split(", ")]
    actual = list(inspect.signature(func).parameters)
    if "Parameters" in found and documented != actual:
        problems.append(f"Parameters document {documented}, the signature has {actual}")
    problems += [f"parameter line {line!r} gives no type" for line in entries if " : " not in line]
    return problems


def doctest_failures(func, name):
    """(examples run, the report of each failing one). The examples get empty globals: each imports what it
    uses, as a reader copying it would."""
    report = []
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    attempted = 0
    for test in doctest.DocTestFinder(recurse=False).find(func, name, globs={}):
        result = runner.run(test, out=report.append, clear_globs=True)
        attempted += result.attempted
    return attempted, report


NAMES = documented_names()


def test_the_page_names_the_functions_of_each_section():
    assert len(NAMES) >= 20 and len(set(NAMES)) == len(NAMES), NAMES
    text = PAGE.read_text(encoding="utf-8")
    for part in re.split(r"^## ", text, flags=re.M)[1:]:
        assert re.search(r"^::: ", part, re.M), f"section {part.splitlines()[0]!r} documents no function"


@pytest.mark.parametrize("name", NAMES)
def test_every_function_on_the_page_has_parameters_and_returns(name):
    func = resolve(name)
    assert inspect.isfunction(func), f"{name}: not a function"
    assert f"{func.__module__}.{func.__qualname__}" == name, f"{name}: name it where it is defined"
    assert docstring_problems(func) == [], name


def test_the_examples_on_the_page_run():
    attempted, failures = 0, []
    for name in NAMES:
        n, report = doctest_failures(resolve(name), name)
        attempted += n
        failures += report
    assert not failures, "".join(failures)
    assert attempted >= 15  # the examples exist: a page without any would pass the line above for nothing


# ---------------------------------------------------------------- the checks can fail


def _summary_only(a):
    """Adds one."""
    return a + 1


def _wrong_parameter(a, b):
    """Adds two numbers.

    Parameters
    ----------
    a : int
        One.
    c
        The other.

    Returns
    -------
    int
        The sum.

    Examples
    --------
    >>> 1 + 2
    4
    """
    return a + b


def test_the_checks_catch_missing_sections_wrong_parameters_and_false_examples():
    assert docstring_problems(_summary_only) == ["no Parameters section", "no Returns section"]
    assert docstring_problems(_wrong_parameter) == [
        "Parameters document ['a', 'c'], the signature has ['a', 'b']",
        "parameter line 'c' gives no type",
    ]
    attempted, report = doctest_failures(_wrong_parameter, "_wrong_parameter")
    assert attempted == 1 and "Expected:\n    4\nGot:\n    3" in "".join(report)
    assert documented_names()[0] == "analysis.data.load.load_ratings"  # the page's `::: name` lines are read
