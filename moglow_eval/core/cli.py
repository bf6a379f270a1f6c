"""One convention for every command-line tool of the project.

A problem with what the user gave (a file, a line in it, a flag) ends the run with one line on stderr,
``error: WHERE: WHAT``, and exit code 2; never a traceback. Library code raises `UserError` (or a
subclass, e.g. ``BvhError``) with a message that already names the file, line or field; flags are
checked by the argparse types below, and a flag or argument given an empty value by the parser itself; `run`
turns both into that one line. Anything else is a bug and keeps its traceback.

    def main(argv=None):
        return cli.run(_main, argv)
"""

import argparse
import contextlib
import gc
import logging
import math
import sys
from importlib import metadata
from pathlib import Path

EXIT_USAGE = 2
DIST = "moglow-eval"


def version() -> str:
    """The package's version, from its installed metadata (pyproject.toml is the one place it is written)."""
    try:
        return metadata.version(DIST)
    except metadata.PackageNotFoundError:
        return "unknown (not installed: pip install -e .)"


class UserError(ValueError):
    """Bad input from the user: the message is one line naming the file, line, field or flag."""


_invoked_as: str | None = None  # the name a command was run by, when not `python -m ...` (see `invoked_as`)
_as_process = False  # the console script runs a command as its process's own program (see `invoked_as`)
_frozen = False  # whether `imports_done` has run in this process


@contextlib.contextmanager
def invoked_as(name: str, process: bool = False):
    """Within the block, a command's parser calls itself `name` (e.g. ``moglow-eval report``) in its usage, help
    and error lines instead of the ``python -m ...`` it was built with, and, with `process`, the command is the
    process's own program, as a ``python -m`` run is (see `run`). Only a console command's main uses it."""
    global _invoked_as, _as_process
    before = _invoked_as, _as_process
    _invoked_as, _as_process = name, process
    try:
        yield
    finally:
        _invoked_as, _as_process = before


