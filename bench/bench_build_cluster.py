"""Benchmark of rendering on a Dask cluster (issue 65 target: the engine's overhead over local processes <= 10% on
2 cores): one study built with two local render processes and on a cluster of two Dask workers on this machine,
alternately, each a whole `make_stimuli --study` from nothing in a fresh process.

    python bench/bench_build_cluster.py [--items 8] [--size 160] [--repeat 2]
"""

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from generation.own_study import demo_study  # noqa: E402


def build(study, out, size, *extra):
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out), "--quiet"]
    t0 = time.perf_counter()
    subprocess.run([*cmd, "--size", str(size), *extra], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=8)
    ap.add_argument("--size", type=int, default=160)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    procs = [
        subprocess.Popen(["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], **quiet)
    ]
    time.sleep(3)
    worker = ["dask", "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"]
    procs += [subprocess.Popen(worker, **quiet) for _ in range(2)]
    time.sleep(5)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            study = demo_study.build(tmp / "in", args.items)
            local, dask = [], []
            for _ in range(args.repeat):
                local.append(build(study, tmp / "local", args.size, "--workers", "2"))
                dask.append(build(study, tmp / "dask", args.size, "--scheduler", address))
    finally:
        for p in procs:
            os.killpg(p.pid, signal.SIGKILL)
    print(f"load {os.getloadavg()[0]:.1f}")
    print(f"  local, 2 processes   best {min(local):6.1f} s  (baseline)  runs {', '.join(f'{t:.1f}' for t in local)}")
    print(f"  Dask, 2 workers      best {min(dask):6.1f} s  {min(dask) / min(local):.2f}x  runs "
          f"{', '.join(f'{t:.1f}' for t in dask)}")  # fmt: skip


if __name__ == "__main__":
    main()
