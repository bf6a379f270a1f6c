"""Catches a fast-tier test that needs what only the full tier may: ../shared, PostgreSQL or a browser.

The fast tier needs nothing beside the checkout (tests/conftest.py, docs/setup.md), but CI always has ../shared,
PostgreSQL and Chromium, so a test that uses one of them without saying so (a fixture such as `shared_dir` or
`pg_server`, or a `full`, `postgres` or `browser` mark) passes there and fails only on a bare machine, where nobody
runs the suite often. An audit hook (PEP 578) sees every file and folder the worker's main thread opens or lists,
and every program it starts, while a fast-tier test runs; the test then fails naming the first such path or
program. Only the main thread is watched: a server thread that a full-tier fixture left running is not the test's
doing. What a command the test starts does in its own process is not seen, nor a connection to a PostgreSQL server
already running (libpq opens it, out of the hook's sight); the tests learn its address only from `pg_server`.
"""

import os
import sys
import threading

from helpers.paths import SHARED

# Programs of the full tier's parts: the browser and its driver, and PostgreSQL's server and clients.
FULL_PROGRAMS = {"chromium", "chromedriver", "chrome", "postgres", "pg_ctl", "initdb", "psql", "pg_dump"}
_EVENTS = frozenset({"open", "os.listdir", "os.scandir", "subprocess.Popen"})
_PREFIX = str(SHARED) + os.sep
_MAIN = threading.main_thread().ident


class _Watch:
    installed = False
    on = False
    seen = None


def _program(args):
    executable, argv = args[0], args[1]
    if executable is None:
        executable = argv if isinstance(argv, (str, bytes, os.PathLike)) else (argv[0] if argv else "")
    name = os.path.basename(os.fsdecode(os.fspath(executable))).split()[0] if executable else ""
    return name if name in FULL_PROGRAMS else None


def _hook(event, args):
    # Called for every audited event of the process (id(), imports, sockets...): the event is checked first.
    if event not in _EVENTS or not _Watch.on or _Watch.seen is not None or threading.get_ident() != _MAIN:
        return
    if event == "subprocess.Popen":
        name = _program(args)
        if name:
            _Watch.seen = f"the program {name}"
        return
    if not args or args[0] is None or isinstance(args[0], int):
        return
    path = os.fsdecode(os.fspath(args[0]))
    if path.startswith(_PREFIX) or path == str(SHARED):
        _Watch.seen = path


def install():
    """Adds the hook to this process, once: an audit hook cannot be removed, so it is switched on per test."""
    if not _Watch.installed:
        sys.addaudithook(_hook)
        _Watch.installed = True


def watch():
    _Watch.on, _Watch.seen = True, None


def stop():
    """Stops watching; what the test used since `watch` (a path under ../shared or "the program NAME"), or None."""
    seen, _Watch.on, _Watch.seen = _Watch.seen, False, None
    return seen
