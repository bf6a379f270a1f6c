"""moglow-eval COMMAND [ARGS]: one console command for the whole pipeline (pyproject.toml [project.scripts]).

Each command is the part's own `python -m` main, given the rest of the arguments unchanged:

    moglow-eval stimuli ...   = python -m generation.make_stimuli ...
    moglow-eval intake ...    = python -m generation.challenge.intake ...   (teams' submissions checked)
    moglow-eval serve ...     = python -m rating_app serve ...    (also simulate, export, backup, restore)
    moglow-eval report ...    = python -m analysis.report ...
    moglow-eval plan ...      = python -m analysis.plan ...
    moglow-eval board ...     = python -m analysis.board ...      (the results published as a static site)
    moglow-eval demo ...      = python -m analysis.demo ...
    moglow-eval challenge-demo ... = python -m analysis.challenge_demo ...   (a whole challenge, inputs to board)

This package sits above the five parts (docs/ARCHITECTURE.md): it may import any of them, and none imports it.
"""

from __future__ import annotations

import sys

from .core import cli


# The parts are imported only when their command runs (lazy on purpose): `moglow-eval report` must not load torch
# (generation) nor Flask (rating_app) for nothing, and a machine that only analyses needs neither.
def _stimuli(args):
    from generation.make_stimuli import main as run

    return run(args)


def _intake(args):
    from generation.challenge.intake import main as run

    return run(args)


def _app(command):
    def call(args):
        from rating_app.__main__ import main as run

        return run([command, *args])

    return call


def _report(args):
    from analysis.report import main as run

    return run(args)


def _plan(args):
    from analysis.plan import main as run

    return run(args)


def _board(args):
    from analysis.board import main as run

    return run(args)


def _demo(args):
    from analysis.demo import main as run

    return run(args)


def _challenge_demo(args):
    from analysis.challenge_demo import main as run

    return run(args)


APP_COMMANDS = ("serve", "simulate", "export", "backup", "restore")
COMMANDS = {
    "stimuli": _stimuli,
    "intake": _intake,
    **{c: _app(c) for c in APP_COMMANDS},
    "report": _report,
    "plan": _plan,
    "board": _board,
    "demo": _demo,
    "challenge-demo": _challenge_demo,
}


def _usage() -> str:
    return f"usage: moglow-eval {{{','.join(COMMANDS)}}} [ARGS] (each command's --help; --version)"


def main(argv=None) -> int:
    from_process = argv is None  # the console script itself, not a call in-process (cli.run, imports_done)
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__ if argv else _usage())
        return 0 if argv else cli.EXIT_USAGE
    if argv[0] == "--version":
        print(f"moglow-eval {cli.version()}")
        return 0
    if argv[0] not in COMMANDS:
        print(f"error: moglow-eval: unknown command {argv[0]!r}; {_usage()}", file=sys.stderr)
        return cli.EXIT_USAGE
    # Usage and error lines name the command as typed (`moglow-eval report`), not the `python -m` it stands for;
    # the app's subcommands add their own name to it.
    name = "moglow-eval" if argv[0] in APP_COMMANDS else f"moglow-eval {argv[0]}"
    with cli.invoked_as(name, process=from_process):
        return COMMANDS[argv[0]](argv[1:]) or 0