def imports_done():
    """Once a process, when its imports are done: what they made (modules, classes, functions; some hundred thousand
    objects where torch, scipy or pandas is loaded) lives as long as the process, so it is frozen out of the cyclic
    garbage collector's reach (`gc.freeze`), and each full collection after walks only what the process makes
    itself. Unfrozen, every full collection walked it all again (a measurable share of a command's CPU:
    bench/RESULTS.md, test-suite) and, in a server's forked workers, wrote to each page they share with their
    parent. Only a program's own start calls this (`run` for a ``python -m`` command, the WSGI entry point),
    never a library function: frozen objects are never collected, so a long-lived process calling it again and
    again (a test run calling mains in-process) would keep what was garbage at each call."""
    global _frozen
    if not _frozen:
        _frozen = True
        gc.freeze()


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a bad flag gives one line (``error: argument --fps: ...``), not usage plus message; every
    command and subcommand answers ``--version``."""

    def __init__(self, *args, **kwargs):
        # A subcommand's parser gets its prog from its parent's, so only the `python -m` ones are renamed.
        if _invoked_as and str(kwargs.get("prog", "")).startswith("python -m "):
            kwargs["prog"] = _invoked_as
        super().__init__(*args, **kwargs)
        self.add_argument("--version", action="version", version=f"moglow-eval {version()}")

    def error(self, message):
        self.exit(EXIT_USAGE, f"error: {self.prog}: {message} (see --help)\n")

    def _get_value(self, action, arg_string):
        # An empty value (`--out "$DIR"` with the variable unset) would be read as the current folder once a type made
        # it a Path, or as the flag left out by a command testing for a value: refused for every flag and argument
        # of every command, before its type sees it. argparse has no public hook before the type conversion. A
        # subcommand's strings pass through its parent's action (nargs PARSER) to the subcommand's parser, which checks.
        # argparse also passes a string default through here, so a blank default would refuse every run: none has one.
        passed_on = action.nargs in (argparse.PARSER, argparse.REMAINDER)
        if isinstance(arg_string, str) and not arg_string.strip() and not passed_on:
            leave = ", or leave the flag out" if action.option_strings and not action.required else ""
            raise argparse.ArgumentError(action, f"empty; give a value{leave}")
        return super()._get_value(action, arg_string)


def number(kind=float, lo=None, hi=None, lo_open=False):
    """An argparse type: a finite `kind` (int or float) in [lo, hi] ((lo, hi] with lo_open).
    Rejects nan, inf and absurd sizes before they reach an allocation."""

    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if kind is int else 'a number'}, got {text!r}"
            ) from None
        if isinstance(value, float) and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        too_low = lo is not None and (value <= lo if lo_open else value < lo)
        if too_low or (hi is not None and value > hi):
            low = "" if lo is None else f"{'>' if lo_open else '>='} {lo}"
            high = "" if hi is None else f"<= {hi}"
            raise argparse.ArgumentTypeError(f"must be {' and '.join(s for s in (low, high) if s)}, got {text!r}")
        return value

    return parse


def folder_to_write(out, what: str, flag: str = "--out") -> Path:
    """`out` as the folder a command writes in, checked before any work so a long run does not end on it: not empty
    (that would be the current folder), and neither it nor the nearest of its folders that exists a file.
    `what` names the folder in the message ("the report's folder"). UserError naming the flag, else the path."""
    if not str(out).strip():
        raise UserError(f"{flag}: empty; give {what}")
    out = Path(out)
    there = next((p for p in (out, *out.parents) if p.exists()), None)
    if there is not None and not there.is_dir():
        raise UserError(f"{flag} {out}: " + ("a file, not a folder" if there == out else f"{there} is a file"))
    return out


def file_to_write(out, what: str, flag: str = "--out", reads=()) -> Path:
    """`out` as the file a command writes, checked before any work (a training, a dataset's preparation): not
    empty, not a folder, no file where one of its folders would be, and none of the files the command reads
    (`reads`: (flag, path) pairs; None paths skipped), which the written file would replace. UserError naming the
    flag."""
    if not str(out).strip():
        raise UserError(f"{flag}: empty; give {what}")
    out = Path(out)
    if out.is_dir():
        raise UserError(f"{flag} {out}: a folder; give {what}")
    there = next((p for p in out.parents if p.exists()), None)
    if there is not None and not there.is_dir():
        raise UserError(f"{flag} {out}: {there} is a file")
    for source, path in reads:
        if path is not None and out.exists() and Path(path).exists() and out.samefile(path):
            raise UserError(f"{flag} {out}: is the file {source} names, which it would replace; write elsewhere")
    return out


def run(main, argv=None):
    """Call ``main(argv)`` and return its exit code; a `UserError` or an OS error becomes one line and 2.

    With no `argv` (the command reads the process's own: ``python -m ...``), or under the console script, the
    command is the process's program, and its imports are done: `imports_done` first. A test or another command
    calling a main in-process always passes `argv`."""
    if argv is None or _as_process:
        imports_done()
    try:
        return main(argv) or 0
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
    except OSError as e:
        where = e.filename if e.filename is not None else "system"
        print(f"error: {where}: {e.strerror or e}", file=sys.stderr)
    except MemoryError:
        print("error: out of memory (an input asks for more than this machine has)", file=sys.stderr)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    return EXIT_USAGE


def log_to_stderr(quiet=False, formatter=None):
    """Send a command's diagnostics (`logging`) to stderr as plain lines, warnings only with `quiet`.

    Only a command's `main` calls this: logging is process-wide state (CONTRIBUTING.md). `force` because an
    earlier command run in the same process (a test, the demo) may have left a handler on a stream now gone.
    """
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(formatter or logging.Formatter("%(message)s"))
    logging.basicConfig(level=logging.WARNING if quiet else logging.INFO, handlers=[handler], force=True)
