"""The floor drawn once for a still camera: the drawer's time per frame when each frame starts from a copy of the
floor its look-at point gave the frame before (rendering.raster.FrameDrawer.background), against drawing the
floor's grid every frame, as before, in the same process.

    python bench/bench_floor_reuse.py [--size 640] [--repeats 5]

A real walk from the tests' data (tests/data/bvh), 80 frames at 20 fps, drawn three ways: on the spot (its root
held over one point, as a gesturing speaker's stays) through a study's item camera (rendering.framing.item_camera:
the look-at point still), walking through the default camera that follows the walker (the point moves every frame:
the reuse can only cost its copy there), and two people on the spot in the wide 3:1 frame through one still camera
(the walk and the same walk a metre to the side). Only the
drawing is timed (no encoder): the process's CPU time per frame, the best of --repeats. Each way's frames are
compared byte for byte with the floor drawn every frame.
"""

import argparse
import hashlib
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from generation.motion import skeleton  # noqa: E402
from generation.motion.features import load_take  # noqa: E402
from rendering.camera import DEFAULT_CAMERA, camera_targets  # noqa: E402
from rendering.framing import PAIR_ASPECT, item_camera  # noqa: E402
from rendering.raster import FrameDrawer  # noqa: E402

WALK = ROOT / "tests" / "data" / "bvh" / "bandai_walk_angry_002.bvh.gz"


def frames(drawers, people, targets, reuse):
    """The frames' SHA-256 and the CPU seconds the drawing took; without `reuse`, the floor is drawn every frame."""
    digest, spent = hashlib.sha256(), 0.0
    for t, target in enumerate(targets):
        if not reuse:
            drawers[0].floor_at = drawers[0].last_at = None  # no floor kept: the grid drawn again, as before
        t0 = time.process_time()
        drawers[0].background(target)
        for d, joints in zip(drawers, people):
            frame = d.add_figure(joints[t], target)
        spent += time.process_time() - t0
        digest.update(frame)
    return digest.hexdigest(), spent


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=640)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    walk = load_take(WALK, 20.0)[:80].astype(np.float64)
    names, parents = skeleton.JOINT_NAMES, skeleton.PARENTS
    in_place = walk - (walk[:, :1] - walk[:1, :1]) * np.array([1.0, 0.0, 1.0])  # the root held over one spot
    still = item_camera([in_place], names, parents, 20.0)
    beside = in_place + np.array([1.0, 0.0, 0.0])
    pair = item_camera([in_place, beside], names, parents, 20.0, aspect=PAIR_ASPECT)
    wide = (round(PAIR_ASPECT * args.size) // 2 * 2, args.size)
    ways = {
        "still camera": (still, [in_place], args.size),
        "following camera": (DEFAULT_CAMERA, [walk], args.size),
        "two people, still": (pair, [in_place, beside], wide),
    }
    print(f"{len(walk)} frames at {args.size} px high, best of {args.repeats}; load {os.getloadavg()[0]:.1f}")
    for name, (camera, people, size) in ways.items():
        targets = camera_targets(people[0], 20.0, camera)
        best = {}
        for _ in range(args.repeats):
            for reuse in (False, True):
                first = FrameDrawer(parents, names, size, camera)
                drawers = [first] + [FrameDrawer(parents, names, size, camera, frame=first.frame) for _ in people[1:]]
                got, cpu = frames(drawers, people, targets, reuse)
                best[reuse] = min(best.get(reuse, cpu), cpu)
                assert got == best.setdefault(("bytes", reuse), got)
        assert best[("bytes", True)] == best[("bytes", False)], f"{name}: the frames differ"
        still_points = int((np.abs(np.diff(targets, axis=0)).max(1) == 0).sum())
        per = {k: 1000 * best[k] / len(targets) for k in (False, True)}
        print(
            f"{name:<18} {per[False]:6.2f} ms a frame drawn every time, {per[True]:6.2f} reused: "
            f"{per[True] / per[False]:.2f}x, the same bytes ({still_points} of {len(targets) - 1} frames from the "
            "point before)"
        )


if __name__ == "__main__":
    main()
