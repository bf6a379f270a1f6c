"""Catches a fast-tier test that needs what only the full tier may: ../shared, PostgreSQL or a browser.

The fast tier needs nothing beside the checkout (tests/conftest.py, docs/setup.md), but CI always has ../shared,
PostgreSQL and Chromium, so a test that uses one of them without saying so (a fixture such as `shared_dir` or
`pg_server`, or a `full`, `postgres` or `browser` mark) passes there and fails only on a bare machine, where nobody
runs the suite often. An audit hook (PEP 578) sees every file and folder the test's thread opens or lists, and every
program it starts, while a fast-tier test runs; the test then fails naming the first such path or
program. Only the thread that runs the test is watched: a server thread that a full-tier fixture left running is not
the test's doing. What a command the test starts does in its own process is not seen, nor a connection to a PostgreSQL
server already running (libpq opens it, out of the hook's sight); the tests learn its address only from `pg_server`.
"""

import os
import sys
import threading

from helpers.paths import SHARED

# Programs of the full tier's parts: the browser and its driver, and PostgreSQL's server and clients.
FULL_PROGRAMS = frozenset(
    {"chromium", "chromedriver", "chrome", "postgres", "pg_ctl", "pg_ctlcluster", "initdb", "psql", "pg_dump"}
)
_EVENTS = frozenset({"open", "os.listdir", "os.scandir", "subprocess.Popen"})
_SHARED = str(SHARED)
_PREFIX = _SHARED + os.sep


class _Watch:
    installed = False
    on = False
    thread = None  # the ident of the thread running the test (an older execnet's is not the main thread)
    seen = None


def _program(args):
    """The full-tier program a subprocess.Popen event starts, or None: its executable, or the command after `--`
    of a wrapper such as `runuser -u postgres -- initdb` (how the tests' own PostgreSQL is made as root)."""
    executable, argv = args[0], args[1]
    argv = [argv] if isinstance(argv, (str, bytes, os.PathLike)) else list(argv or [])
    words = [executable if executable is not None else (argv[0] if argv else "")]
    if "--" in argv[:-1]:
        words.append(argv[argv.index("--") + 1])
    for word in words:
        name = os.path.basename(os.fsdecode(os.fspath(word))).split()
        if name and name[0] in FULL_PROGRAMS:
            return name[0]
    return None


def _hook(event, args):
    # Called for every audited event of the process (id(), imports, sockets...): the event is checked first.
    if event not in _EVENTS or not _Watch.on or _Watch.seen is not None or threading.get_ident() != _Watch.thread:
        return
    if event == "subprocess.Popen":
        name = _program(args)
        if name:
            _Watch.seen = f"the program {name}"
        return
    if not args or args[0] is None or isinstance(args[0], int):
        return
    path = os.fsdecode(os.fspath(args[0]))
    if path.startswith(_PREFIX) or path == _SHARED:
        _Watch.seen = path


def install():
    """Adds the hook to this process, once: an audit hook cannot be removed, so it is switched on per test."""
    if not _Watch.installed:
        sys.addaudithook(_hook)
        _Watch.installed = True


def watch():
    """Starts watching the calling thread."""
    _Watch.on, _Watch.thread, _Watch.seen = True, threading.get_ident(), None


def stop():
    """Stops watching; what the test used since `watch` (a path under ../shared or "the program NAME"), or None."""
    seen, _Watch.on, _Watch.seen = _Watch.seen, False, None
    return seen
