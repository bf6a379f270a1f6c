"""Drawing speed per frame for any skeleton (issue 31): the 21-joint figure against the renderer of a baseline
commit, same run, and a 70-joint figure with fingers and a face.

    python bench/bench_draw_skeletons.py [--baseline 6e978f1] [--size 640] [--rounds 5]

Times FrameDrawer.draw (the rasteriser; the encoder is the same for both) over a real 80-frame walk, in fresh
processes that alternate between the baseline's code (`git archive BASELINE rendering core` into a temporary
folder) and the working tree's, so a drift of the machine's speed hits both alike. Prints the median ms per
frame of each and their ratio per round (the target: the 21-joint figure within 1.2x of the baseline).
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT.parent / "shared/data/bandai-namco-locomotion/dataset-1/data/dataset-1_walk_angry_002.bvh.gz"

# Run in a child: draws every frame `reps` times and prints the best ms per frame as JSON.
CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1]); sys.path.insert(1, sys.argv[2])
import numpy as np
from rendering.raster import FrameDrawer
from rendering.camera import camera_targets
joints, parents, names = (np.load(sys.argv[3], allow_pickle=False)[k] for k in ("joints", "parents", "names"))
d = FrameDrawer(parents, list(names), int(sys.argv[4]))
targets = camera_targets(joints, 20.0)
best = float("inf")
for _ in range(3):
    t0 = time.perf_counter()
    for t in range(len(joints)):
        d.draw(joints[t], targets[t])
    best = min(best, (time.perf_counter() - t0) / len(joints))
print(json.dumps(best * 1000))
"""


def _inputs(tmp):
    """Two .npz inputs: the 21-joint walk, and a 70-joint figure (tests/helpers/own_study_data.py's skeleton)."""
    import numpy as np

    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "tests"))
    from helpers.own_study_data import make_study

    from generation.data.motion_files import read_motion
    from generation.motion import skeleton
    from generation.motion.features import load_take

    walk = load_take(WALK, 20.0)[:80]
    np.savez(tmp / "walk21.npz", joints=walk, parents=skeleton.PARENTS, names=np.array(skeleton.JOINT_NAMES))
    make_study(tmp / "study", n_items=1, n_catch=0)
    m = read_motion(tmp / "study" / "real" / "item00.bvh.gz", 20.0)
    np.savez(tmp / "fingers70.npz", joints=m.joints[:80], parents=m.parents, names=np.array(m.names))
    return tmp / "walk21.npz", tmp / "fingers70.npz"


def _time(code, clip, size):
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(code), str(ROOT), str(clip), str(size)],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", default="6e978f1", help="commit whose renderer is the baseline")
    ap.add_argument("--size", type=int, default=640)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "baseline"
        base.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", args.baseline, "rendering", "core"], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        walk, fingers = _inputs(tmp)
        old, new, big = [], [], []
        for _ in range(args.rounds):
            old.append(_time(base, walk, args.size))
            new.append(_time(ROOT, walk, args.size))
            big.append(_time(ROOT, fingers, args.size))
    ratios = [n / o for n, o in zip(new, old)]
    print(f"draw per frame at {args.size}x{args.size}, median of {args.rounds} rounds (each the best of 3 passes):")
    print(f"  21 joints, baseline {args.baseline}: {statistics.median(old):.2f} ms")
    print(
        f"  21 joints, this tree:        {statistics.median(new):.2f} ms  "
        f"(ratio per round {', '.join(f'{r:.3f}' for r in ratios)}; median {statistics.median(ratios):.3f})"
    )
    print(f"  70 joints (fingers, face):   {statistics.median(big):.2f} ms")


if __name__ == "__main__":
    main()
