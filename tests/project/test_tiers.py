"""The fast tier's promise, that it needs nothing beside the checkout, is watched (helpers/shared_reads.py)."""

import os

from helpers import shared_reads
from helpers.paths import ACTIONS, ROOT, SHARED


def test_a_read_under_shared_is_seen_and_one_beside_it_is_not():
    # The paths need not exist: the audit event comes before the open, so this holds on a bare clone too.
    shared_reads.watch()
    for path in (ROOT / "README.md", ROOT.parent / "shared-not", ROOT / "tests"):
        try:
            open(path).close() if path.suffix else os.listdir(path)
        except OSError:
            pass
    assert shared_reads.stop() is None
    for read in (lambda p: open(p), os.listdir, os.scandir):
        shared_reads.watch()
        try:
            read(ACTIONS / "absent.bvh")
        except OSError:
            pass
        assert shared_reads.stop() == str(ACTIONS / "absent.bvh")
    shared_reads.watch()
    try:
        os.listdir(SHARED)
    except OSError:
        pass
    assert shared_reads.stop() == str(SHARED)


def test_nothing_is_seen_when_not_watched():
    shared_reads.stop()
    try:
        open(ACTIONS / "absent.bvh")
    except OSError:
        pass
    shared_reads.watch()
    assert shared_reads.stop() is None
