"""Benchmark of clips built once (issue 65, part 1): a resume after a kill at half way renders only the other half,
a rebuild with nothing changed renders nothing, and a condition that joins renders only its own clips.

The study is own_study.demo_study's (real takes of ../shared/data/bandai-namco-actions, two made-up systems, speech
by espeak-ng). Each figure is a whole `python -m generation.make_stimuli --study` in a fresh process, against the
same-run baseline of the full build from nothing.

    python bench/bench_build_once.py [--items 8] [--size 160] [--workers 2]
"""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from generation.own_study import demo_study  # noqa: E402
from generation.stimuli.build_index import BuildIndex  # noqa: E402


def build(study, out, args, *extra):
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out), "--quiet"]
    cmd += ["--size", str(args.size), "--workers", str(args.workers), *extra]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def kill_at_half(study, out, args, n_clips):
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out), "--quiet"]
    cmd += ["--size", str(args.size), "--workers", str(args.workers)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    while proc.poll() is None and len(BuildIndex(out).done) < n_clips // 2:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    return len(BuildIndex(out).done)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=8)
    ap.add_argument("--size", type=int, default=160)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        study = demo_study.build(tmp / "in", args.items)
        full = build(study, tmp / "full", args)
        n = len(BuildIndex(tmp / "full").done)
        again = build(study, tmp / "full", args, "--force")
        done = kill_at_half(study, tmp / "resumed", args, n)
        resume = build(study, tmp / "resumed", args)
        joined = tmp / "in" / "joined"
        joined.mkdir()
        for f in (tmp / "in" / "smooth").glob("*.npy"):  # a system inside the others' frames: SMOOTH's, 0.5 m aside
            np.save(joined / f.name, np.load(f) + np.float32([0.5, 0.0, 0.0]))
        grown = tmp / "in" / "grown.toml"
        grown.write_text(study.read_text().replace('TREMBLE = "tremble"', 'TREMBLE = "tremble"\nJOINED = "joined"'))
        shutil.copytree(tmp / "full", tmp / "grown")
        add = build(grown, tmp / "grown", args, "--force")
        n_grown = len(BuildIndex(tmp / "grown").done)
    load = os.getloadavg()[0]
    print(f"{n} clips at {args.size} px on {args.workers} workers (load {load:.1f})")
    print(f"  full build from nothing      {full:6.1f} s  (baseline)")
    print(f"  rebuild, nothing changed     {again:6.1f} s  {again / full:.2f}x")
    print(f"  resume after a kill at {done}/{n} {resume:6.1f} s  {resume / full:.2f}x  ({n - done} clips rendered)")
    print(f"  a condition joins (+{n_grown - n})     {add:6.1f} s  {add / full:.2f}x")


if __name__ == "__main__":
    main()
