"""Two people against one: the time to render one item's clip to an MP4 with the real interlocutor beside the agent
(and captions), against the agent alone, at the same size and style (target: within 2x).

Two takes of ../shared's Bandai-Namco actions stand face to face (generation.own_study.placing), one fixed camera
frames both from the hips up in the wide frame two people are filmed in (rendering.framing.pair_camera,
PAIR_ASPECT: three times the pixels of the square one-person frame of the same height); the one-person clip is
the agent alone through its own upper-body camera (as a one-person item is built: the body larger in the frame),
and through the pair's camera (the same body, only the second person missing). Each style is timed in turns, for
--repeats rounds in one process; prints the medians, the ratios against both, and the load average beside them.

    PYTHONPATH=$PWD python bench/bench_render_two.py [--size 640] [--frames 150] [--repeats 3]
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from generation.data.motion_files import read_motion  # noqa: E402
from generation.own_study.demo_study import actions_dir  # noqa: E402
from generation.own_study.placing import place_pair  # noqa: E402
from generation.own_study.scene import place  # noqa: E402
from rendering.captions import ROOM, phrases  # noqa: E402
from rendering.framing import PAIR_ASPECT, item_camera, pair_camera  # noqa: E402
from rendering.raster import STYLES  # noqa: E402
from rendering.render import RenderOptions, render_clip  # noqa: E402

WORDS = "so the plan is to cross the old bridge before noon and then we wait for the morning light".split()


def _takes(frames):
    """The first two action takes of at least `frames` frames at 30 fps, as Motion."""
    takes = sorted(actions_dir().glob("*.bvh.gz"))
    found = []
    for take in takes:
        m = read_motion(take, 30.0)
        if len(m.joints) >= frames:
            found.append(m)
        if len(found) == 2:
            return found
    raise SystemExit(f"no two takes of {frames} frames in {actions_dir()}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=640)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    a, b = _takes(args.frames)
    n = args.frames
    names, parents = list(a.names), np.asarray(a.parents)
    alone = place(a.joints[:n], names, parents)
    one_camera = item_camera([alone], names, parents, 30.0, "three-quarter", "upper")
    (agents, partner) = place_pair([a.joints[:n]], names, b.joints[:n], list(b.names))
    people = [(names, parents, None), (list(b.names), b.parents, partner)]
    two_camera, target = pair_camera(agents, people, aspect=PAIR_ASPECT)
    cap_camera, cap_target = pair_camera(agents, people, room=ROOM, aspect=PAIR_ASPECT)
    words = [(0.2 + 0.3 * k, 0.2 + 0.3 * k + 0.25, w, w == "bridge") for k, w in enumerate(WORDS)]
    captions = phrases(words, args.size)
    clip = dict(joints=alone, parents=parents, joint_names=names, fps=30.0)
    pair = dict(joints=agents[0], parents=parents, joint_names=names, fps=30.0)
    other = dict(joints=partner, parents=b.parents, joint_names=list(b.names), fps=30.0)
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "clip.mp4"
        for _ in range(args.repeats):
            for style in ("stick", "solid"):
                s = STYLES[style]
                one = RenderOptions(args.size, one_camera, s, threads=1)
                two = RenderOptions(args.size, two_camera, s, threads=1, target=target, aspect=PAIR_ASPECT)
                cap = RenderOptions(args.size, cap_camera, s, threads=1, target=cap_target, aspect=PAIR_ASPECT)
                runs = {
                    "one": lambda o=one: render_clip(clip, out, o),
                    "one, pair camera": lambda o=two: render_clip(pair, out, o),
                    "two": lambda o=two: render_clip(pair, out, o, partner=other),
                    "two + captions": lambda o=cap: render_clip(pair, out, o, partner=other, captions=captions),
                }
                for name, run in runs.items():
                    t0 = time.perf_counter()
                    run()
                    times.setdefault((style, name), []).append(time.perf_counter() - t0)
    wide = f"{round(PAIR_ASPECT * args.size)}x{args.size}"
    load = os.getloadavg()[0]
    print(f"{n} frames at {args.size}x{args.size} (two people: {wide}), {args.repeats} rounds; load {load:.1f}")
    for style in ("stick", "solid"):
        one = float(np.median(times[(style, "one")]))
        same = float(np.median(times[(style, "one, pair camera")]))
        for name in ("one", "one, pair camera", "two", "two + captions"):
            t = float(np.median(times[(style, name)]))
            print(f"{style:<6} {name:<17} {t:6.2f} s   / one = {t / one:.2f}   / one, pair camera = {t / same:.2f}")


if __name__ == "__main__":
    main()
