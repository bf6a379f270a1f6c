"""Data-pipeline benchmarks (issue 2).

    python bench/bench_data.py [--data DIR] [--workers 2] [--skip-baseline]

1. prepare_data over every take in DIR (default: the 1067 Bandai-Namco takes), with a process pool
   of --workers, against the same run with one process (baseline, same run). Target: < 60 s on 2 cores.
2. Parsing a ~10 MB BVH file (real frames repeated) with generation.motion.bvh.read_bvh, against a plain
   line-by-line Python parser of the same MOTION block (baseline). Target: < 1 s.
"""

import argparse
import gzip
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.prepare import default_data_dir, find_takes, prepare  # noqa: E402
from generation.motion.bvh import read_bvh  # noqa: E402


def bench_prepare(data, workers, out_dir, baseline=True):
    rows = []
    for w in [workers, 1] if baseline and workers != 1 else [workers]:
        t, c = time.perf_counter(), cpu_all()
        summary = prepare(data, Path(out_dir) / f"ds_{w}.npz", workers=w, progress=False)
        rows.append((w, time.perf_counter() - t, cpu_all() - c, summary))
    return rows


def make_big_bvh(src, target_bytes, path):
    """A BVH of about target_bytes: the header of `src` and its frames repeated."""
    text = gzip.decompress(Path(src).read_bytes()).decode() if str(src).endswith(".gz") else Path(src).read_text()
    head, _, rest = text.partition("MOTION")
    frames = [line for line in rest.split("\n")[3:] if line.strip()]
    block = "\n".join(frames) + "\n"
    reps = max(1, int(np.ceil(target_bytes / len(block))))
    n = len(frames) * reps
    Path(path).write_text(f"{head}MOTION\nFrames: {n}\nFrame Time: 0.0333333\n" + block * reps)
    return n


def naive_parse(path):
    """Baseline: the usual loop, one float() per token, list of lists -> array."""
    lines = Path(path).read_text().split("\n")
    k = next(i for i, line in enumerate(lines) if line.startswith("Frame Time"))
    return np.array([[float(v) for v in line.split()] for line in lines[k + 1 :] if line.strip()])


def best_of(fn, n=3):
    """Best wall time and best CPU time (this process) of n runs, and the last result."""
    walls, cpus = [], []
    for _ in range(n):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return min(walls), min(cpus), out


def cpu_all():
    """CPU seconds of this process and its finished children (the pool workers)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--skip-baseline", action="store_true")
    args = ap.parse_args()
    data = Path(args.data) if args.data else default_data_dir()
    files = find_takes(data)
    print(f"machine: {os.cpu_count()} cores; load average before: {os.getloadavg()[0]:.2f}")

    with tempfile.TemporaryDirectory() as tmp:
        big = Path(tmp) / "big.bvh"
        frames = make_big_bvh(next(f for f in files if "_walk_" in f.name), 10_000_000, big)
        size = big.stat().st_size
        t_fast, c_fast, b = best_of(lambda: read_bvh(big), 5)
        t_naive, c_naive, m = best_of(lambda: naive_parse(big), 3)
        assert np.array_equal(b.motion, m)
        print(
            f"parse {size / 1e6:.1f} MB BVH ({frames} frames x {b.motion.shape[1]} channels), best of 5/3: "
            f"read_bvh {t_fast:.3f} s wall, {c_fast:.3f} s CPU; line-by-line Python (no checks) "
            f"{t_naive:.3f} s wall, {c_naive:.3f} s CPU; CPU ratio x{c_naive / c_fast:.1f}  [target < 1 s]"
        )

        t, c = time.perf_counter(), time.process_time()
        for f in files:
            read_bvh(f)
        print(
            f"read_bvh of all {len(files)} takes, one process: {time.perf_counter() - t:.2f} s wall, "
            f"{time.process_time() - c:.2f} s CPU"
        )

        for w, secs, cpu, s in bench_prepare(data, args.workers, tmp, baseline=not args.skip_baseline):
            n = s["n_windows"]
            print(
                f"prepare_data, {len(files)} takes, {w} worker(s): {secs:.1f} s wall, {cpu:.1f} s CPU "
                f"(windows train {n['train']}, valid {n['valid']}, test {n['test']})  [target < 60 s]"
            )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
