"""Rendering spread over machines (issue 65, part 2): a study built on a Dask cluster of two workers (a scheduler
and two worker processes on this machine, as on others) is the same bytes as a local build, and a worker killed
mid-build has its clips run again on the other (generation.stimuli.cluster)."""

import hashlib
import os
import signal
import subprocess
import sys
import time

import pytest
from helpers.own_study_data import make_study

from generation.stimuli.build_index import BuildIndex
from moglow_eval.core.ports import free_port

pytestmark = pytest.mark.full  # the real actions in ../shared
ARGS = ["--size", "96", "--length-s", "1.5", "--quiet"]


def _files(folder):
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*"))
            if p.is_file()}  # fmt: skip


@pytest.fixture
def cluster(tmp_path):
    """(scheduler address, [worker processes]): `dask scheduler` and two `dask worker`s, each a process group."""
    address = f"tcp://127.0.0.1:{free_port()}"
    started = []

    def start(*cmd, log):
        started.append(subprocess.Popen(cmd, stdout=open(log, "w"), stderr=subprocess.STDOUT, start_new_session=True))
        return started[-1]

    start("dask", "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1], "--no-dashboard",
          log=tmp_path / "scheduler.log")  # fmt: skip
    workers = [
        start(
            "dask",
            "worker",
            address,
            "--nworkers",
            "1",
            "--nthreads",
            "1",
            "--no-dashboard",
            "--name",
            f"w{i}",
            log=tmp_path / f"worker{i}.log",
        )  # fmt: skip
        for i in (1, 2)
    ]
    yield address, workers
    for p in started:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()


def test_a_cluster_build_is_a_local_builds_bytes_and_survives_a_lost_worker(tmp_path, cluster):
    address, workers = cluster
    study = make_study(tmp_path / "in", n_items=3, n_catch=1, audio=True)
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), *ARGS]
    subprocess.run([*cmd, "--out", str(tmp_path / "local"), "--workers", "2"], check=True, timeout=600)
    n_clips = len(BuildIndex(tmp_path / "local").done)
    out = tmp_path / "cluster"
    build = subprocess.Popen([*cmd, "--out", str(out), "--scheduler", address], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while build.poll() is None and time.monotonic() < deadline and len(BuildIndex(out).done) < 3:
        time.sleep(0.05)
    os.killpg(workers[0].pid, signal.SIGKILL)  # a worker lost mid-build: its clip runs again on the other
    _, err = build.communicate(timeout=600)
    assert build.returncode == 0, err[-2000:]
    assert 3 <= n_clips and _files(out) == _files(tmp_path / "local")


def test_no_scheduler_there_is_one_line(tmp_path, capsys):
    from generation.make_stimuli import main

    study = make_study(tmp_path / "in", n_items=2, n_catch=1)
    out = tmp_path / "out"
    code = main(["--study", str(study), "--out", str(out), *ARGS, "--scheduler", f"tcp://127.0.0.1:{free_port()}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and "no Dask scheduler answers there" in err[-1] and "Traceback" not in "\n".join(err)
