"""Solid body against stick figure: the time to render one clip to an MP4 in each style, at the same size and
through the same camera (a ZeroEGGS-like speaker, 75 joints with fingers, framed from the hips up, front on).
Prints each style's median over repeats and the ratio solid / stick (target: within 2), the solid body rasterised
on a grid of half the frame's resolution (Style.solid_grid = 2, the default) and on every frame pixel (1).

    PYTHONPATH=$PWD python bench/bench_render_solid.py [--size 640] [--frames 150] [--repeats 3] [--grid 2 1]
"""

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from helpers.bvh_fixtures import SPEAKER, write_zeroeggs  # noqa: E402

from generation.data.motion_files import read_motion  # noqa: E402
from generation.own_study.scene import place  # noqa: E402
from rendering.framing import item_camera  # noqa: E402
from rendering.raster import STYLES  # noqa: E402
from rendering.render import RenderOptions, render_clip  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=640)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--grid", type=int, nargs="+", default=[2, 1])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        m = read_motion(write_zeroeggs(Path(tmp) / "take.bvh", args.frames, turns=SPEAKER), fps=30.0)
        joints = place(m.joints, m.names, m.parents)
        clip = dict(joints=joints, parents=m.parents, joint_names=m.names, fps=30.0)
        camera = item_camera([joints], list(m.names), np.asarray(m.parents), 30.0, "front", "upper")
        styles = {"stick": STYLES["stick"]}
        styles.update({f"solid, grid {g}": replace(STYLES["solid"], solid_grid=g) for g in args.grid})
        times = {}
        for _ in range(args.repeats):
            for name, style in styles.items():
                t0 = time.perf_counter()
                options = RenderOptions(args.size, camera, style, threads=1, rate_seed=0)
                render_clip(clip, Path(tmp) / "clip.mp4", options)
                times.setdefault(name, []).append(time.perf_counter() - t0)
    median = {name: float(np.median(t)) for name, t in times.items()}
    print(f"{args.frames} frames at {args.size}x{args.size}, load {os.getloadavg()[0]:.1f}")
    for name, t in median.items():
        print(f"{name} {t:.2f} s: / stick = {t / median['stick']:.2f}")


if __name__ == "__main__":
    main()
