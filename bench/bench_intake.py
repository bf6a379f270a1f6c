"""Benchmark of the challenge intake (issue 64 target: a 500-item submission checked in <= 60 s on 2 cores).

A submission of N items (default 500), each a real take (tests/data/bvh/bandai_walk_angry_002: 242 frames at 30 fps,
8 s) under the item's name, in two formats: BVH as the dataset ships it (.bvh.gz) and clip files (.npz). Each run is
the whole command in a fresh process (`python -m generation.challenge.intake`), against the same-run baseline of
the study reader alone reading the same files in a fresh process (what any check must at least do), with the peak
memory of each.

    python bench/bench_intake.py [--items 500] [--repeat 3]
"""

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import wave
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from generation.data.motion_files import read_motion  # noqa: E402
from moglow_eval.core.clip import save_clip  # noqa: E402

TAKE = ROOT / "tests" / "data" / "bvh" / "bandai_walk_angry_002.bvh.gz"
FPS = 30.0
READ_ONLY = """
import sys
from pathlib import Path
from generation.data.motion_files import native_fps, read_motion
for p in sorted(Path(sys.argv[1]).iterdir()):
    read_motion(p, native_fps(p), up="y")
"""


def make_submission(root: Path, n: int):
    """speech/ITEM.wav and two teams of n items each: bvh/ITEM.bvh.gz and clips/ITEM.npz."""
    take = read_motion(TAKE, FPS, up="y")
    seconds = len(take.joints) / FPS
    for sub in ("speech", "teams/bvh", "teams/clips"):
        (root / sub).mkdir(parents=True)
    silence = np.zeros(round(16000 * seconds), np.int16).tobytes()
    for k in range(n):
        item = f"item{k:04d}"
        with wave.open(str(root / "speech" / f"{item}.wav"), "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(16000)
            w.writeframes(silence)
        shutil.copy(TAKE, root / "teams" / "bvh" / f"{item}.bvh.gz")
        save_clip(root / "teams" / "clips" / f"{item}.npz", take.joints, take.parents, take.names, FPS)


def timed(argv):
    """(wall seconds, peak RSS of the child in MB) of one command in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    r = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if r.returncode not in (0,):
        raise SystemExit(f"{argv[2:5]} exited {r.returncode}: {r.stderr[-800:]}")
    return wall, max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--items", type=int, default=500)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} at start; {args.items} items, best of {args.repeat}")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        make_submission(root, args.items)
        for fmt in ("bvh", "clips"):
            team = root / "teams" / fmt
            intake = [sys.executable, "-m", "generation.challenge.intake", "--inputs", str(root / "speech"), "--fps",
                      "30", "--up", "y", "--quiet", "--out", str(root / "out"), str(team)]  # fmt: skip
            reading = [sys.executable, "-c", READ_ONLY, str(team)]
            runs = [(timed(intake), timed(reading)) for _ in range(args.repeat)]
            (t_in, mb_in), (t_rd, mb_rd) = min(r[0] for r in runs), min(r[1] for r in runs)
            print(f"{fmt:5s}: intake {t_in:6.1f} s ({mb_in:.0f} MB peak); the reader alone {t_rd:6.1f} s "
                  f"({mb_rd:.0f} MB); ratio {t_in / t_rd:.2f}")  # fmt: skip
    print(f"load average {os.getloadavg()[0]:.2f} at end")


if __name__ == "__main__":
    main()
