"""Catches a fast-tier test that reads ../shared.

The fast tier needs nothing beside the checkout (tests/conftest.py), but CI always has ../shared beside it, so a test
that reads the real data without saying so (the `shared_dir` fixture, or a `full` mark) passes there and fails only on
a bare clone, where nobody runs the suite often. An audit hook (PEP 578) sees every file and folder the worker's
main thread opens or lists while a fast-tier test runs, and the test fails naming the first path under ../shared.
Only the main thread is watched: a server thread that a full-tier fixture left running is not the test's doing.
"""

import os
import sys
import threading

from helpers.paths import SHARED

_EVENTS = {"open", "os.listdir", "os.scandir"}
_PREFIX = str(SHARED) + os.sep
_MAIN = threading.main_thread().ident


class _Watch:
    installed = False
    on = False
    seen = None


def _hook(event, args):
    if not _Watch.on or _Watch.seen is not None or event not in _EVENTS:
        return
    path = args[0] if args else None
    if isinstance(path, int) or path is None or threading.get_ident() != _MAIN:
        return
    path = os.fsdecode(os.fspath(path))
    if path.startswith(_PREFIX) or path == str(SHARED):
        _Watch.seen = path


def install():
    """Adds the hook to this process (once: an audit hook cannot be removed, so it is switched on per test)."""
    if not _Watch.installed:
        sys.addaudithook(_hook)
        _Watch.installed = True


def watch():
    _Watch.on, _Watch.seen = True, None


def stop():
    """Stops watching; the first path under ../shared read since `watch`, or None."""
    seen, _Watch.on, _Watch.seen = _Watch.seen, False, None
    return seen
