"""The fast tier's promise, that it needs nothing beside the checkout, is watched (helpers/fast_tier.py)."""

import os
from contextlib import suppress

from helpers import fast_tier
from helpers.paths import ACTIONS, ROOT, SHARED


def test_a_read_under_shared_is_seen_and_one_beside_it_is_not():
    # The paths need not exist: the audit event comes before the open, so this holds on a bare clone too.
    fast_tier.watch()
    for path in (ROOT / "README.md", ROOT.parent / "shared-not", ROOT / "tests"):
        with suppress(OSError):
            open(path).close() if path.suffix else os.listdir(path)
    assert fast_tier.stop() is None
    for read in (lambda p: open(p), os.listdir, os.scandir):
        fast_tier.watch()
        with suppress(OSError):
            read(ACTIONS / "absent.bvh")
        assert fast_tier.stop() == str(ACTIONS / "absent.bvh")
    fast_tier.watch()
    with suppress(OSError):
        os.listdir(SHARED)
    assert fast_tier.stop() == str(SHARED)


def test_nothing_is_seen_when_not_watched():
    fast_tier.stop()
    with suppress(OSError):
        open(ACTIONS / "absent.bvh")
    fast_tier.watch()
    assert fast_tier.stop() is None


def test_a_browser_or_postgresql_started_is_seen_and_ffmpeg_is_not():
    import subprocess

    for argv, seen in (
        (["ffmpeg", "-version"], None),
        (["/usr/bin/chromedriver", "--version"], "the program chromedriver"),
        (["pg_ctl", "--version"], "the program pg_ctl"),
        (["env", "--", "initdb", "--version"], "the program initdb"),
        (["env", "-u", "postgres", "ffmpeg", "-version"], None),
        (["chromium", "--version"], "the program chromium"),
    ):
        fast_tier.watch()
        with suppress(OSError):  # not installed here: the event came before the start
            subprocess.run(argv, capture_output=True, timeout=60, stdin=subprocess.DEVNULL)
        assert fast_tier.stop() == seen, argv


def test_a_read_by_another_thread_is_not_the_tests():
    import threading

    def read():
        with suppress(OSError):
            open(ACTIONS / "absent.bvh")

    fast_tier.watch()
    other = threading.Thread(target=read)
    other.start()
    other.join()
    assert fast_tier.stop() is None
    fast_tier.watch()
    read()
    assert fast_tier.stop() == str(ACTIONS / "absent.bvh")
