"""How bad each tool-made catch kind is (issue 31): metrics.csv's metrics and the C2ST against the real clips.

    python bench/catch_kinds.py [--fps 20]

On every real take of ../shared/data/bandai-namco-actions (not locomotion: bows, waves, guides, punches, a dance)
with the common 22-joint skeleton: each kind of generation/stimuli/catch_kinds.py is applied to every take, and the
median of each metric over takes is printed as a ratio to the real takes' median (bone-length variation, ~0 for
rigid mocap, in millimetres), how far its poses are from any pose of the take it was made from (about the body's
root, the median over frames of the nearest real pose's mean joint distance, in cm: 0 for poses the take holds
itself), how many takes the kind fails to break visibly (`strays` under VISIBLE: what a study's build then
replaces by its next kind), and the C2ST AUC of the kind's clips against the real ones (folds grouped by take).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from helpers.own_study_data import ACTIONS  # noqa: E402

from generation.data.motion_files import read_motion  # noqa: E402
from generation.metrics import c2st  # noqa: E402
from generation.metrics.objective import (  # noqa: E402
    any_clip_metrics,
    find_feet,
)
from generation.stimuli.catch_kinds import KINDS, VISIBLE, make_catch, strays, unlike_any_pose  # noqa: E402
from moglow_eval.core.skeleton_names import body_root, body_skeleton  # noqa: E402

SHOWN = ("jerk", "acceleration", "foot_skating")  # as multiples of the real takes'; bone-length std in mm


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fps", type=float, default=20.0)
    args = ap.parse_args()
    takes = [read_motion(p, args.fps) for p in sorted(ACTIONS.glob("*.bvh.gz"))]
    common = max({len(m.names) for m in takes}, key=[len(m.names) for m in takes].count)
    takes = [m for m in takes if len(m.names) == common]
    names, parents = takes[0].names, takes[0].parents
    feet, root = find_feet(names), body_root(names, parents)
    clips = {"real": [m.joints for m in takes]}
    clips |= {k: [make_catch(m.joints, k, seed=i, root=root) for i, m in enumerate(takes)] for k in KINDS}
    rows = {k: [any_clip_metrics(j, args.fps, names, parents, feet) for j in js] for k, js in clips.items()}
    med = {k: {m: float(np.median([r[m] for r in rs])) for m in SHOWN} for k, rs in rows.items()}
    body, _, body_parents = body_skeleton(names, parents)  # the C2ST's features, as a study takes them
    at = body.index(root)
    unlike = {
        k: np.median([np.median(unlike_any_pose(j[:, body], m.joints[:, body], at)) for j, m in zip(js, takes)])
        for k, js in clips.items()
    }
    unseen = {k: sum(strays(j, m.joints, root) < VISIBLE for j, m in zip(js, takes)) for k, js in clips.items()}
    feats = {
        k: {i: c2st.clip_features(j[:, body], args.fps, body_parents) for i, j in enumerate(js)}
        for k, js in clips.items()
    }
    print(f"{len(takes)} real action takes, {common} joints, {args.fps:g} fps; medians over takes as x real")
    print(
        f"{'kind':8} "
        + " ".join(f"{m:>16}" for m in SHOWN)
        + "  bone-length std  unlike real  unseen   C2ST AUC vs real"
    )
    for k in clips:
        ratios = " ".join(f"{med[k][m] / med['real'][m]:>15.2f}x" for m in SHOWN)
        bones = np.median([r["bone_length_std"] for r in rows[k]]) * 1000
        auc = c2st.c2st_self(feats["real"])["auc"] if k == "real" else c2st.c2st(feats["real"], feats[k])["auc"]
        floor = " (real split in two: the floor)" if k == "real" else ""
        seen = f"{unseen[k]:>3}/{len(takes)}" if k != "real" else "      "
        print(f"{k:8} {ratios} {bones:>13.2f} mm {unlike[k] * 100:>9.1f} cm  {seen}   {auc:.3f}{floor}")


if __name__ == "__main__":
    main()
