"""A clip's contact sheet: its cost at 640 px, converted at half size as now against at full size as before.

    python bench/bench_contact_sheet.py [--size 640] [--repeats 5] [--core 0]

Renders the real 80-frame walk (4 s at 20 fps) at size x size three ways in turn, pinned to one core with its
ffmpeg child: with no sheet, with a sheet whose 8 frames are converted at full size (rendering.render.SHEET_TILE
set out of reach, the path before), and with the default. Reported: the median CPU time per clip (this process +
ffmpeg) of each, and what the sheet adds to the clip in each way, as a ratio of new to old.
"""

import argparse
import os
import resource
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from generation.motion import skeleton  # noqa: E402
from generation.motion.features import load_take  # noqa: E402
from moglow_eval.core.clip import save_clip  # noqa: E402
from rendering import render  # noqa: E402

WALK = Path(__file__).resolve().parents[1] / "tests" / "data" / "bvh" / "bandai_walk_angry_002.bvh.gz"


def cpu():
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=640)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--core", type=int, default=0)
    args = ap.parse_args()
    os.sched_setaffinity(0, {args.core})
    tile = render.SHEET_TILE
    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(tmp) / "walk.npz"
        save_clip(clip, load_take(WALK, 20.0)[:80], skeleton.PARENTS, skeleton.JOINT_NAMES, 20.0)
        ways = {"no sheet": (tile, False), "full-size sheet": (10**6, True), "half-size sheet": (tile, True)}
        times = {k: [] for k in ways}
        for _ in range(args.repeats):
            for name, (sheet_tile, sheet) in ways.items():
                render.SHEET_TILE = sheet_tile
                opts = render.RenderOptions(size=args.size, rate_seed=0, threads=1)
                start = cpu()
                render.render_clip(clip, Path(tmp) / "w.mp4", opts, sheet=Path(tmp) / "w.png" if sheet else None)
                times[name].append(cpu() - start)
    med = {k: statistics.median(v) for k, v in times.items()}
    for k, v in med.items():
        print(f"{k:16s} {v * 1000:6.0f} ms CPU per clip (median of {args.repeats})")
    old, new = (med[k] - med["no sheet"] for k in ("full-size sheet", "half-size sheet"))
    print(f"the sheet adds {new * 1000:.0f} ms now against {old * 1000:.0f} before: {new / old:.2f}x")


if __name__ == "__main__":
    main()
