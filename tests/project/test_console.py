"""The console command (pyproject [project.scripts]) and --version on every command (issue 33, item 2)."""

import importlib
import re
import subprocess
import sys
import tomllib
from importlib import metadata

import pytest
from helpers.paths import ROOT

from moglow_eval.console import COMMANDS

VERSION = metadata.version("moglow-eval")


def entry_point(name):
    """The function pyproject.toml names for console script `name`, imported as pip's wrapper imports it."""
    spec = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"][name]
    module, func = spec.split(":")
    return getattr(importlib.import_module(module), func)


def test_the_console_script_is_the_dispatcher():
    from moglow_eval.console import main

    assert entry_point("moglow-eval") is main


def test_every_subcommand_reaches_its_part_and_answers_version(capsys):
    main = entry_point("moglow-eval")
    assert set(COMMANDS) >= {"stimuli", "serve", "simulate", "export", "report", "plan", "demo", "backup", "restore"}
    for command in COMMANDS:
        with pytest.raises(SystemExit) as e:
            main([command, "--version"])
        assert e.value.code == 0, command
        assert capsys.readouterr().out.strip() == f"moglow-eval {VERSION}", command
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"moglow-eval {VERSION}"


def test_a_subcommand_is_the_python_m_command(tmp_path, capsys):
    """The same arguments give the same one-line error and exit code as `python -m`."""
    missing = tmp_path / "none.sqlite"
    args = ["export", "--db", f"sqlite:///{missing}", "--out", str(tmp_path / "r.csv")]
    code = entry_point("moglow-eval")(args)
    err = capsys.readouterr().err.strip()
    r = subprocess.run([sys.executable, "-m", "rating_app", *args], capture_output=True, text=True, cwd=ROOT)
    assert (code, err) == (r.returncode, r.stderr.strip()) == (2, f"error: {missing}: no such database file")


@pytest.mark.parametrize("command", ["report", "stimuli", "serve", "demo"])
def test_help_and_errors_name_the_command_as_typed(command, capsys):
    """Issue 46: `moglow-eval report --help` said `usage: python -m analysis.report`."""
    main = entry_point("moglow-eval")
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert capsys.readouterr().out.startswith(f"usage: moglow-eval {command} "), command
    with pytest.raises(SystemExit) as e:
        main([command, "--no-such-flag"])
    assert e.value.code == 2 and capsys.readouterr().err.startswith("error: moglow-eval")
    # and `python -m` keeps its own name afterwards (the name is set only while the console command runs)
    from analysis.report import build_parser

    assert build_parser().prog == "python -m analysis.report"


def test_an_unknown_command_is_one_line(capsys):
    assert entry_point("moglow-eval")(["bogus"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown command 'bogus'" in err


@pytest.mark.parametrize("module", ["rendering", "analysis.report", "analysis.plan", "generation.data.import_motion"])
def test_python_m_keeps_working_and_answers_version(module):
    r = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True, text=True, cwd=ROOT)
    assert (r.returncode, r.stdout.strip()) == (0, f"moglow-eval {VERSION}")


PACKAGES = ("generation", "rendering", "analysis", "rating_app")


def product_sources():
    """(path, text) of every Python file of the product's parts, in a stable order."""
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield path, path.read_text(encoding="utf-8")


def command_modules():
    """Every module of the product with a `main`: each a `python -m` command (a list kept by hand missed ten)."""
    return [
        ".".join(path.relative_to(ROOT).with_suffix("").parts)
        for path, text in product_sources()
        if re.search(r"^def main\(", text, re.M)
    ]


COMMAND_MODULES = command_modules()


def test_every_command_parses_with_the_projects_parser():
    """cli.ArgumentParser gives every command its one-line errors, --version and the refusal of an empty value; a
    command built on argparse's own parser would have none of them."""
    assert len(COMMAND_MODULES) >= 20, COMMAND_MODULES
    own = [str(path.relative_to(ROOT)) for path, text in product_sources() if "argparse.ArgumentParser(" in text]
    assert own == [], own


@pytest.mark.parametrize("module", COMMAND_MODULES)
def test_every_main_answers_version(module, capsys):
    """Every `python -m` command answers --version with the one version pyproject.toml sets, through its main."""
    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"moglow-eval {VERSION}"
    assert VERSION == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
