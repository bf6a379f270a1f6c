"""Solid body against stick figure: the time to render one clip to an MP4 in each style, at the same size and
through the same camera (a ZeroEGGS-like speaker, 75 joints with fingers, framed from the hips up, front on).
Prints each style's median over repeats and the ratio solid / stick (target: within 2).

    PYTHONPATH=$PWD python bench/bench_render_solid.py [--size 640] [--frames 150] [--repeats 3]
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from helpers.bvh_fixtures import SPEAKER, write_zeroeggs  # noqa: E402

from generation.data.motion_files import read_motion  # noqa: E402
from generation.own_study.builder import place  # noqa: E402
from rendering.framing import item_camera  # noqa: E402
from rendering.raster import STYLES  # noqa: E402
from rendering.render import render_clip  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=640)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        m = read_motion(write_zeroeggs(Path(tmp) / "take.bvh", args.frames, turns=SPEAKER), fps=30.0)
        joints = place(m.joints, m.names)
        clip = dict(joints=joints, parents=m.parents, joint_names=m.names, fps=30.0)
        camera = item_camera([joints], list(m.names), np.asarray(m.parents), 30.0, "front", "upper")
        times = {}
        for _ in range(args.repeats):
            for name in ("stick", "solid"):
                t0 = time.perf_counter()
                render_clip(clip, Path(tmp) / f"{name}.mp4", args.size, camera, STYLES[name], threads=1, rate_seed=0)
                times.setdefault(name, []).append(time.perf_counter() - t0)
    stick, solid = (float(np.median(times[n])) for n in ("stick", "solid"))
    print(f"{args.frames} frames at {args.size}x{args.size}, load {os.getloadavg()[0]:.1f}")
    print(f"stick {stick:.2f} s, solid {solid:.2f} s: solid / stick = {solid / stick:.2f}")


if __name__ == "__main__":
    main()
