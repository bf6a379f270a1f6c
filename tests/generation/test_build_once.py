"""Clips built once (issue 65, part 1): a study's build is a function of its inputs and its seed (clip ids, sound
check names and every byte), each video keyed by what decides its bytes (generation.stimuli.build_index); a build
killed by SIGKILL resumes with no finished clip lost, and a condition that joins renders only its own clips."""

import csv
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from helpers.own_study_data import make_study

from generation.stimuli.build_index import INDEX, BuildIndex, keyed_id

pytestmark = pytest.mark.full  # the real actions in ../shared
ARGS = ["--size", "96", "--length-s", "1.5", "--workers", "2"]


def _build(study, out, *extra):
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out), *ARGS, *extra]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return [line for line in r.stderr.splitlines() if "render: " in line and " of " in line]


def _files(folder):
    """{relative path: SHA-256} of every file of a stimulus folder."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _rows(folder):
    with open(folder / "manifest.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("once")
    study = make_study(root / "in", n_items=3, n_catch=1, audio=True)
    _build(study, root / "a")
    return root, study


def test_two_builds_of_one_study_and_seed_are_the_same_bytes(built):
    root, study = built
    _build(study, root / "b")
    a = _files(root / "a")
    assert a == _files(root / "b")
    assert INDEX in a and any(p.startswith("audio_check/") for p in a)  # the sound check's names too
    # another seed: other ids (and sound-check names), so none can be foretold without the study's seed
    _build(study, root / "c", "--seed", "2")
    ids = {r["clip_id"] for r in _rows(root / "a")}
    assert not ids & {r["clip_id"] for r in _rows(root / "c")}
    assert set((root / "a" / "audio_check").iterdir()) != set((root / "c" / "audio_check").iterdir())


def test_a_killed_build_resumes_to_the_same_bytes(built):
    root, study = built
    out = root / "killed"
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out), *ARGS]
    n_clips = len(_rows(root / "a"))
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    index, deadline = out / INDEX, time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if index.is_file() and len(BuildIndex(out).done) >= n_clips // 2:
            break
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the whole build: the command and its render workers
    proc.wait()
    finished = len(BuildIndex(out).done)
    assert 0 < finished < n_clips and not (out / "manifest.csv").exists()  # no stimulus set meanwhile
    (line,) = [x for x in _build(study, out) if "processes" in x]
    assert f"render: {n_clips - finished} of {n_clips} clips" in line  # only what was not finished
    assert _files(out) == _files(root / "a")


def test_a_condition_that_joins_renders_only_its_clips(built):
    root, study = built
    out = root / "grown"
    shutil.copytree(root / "a", out)
    before = {r["clip_id"]: (out / r["video"]).read_bytes() for r in _rows(out)}
    (root / "in" / "sys_c").mkdir()
    for f in (root / "in" / "sys_a").glob("*.npy"):  # a system whose bodies stay inside the others' frames:
        np.save(root / "in" / "sys_c" / f.name, np.load(f) + np.float32([50.0, 0.0, 0.0]))  # SYS_A's, 0.5 m aside
    grown = root / "in" / "grown.toml"
    grown.write_text(study.read_text().replace('SYS_B = "sys_b"', 'SYS_B = "sys_b"\nSYS_C = "sys_c"'))
    (line,) = [x for x in _build(grown, out, "--force") if "processes" in x]
    rows = _rows(out)
    n_new = sum(r["condition"] == "SYS_C" for r in rows)
    assert n_new and f"render: {n_new} of {len(rows)} clips" in line
    for cid, video in before.items():  # every earlier clip kept, its id and bytes as they were
        (row,) = [r for r in rows if r["clip_id"] == cid]
        assert (out / row["video"]).read_bytes() == video
    for item in {r["item"] for r in rows}:  # the one-size rule holds after the incremental build
        assert len({(out / r["video"]).stat().st_size for r in rows if r["item"] == item}) == 1


def test_a_clip_id_is_drawn_from_the_seed_and_what_the_clip_is():
    taken = set()
    a = keyed_id(1, "NAT\0item01\0test", taken)
    assert a == keyed_id(1, "NAT\0item01\0test", set()) != keyed_id(2, "NAT\0item01\0test", set())
    assert keyed_id(1, "NAT\0item01\0test", taken) != a  # taken: drawn again
    assert "nat" not in keyed_id(1, "x", set(), forbidden=["NAT"])
