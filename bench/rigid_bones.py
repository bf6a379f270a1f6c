"""What putting MG's and FL's poses onto the actor's bones does to every figure (issue 34, item 1).

    python bench/rigid_bones.py [--seeds 2] [--temperature 1.0] [--mg CKPT] [--fl CKPT] [--only MG|FL]

The shipped MG and FL sample every held-out window (valid + test, generation/pretrained/heldout.npz: 192 windows
with their real 10-frame histories) on the same control; each sample is then taken five ways:
- `free`: as sampled;
- `directions`: every joint at the actor's bone length from its placed parent, along the direction from its parent
  that the model sampled (so a bone's length error moves every joint below it);
- `nearest` (rigid.fit_bones): every joint at the actor's bone length from its placed parent, at the point nearest
  to where the model put it;
- `bones`: the hips first put back on the root (their x and z in the root frame set to 0, as in real data), then
  `nearest`: what make_stimuli shipped before 2026-11-26 (`root_hips+rigid_bones`);
- `shipped` (invariants.fit_to_actor): the hips on the root, then the actor's rigid skeleton (rigid.fit_skeleton:
  `nearest`, with the hips' and the chest's children turned into place together in the actor's shape): what
  make_stimuli ships (`root_hips+rigid_skeleton`).
The actor's bone lengths are the means over the window's history (real frames). With --seeds N every window is
sampled N times and its figures are their means over the N samples. Printed per model and variant: the largest
bone-length std (mm), the worst bone's median error of its mean length (%), each joint's mean jerk over NAT's (the
worst joint named), foot skating over NAT's (median over windows), the worst category's median late stepping over
NAT's, the classifier two-sample test against NAT (metrics.c2st; mean and sd over seeds), and the Fréchet motion
distance over the floor (NAT's FMD to training motion of the same categories, generation.metrics.fmd), one
sample per window, as the range over seeds.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.dataset import heldout_windows, read_arrays  # noqa: E402
from generation.metrics import c2st  # noqa: E402
from generation.metrics.fmd import MotionEncoder  # noqa: E402
from generation.metrics.objective import (  # noqa: E402
    foot_skating,
    joint_jerk,
    late_stepping,
)
from generation.motion import invariants, rigid, skeleton  # noqa: E402
from generation.motion.features import to_world  # noqa: E402
from generation.sampling.pretrained import CHECKPOINTS, HELDOUT, MOTION_ENCODER  # noqa: E402
from generation.sampling.sample import load_model, sample_windows  # noqa: E402

P = skeleton.PARENTS


def along_directions(x, lengths):
    """The variant not shipped: each joint along its sampled direction from its parent, at the actor's length."""
    j = x.reshape(x.shape[:-1] + (skeleton.N_JOINTS, 3)).astype(np.float64)
    out = j.copy()
    for k in range(1, skeleton.N_JOINTS):  # parents come before their children in this skeleton
        bone = j[..., k, :] - j[..., P[k], :]
        out[..., k, :] = (
            out[..., P[k], :] + bone / np.linalg.norm(bone, axis=-1, keepdims=True) * lengths[:, None, k - 1, None]
        )
    return out.reshape(x.shape).astype(x.dtype)


def per_window(x, c, nat, lengths, fps):
    """Per-window figures of samples x against NAT on the same windows: bone-length std and mean-length error
    [B, bones], per-joint jerk [B, J], skating and late stepping over NAT's [B]."""
    b = rigid.frame_bone_lengths(x)
    world, nat_world = to_world(x, c), to_world(nat, c)
    return dict(
        bone_std=b.std(1),
        length_err=np.abs(b.mean(1) / lengths - 1),
        jerk=joint_jerk(world, fps),
        skating=np.array([foot_skating(w, fps) / foot_skating(n, fps) for w, n in zip(world, nat_world)]),
        late=np.array([late_stepping(a, fps) / late_stepping(n, fps) for a, n in zip(x, nat)]),
    )


