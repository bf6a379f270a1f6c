"""A command that is its process's own program freezes what its imports made out of the cyclic collector's reach
(moglow_eval.core.cli.imports_done), once; a main called in-process, by a test or by another command, never does:
frozen objects are never collected, so freezing in a long-lived caller would keep its garbage."""

import subprocess
import sys

from helpers.paths import ROOT

# `main` prints the freeze count the collector had before `cli.run` and while main runs; run twice, the second
# call's count shows whether a second freeze moved the lists made in between.
PROBE = """
import gc
from moglow_eval.core import cli
before = gc.get_freeze_count()
def main(argv):
    print(before, gc.get_freeze_count())
cli.run(main{args})
made = [[i] for i in range(1000)]
cli.run(main{args})
"""


def counts(args=""):
    code = PROBE.format(args=args)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 0, r.stderr
    return [tuple(map(int, line.split())) for line in r.stdout.splitlines()]


def test_a_command_run_as_its_process_freezes_its_imports_once():
    (before, first), (_, second) = counts()
    assert before == 0 and first > 1000  # argparse, logging and the rest cli imports
    assert second == first  # not again: the lists made between the two calls stay collectable


def test_a_main_called_in_process_leaves_the_collector_alone():
    assert counts(", []") == [(0, 0), (0, 0)]


def test_the_console_script_runs_its_command_as_the_process():
    code = (
        "import atexit, gc, sys; atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0));"
        "from moglow_eval.console import main; sys.exit(main({}))"
    )
    for argv, frozen in ((None, "True"), (["report", "--version"], "False")):
        r = subprocess.run(
            [sys.executable, "-c", code.format(argv), "report", "--version"],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=120,
        )
        assert r.returncode == 0 and r.stdout.splitlines()[-1] == f"frozen {frozen}", (argv, r.stdout, r.stderr)
