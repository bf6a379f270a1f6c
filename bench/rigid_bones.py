"""What putting MG's and FL's poses onto the actor's bones does to every figure (issue 34, item 1).

    python bench/rigid_bones.py [--seeds 2] [--temperature 1.0]

The shipped MG and FL sample every held-out window (valid + test, generation/pretrained/heldout.npz: 192 windows
with their real 10-frame histories) on the same control; each sample is then taken three ways:
- `free`: as sampled;
- `directions` (the shipped rule, generation.rigid.fit_bones): every joint at the actor's bone length along the
  direction the model sampled, from the hips out;
- `legs kept`: the same, with each foot kept where the model put it and the knee bent to reach it (two-bone inverse
  kinematics, generation.rigid.LEGS).
The actor's bone lengths are the means over the window's history (real frames). Printed per model and variant:
the largest bone-length std (mm) and mean-length error (%), each joint's mean jerk over NAT's (the worst joint
named), foot skating over NAT's, the worst category's late stepping over NAT's (medians per window), and the
classifier two-sample test against NAT (generation.c2st; mean and sd over seeds).
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation import c2st, rigid, skeleton  # noqa: E402
from generation.features import to_world  # noqa: E402
from generation.metrics import foot_skating, late_stepping  # noqa: E402
from generation.pretrained import CHECKPOINTS, HELDOUT  # noqa: E402
from generation.sample import load_model, sample_windows  # noqa: E402

P = skeleton.PARENTS


def joint_jerk(world, fps):
    """Mean jerk norm per joint [B, J] of world joints [B, T, J, 3]."""
    return np.linalg.norm(np.diff(world, n=3, axis=1), axis=-1).mean(1) * fps**3


def figures(x, c, nat, labels, lengths, fps):
    j = x.reshape(x.shape[:-1] + (skeleton.N_JOINTS, 3))
    b = np.linalg.norm(j[..., 1:, :] - j[..., P[1:], :], axis=-1)
    world, nat_world = to_world(x, c), to_world(nat, c)
    jerk = joint_jerk(world, fps).mean(0) / joint_jerk(nat_world, fps).mean(0)
    skate = np.median([foot_skating(w, fps) / foot_skating(n, fps) for w, n in zip(world, nat_world)])
    late = {}
    for lab in np.unique(labels):
        k = labels == lab
        late[lab] = np.median([late_stepping(a, fps) / late_stepping(n, fps) for a, n in zip(x[k], nat[k])])
    return dict(
        bone_std_mm=float(b.std(1).max(0).max() * 1000),
        length_err=float(np.abs(b.mean(1) / lengths - 1).max() * 100),
        jerk_max=float(jerk.max()),
        jerk_worst=skeleton.JOINT_NAMES[int(jerk.argmax())],
        jerk=jerk,
        skating=float(skate),
        late_min=float(min(late.values())),
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
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    d = np.load(HELDOUT)
    x, c, h, hc, labels = (
        np.concatenate([d[f"valid_{k}"], d[f"test_{k}"]]) for k in ("x", "c", "hist", "hist_c", "labels")
    )
    fps = float(d["fps"])
    lengths = rigid.bone_lengths(h)
    variants = {
        "free": lambda s: s,
        "directions": lambda s: rigid.fit_bones(s, lengths),
        "legs kept": lambda s: rigid.fit_bones(s, lengths, chains=rigid.LEGS),
    }
    for name, ckpt in (("MG", CHECKPOINTS["mg"]), ("FL", CHECKPOINTS["fl"])):
        model = load_model(ckpt, "cpu")
        rows = {v: [] for v in variants}
        for seed in range(args.seeds):
            s = sample_windows(model, c, h, hc, args.temperature, seed)
            for v, fit in variants.items():
                y = fit(s)
                rows[v].append((figures(y, c, x, labels, lengths, fps), auc(y, c, x, fps)))
        for v, got in rows.items():
            f = got[0][0]
            aucs = np.array([a for _, a in got])
            print(
                f"{name} {v:10s} bone std max {f['bone_std_mm']:6.2f} mm | length err max {f['length_err']:5.1f}% | "
                f"jerk/NAT max {f['jerk_max']:.2f} ({f['jerk_worst']}) | skating/NAT {f['skating']:.2f} | "
                f"late stepping min {f['late_min']:.2f} | C2ST AUC {aucs.mean():.3f} (sd {aucs.std():.3f})"
            )
            print("    jerk/NAT per joint:", " ".join(f"{n}:{r:.2f}" for n, r in zip(skeleton.JOINT_NAMES, f["jerk"])))


if __name__ == "__main__":
    main()
