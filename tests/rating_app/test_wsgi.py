"""gunicorn as docs/hosting.md starts it, with `--preload`: the master builds the app once, reading the videos into
its cache, and the workers it forks share those pages. Without `--preload` each worker reads its own copy."""

import time
from pathlib import Path

import pytest
from helpers.fake_stimuli import write_fake_stimuli
from helpers.servers import crowd_env, start_gunicorn, stop, warm_up

from moglow_eval.core.ports import free_port

pytestmark = pytest.mark.full  # servers of several workers, each holding a set of 200 MB
SET_MB = 200


def worker_memory_mb(master):
    """[(resident, private) MiB] of each worker of the gunicorn master `master` (/proc/PID/smaps_rollup)."""
    workers = Path(f"/proc/{master}/task/{master}/children").read_text().split()
    out = []
    for pid in workers:
        lines = Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:]
        kb = {line.split(":")[0]: int(line.split()[1]) for line in lines}
        out.append((kb["Rss"] / 1024, (kb["Private_Clean"] + kb["Private_Dirty"]) / 1024))
    return out


def all_workers_hold(master, workers, size, own, timeout_s=120.0):
    """The workers' memory once `workers` of them run and each holds `size` MiB, in its resident memory, or (`own`)
    in its private memory: gunicorn starts them one after another, and one answers a request while the next still
    reads its videos. The last seen at the deadline."""
    deadline = time.monotonic() + timeout_s
    while True:
        held = worker_memory_mb(master)
        if len(held) == workers and all((private if own else rss) >= size for rss, private in held):
            return held
        if time.monotonic() > deadline:
            return held
        time.sleep(0.2)


def test_the_workers_share_the_videos_the_master_read(tmp_path):
    manifest = write_fake_stimuli(tmp_path / "stimuli", n_items=4)
    videos = sorted((tmp_path / "stimuli" / "videos").glob("*.mp4"))
    for v in videos:  # a set of SET_MB: each video padded (the app reads a video's bytes; only its first box is read)
        with open(v, "ab") as f:
            f.write(bytes(SET_MB * 2**20 // len(videos)))
    size = sum(v.stat().st_size for v in videos) / 2**20
    held = {}
    for preload in (True, False):
        port, db = free_port(), f"sqlite:///{tmp_path}/r{preload}.sqlite"
        with open(tmp_path / "gunicorn.log", "a") as log:
            proc = start_gunicorn(port, crowd_env(manifest, db, "tok"), log, workers=3, threads=4, preload=preload)
            try:
                warm_up(f"http://127.0.0.1:{port}", 12)
                held[preload] = all_workers_hold(proc.pid, 3, size, own=not preload)
            finally:
                stop([proc])
    for preload, workers in held.items():
        assert len(workers) == 3, held
        # every worker holds the whole set in its cache (RATING_VIDEO_CACHE_MB: 512 by default) ...
        assert all(rss >= size for rss, _ in workers), (size, held)
    # ... its own copy without --preload, the master's pages with it
    assert all(private >= size for _, private in held[False]), (size, held)
    assert all(private < size / 2 for _, private in held[True]), (size, held)