def summary(runs, nat_jerk, labels):
    """The figures over seeds: each window's figures are their means over its samples (as bench/sample_quality.py
    does), then the worst bone, the worst joint's jerk over NAT's, the median skating and the worst category's
    median late stepping."""
    mean = {k: np.mean([r[k] for r in runs], axis=0) for k in runs[0]}
    jerk = mean["jerk"].mean(0) / nat_jerk
    return dict(
        bone_std_mm=float(np.max([r["bone_std"].max() for r in runs]) * 1000),
        length_err=float(np.median(mean["length_err"], axis=0).max() * 100),
        jerk_max=float(jerk.max()),
        jerk_worst=skeleton.JOINT_NAMES[int(jerk.argmax())],
        jerk=jerk,
        skating=float(np.median(mean["skating"])),
        late_min=float(min(np.median(mean["late"][labels == lab]) for lab in np.unique(labels))),
    )


def auc(x, c, nat, fps):
    """The C2ST AUC of the sampled windows against NAT's (folds grouped by window)."""
    ref = {i: c2st.clip_features(to_world(nat[i], c[i]), fps, P) for i in range(len(x))}
    other = {i: c2st.clip_features(to_world(x[i], c[i]), fps, P) for i in range(len(x))}
    return c2st.c2st(ref, other)["auc"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--temperature", type=float, default=1.0)
    ap.add_argument("--mg", default=str(CHECKPOINTS["mg"]), help="MG checkpoint (default: the shipped one)")
    ap.add_argument("--fl", default=str(CHECKPOINTS["fl"]), help="FL checkpoint (default: the shipped one)")
    ap.add_argument("--only", choices=("MG", "FL"), default=None, help="one model only")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    x, c, h, hc, labels = heldout_windows(HELDOUT, ("x", "c", "hist", "hist_c", "labels"))
    fps = float(read_arrays(HELDOUT, ["fps"])["fps"])
    lengths = rigid.bone_lengths(h)
    variants = {
        "free": lambda s: s,
        "directions": lambda s: along_directions(s, lengths),
        "nearest": lambda s: rigid.fit_bones(s, lengths),
        "bones": lambda s: rigid.fit_bones(invariants.root_hips(s), lengths),
        "shipped": lambda s: invariants.fit_to_actor(s, h),
    }
    nat_jerk = joint_jerk(to_world(x, c), fps).mean(0)
    encoder = MotionEncoder.load(MOTION_ENCODER)
    floor = encoder.fmd(x, labels)
    for name, ckpt in (("MG", args.mg), ("FL", args.fl)):
        if args.only not in (None, name):
            continue
        model = load_model(ckpt, "cpu")
        runs, aucs, fmds = ({v: [] for v in variants} for _ in range(3))
        for seed in range(args.seeds):
            s = sample_windows(model, c, h, hc, args.temperature, seed)
            for v, fit in variants.items():
                y = fit(s)
                runs[v].append(per_window(y, c, x, lengths, fps))
                aucs[v].append(auc(y, c, x, fps))
                fmds[v].append(encoder.fmd(y, labels) / floor)
        for v in variants:
            f, a = summary(runs[v], nat_jerk, labels), np.array(aucs[v])
            print(
                f"{name} {v:10s} bone std max {f['bone_std_mm']:6.2f} mm | length err max {f['length_err']:5.1f}%"
                f" | jerk/NAT max {f['jerk_max']:.2f} ({f['jerk_worst']}) | skating/NAT {f['skating']:.3f} | "
                f"late stepping min {f['late_min']:.3f} | C2ST AUC {a.mean():.3f} (sd {a.std():.3f}) | "
                f"FMD/floor {min(fmds[v]):.2f}-{max(fmds[v]):.2f}"
            )
            print("    jerk/NAT per joint:", " ".join(f"{n}:{r:.2f}" for n, r in zip(skeleton.JOINT_NAMES, f["jerk"])))


if __name__ == "__main__":
    main()
