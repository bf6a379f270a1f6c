"""The motion reader on a long take: its peak resident memory and CPU, against a baseline checkout.

A real BVH take (the PFNN skeleton of ../shared, 120 fps, 31 joints) has its frames repeated to about --mb
megabytes of text; `generation.data.motion_files.read_motion` reads it at 30 fps in a fresh process per run, once with
this checkout and once with --baseline (another checkout, such as a `git worktree` of the commit before), turn
about. Reported: the process's own peak resident memory above what its imports held (VmHWM), and the read's CPU.

    git worktree add /tmp/before HEAD~1
    python bench/bench_read_motion.py --baseline /tmp/before --mb 100 --runs 2
"""

import argparse
import gzip
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from helpers.paths import PFNN  # noqa: E402

TAKE = PFNN / "animations" / "LocomotionFlat04_000.bvh.gz"

MEASURE = """
import re, sys, time
from generation.data.motion_files import read_motion
def peak():
    return int(re.search(r"VmHWM:\\s*(\\d+) kB", open("/proc/self/status").read()).group(1)) * 1024
before, t = peak(), time.process_time()
read_motion(sys.argv[1], 30.0)
print(peak() - before, time.process_time() - t)
"""


def long_take(path: Path, mb: float) -> None:
    head, motion = gzip.open(TAKE, "rt").read().split("MOTION", 1)
    lines = motion.strip().split("\n")
    frames = lines[2:]
    repeat = max(1, int(mb * 1e6) // sum(len(f) + 1 for f in frames))
    with open(path, "w") as f:
        f.write(f"{head}MOTION\nFrames: {len(frames) * repeat}\n{lines[1]}\n")
        for _ in range(repeat):
            f.write("\n".join(frames) + "\n")


def measure(checkout: Path, take: Path) -> tuple[float, float]:
    r = subprocess.run(
        [sys.executable, "-c", MEASURE, str(take)], capture_output=True, text=True, cwd=checkout, check=True
    )
    grown, cpu = r.stdout.split()
    return int(grown) / 2**20, float(cpu)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", type=Path, required=True, help="another checkout to compare with")
    ap.add_argument("--mb", type=float, default=100.0, help="size of the take's text (default 100)")
    ap.add_argument("--runs", type=int, default=2)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        take = Path(tmp) / "long.bvh"
        long_take(take, a.mb)
        size = take.stat().st_size / 2**20
        results = {"this checkout": [], "baseline": []}
        for _ in range(a.runs):
            results["this checkout"].append(measure(ROOT, take))
            results["baseline"].append(measure(a.baseline, take))
    print(f"a {size:.0f} MiB take read at 30 fps, {a.runs} runs each, turn about:")
    for name, runs in results.items():
        mem = statistics.median(m for m, _ in runs)
        cpu = statistics.median(c for _, c in runs)
        print(f"  {name:14s} peak {mem:7.0f} MiB above its imports ({mem / size:.1f}x the file), CPU {cpu:.2f} s")


if __name__ == "__main__":
    main()
