"""What still tells the shipped MG and FL from the mocap, on every held-out window (issue: Realism III).

    python bench/c2st_heldout.py [--seeds 3] [--cnn-seeds 3] [--post shipped|bones|rigid] [--only MG|FL] [--contacts]
        [--temperature NAME=T] [--ckpt NAME=PATH] [--posture] [--ripple]

The shipped MG and FL sample the 192 held-out windows (valid + test, generation/pretrained/heldout.npz) on their
real control and history, at the stimuli's temperatures (MG 0.5, FL 1.0), once per seed; each sample is then
post-processed as the stimuli ship it (`--post shipped`: the hips on the root, then the actor's rigid skeleton,
invariants.fit_to_actor) or as they shipped before (`--post bones`: the hips on the root, then the bone lengths
alone, until 2026-11-26; `--post rigid`: the bone lengths alone, before Realism III). Every classifier below runs in
5 folds grouped by take (a take's windows are never on both sides of a fold), against NAT on the same windows:
- the project's C2ST (generation.metrics.c2st: a logistic regression on per-window statistics of the world
  joints) on all features and per feature group (generation.metrics.c2st_features.GROUPS), and its strongest
  single features;
- the same logistic regression on the root-frame features' own statistics (per dimension its mean and log spread
  over the window: what the independent test read, where the hips' x and z in the root frame told every window);
- a small 1-D CNN (two convolutions, global average pooling) on the standardised root-frame sequences [T, 63],
  trained per fold with `--cnn-seeds` initialisations.
Printed as mean (sd) over the sample seeds, after the floor: NAT's takes split in two at random (`--seeds 0`: the
floor alone). With --posture: per category, the joint whose mean pose sits farthest from NAT's (the first sample
seed). With --ripple: the jerk on even and on odd frames. With --contacts: per locomotion category, the share of
frames with a foot in contact (a foot within 1 cm of its lowest height, objective.foot_contacts' rule without its
fallback), the foot skating (m/s) and how high a slow foot sits above its lowest point (cm) for NAT, MG and FL,
medians over windows.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.dataset import heldout_windows, read_arrays  # noqa: E402
from generation.metrics import c2st  # noqa: E402
from generation.metrics.c2st_features import GROUPS, feature_names, single_aucs  # noqa: E402
from generation.metrics.objective import foot_contacts, foot_skating  # noqa: E402
from generation.motion import invariants, rigid, skeleton  # noqa: E402
from generation.motion.features import to_world  # noqa: E402
from generation.sampling.pretrained import CHECKPOINTS, HELDOUT, TEMPERATURE  # noqa: E402
from generation.sampling.sample import load_model, sample_windows  # noqa: E402

FOLDS = 5
POST = {
    "shipped": invariants.fit_to_actor,
    "bones": lambda x, h: rigid.fit_bones(invariants.root_hips(x), rigid.bone_lengths(h)),
    "rigid": lambda x, h: rigid.fit_bones(x, rigid.bone_lengths(h)),
}


def fold_of(takes, seed=0):
    """Fold [N] of each window: a take's windows share one, takes dealt to FOLDS at random by `seed`."""
    names = np.unique(takes)
    order = dict(zip(names[np.random.default_rng(seed).permutation(len(names))], np.arange(len(names)) % FOLDS))
    return np.array([order[t] for t in takes])


def logistic_auc(x, y, takes, seed=0):
    """Out-of-fold AUC of the project's logistic regression (c2st.grouped_cv) with folds grouped by take."""
    return c2st.grouped_cv(x, y, takes, seed=seed, folds=FOLDS)[0]


def frame_features(x):
    """Per window, each root-frame feature's mean and log spread over the window: [N, 2 * 63], in float64 whatever
    x's precision (a single feature's AUC reads ranks, so log(EPS) in float32 against float64 would tell them apart)."""
    x = np.asarray(x, dtype=np.float64)
    return np.concatenate([x.mean(1), np.log(x.std(1) + c2st.EPS)], axis=1)


class SeqNet(torch.nn.Module):
    """The sequence classifier: two 1-D convolutions over time, global average pooling, one logit."""

    def __init__(self, channels, width=32):
        super().__init__()
        self.net = torch.nn.Sequential(
            torch.nn.Conv1d(channels, width, 5, padding=2),
            torch.nn.ReLU(),
            torch.nn.Conv1d(width, width, 5, padding=2, stride=2),
            torch.nn.ReLU(),
            torch.nn.AdaptiveAvgPool1d(1),
            torch.nn.Flatten(),
            torch.nn.Linear(width, 1),
        )

    def forward(self, x):  # x [B, T, C]
        return self.net(x.transpose(1, 2)).squeeze(-1)


def cnn_auc(seqs, y, takes, seed=0, epochs=60):
    """Out-of-fold AUC of SeqNet on sequences seqs [N, T, C], folds grouped by take (dealt by `seed`); each fold's
    net standardised on and trained on the other folds (Adam, full batches of 64)."""
    fold = fold_of(takes, seed)
    prob = np.empty(len(y))
    for f in range(FOLDS):
        tr, te = fold != f, fold == f
        mu, sd = seqs[tr].mean((0, 1)), seqs[tr].std((0, 1)) + c2st.EPS
        xt = torch.as_tensor((seqs[tr] - mu) / sd, dtype=torch.float32)
        yt = torch.as_tensor(y[tr], dtype=torch.float32)
        torch.manual_seed(seed * 100 + f)
        net = SeqNet(seqs.shape[-1])
        opt = torch.optim.Adam(net.parameters(), 1e-3, weight_decay=1e-4)
        gen = torch.Generator().manual_seed(seed * 100 + f)
        for _ in range(epochs):
            for idx in torch.randperm(len(xt), generator=gen).split(64):
                loss = torch.nn.functional.binary_cross_entropy_with_logits(net(xt[idx]), yt[idx])
                opt.zero_grad()
                loss.backward()
                opt.step()
        with torch.no_grad():
            prob[te] = net(torch.as_tensor((seqs[te] - mu) / sd, dtype=torch.float32)).numpy()
    return c2st.auc(prob, y)


def one_sample(nat, sample, c, takes, names, groups, cnn_seeds):
    """{figure: value} of one sample of every window against NAT: the C2STs of the module doc."""
    fps = 20.0
    feats = [np.array([c2st.clip_features(w, fps, skeleton.PARENTS) for w in to_world(a, c)]) for a in (nat, sample)]
    x, y = np.concatenate(feats), np.r_[np.zeros(len(nat)), np.ones(len(sample))]
    both_takes = np.r_[takes, takes]
    out = {"project C2ST, all features": logistic_auc(x, y, both_takes)}
    for g in GROUPS:
        out[f"  {g}"] = logistic_auc(x[:, np.asarray(groups) == g], y, both_takes)
    single = single_aucs(x, y)
    out["singles"] = {n: float(max(a, 1 - a)) for n, a in zip(names, single) if np.isfinite(a)}
    frames = np.concatenate([frame_features(nat), frame_features(sample)])
    out["root-frame statistics"] = logistic_auc(frames, y, both_takes)
    labels = [f"{j} {a}" for j in skeleton.JOINT_NAMES for a in "xyz"]
    fs = single_aucs(frames, y)
    out["frame singles"] = {
        f"{labels[d % 63]} {'mean' if d < 63 else 'spread'}": float(max(a, 1 - a)) for d, a in enumerate(fs)
    }
    seqs = np.concatenate([nat, sample])
    out["sequence CNN"] = float(np.mean([cnn_auc(seqs, y, both_takes, seed=s) for s in range(cnn_seeds)]))
    return out


def floor(x, c, takes, splits=10):
    """The floor: NAT's takes split at random into two halves, labelled as two conditions; the logistic
    regressions' AUCs (project features, root-frame statistics), mean (sd) over `splits` splits."""
    feats = np.array([c2st.clip_features(w, 20.0, skeleton.PARENTS) for w in to_world(x, c)])
    frames, names = frame_features(x), np.unique(takes)
    aucs = {"project C2ST": [], "root-frame statistics": []}
    for s in range(splits):
        half = set(names[np.random.default_rng(1000 + s).permutation(len(names))[: len(names) // 2]])
        y = np.array([t in half for t in takes], dtype=float)
        aucs["project C2ST"].append(logistic_auc(feats, y, takes, seed=s))
        aucs["root-frame statistics"].append(logistic_auc(frames, y, takes, seed=s))
    words = [f"{k} {np.mean(v):.3f} (sd {np.std(v):.3f})" for k, v in aucs.items()]
    print("NAT split in two by take: " + "; ".join(words))


def report(name, runs):
    """Print a model's figures: mean (sd) over sample seeds, and its strongest single features."""
    print(f"\n{name} ({len(runs)} sample seeds): AUC, mean (sd) over seeds")
    for k in runs[0]:
        if isinstance(runs[0][k], float):
            v = np.array([r[k] for r in runs])
            print(f"| {k} | {v.mean():.3f} | {v.std():.3f} |")
    for key in ("singles", "frame singles"):
        mean = {n: np.mean([r[key][n] for r in runs if n in r[key]]) for n in runs[0][key]}
        top = sorted(mean.items(), key=lambda kv: -kv[1])[:6]
        print(f"  strongest {key}: " + "; ".join(f"{n} {a:.3f}" for n, a in top))


def stance_height(joints, fps=20.0, slow=0.3):
    """Median height (cm) of a foot above its lowest point in the clip over the frames where it moves slower than
    `slow` m/s horizontally (a planted foot, by its own speed): real feet sit on the floor, about 0."""
    heights = []
    for pair in np.asarray(skeleton.FEET).reshape(-1, 2):
        y = joints[:, pair, 1]
        rel = (y - y.min(0)).max(-1)[1:]
        speed = np.linalg.norm(np.diff(joints[:, pair][..., [0, 2]], axis=0), axis=-1).mean(-1) * fps
        heights.append(rel[speed < slow])
    return float(np.median(np.concatenate(heights)) * 100)


def contacts(worlds, labels, fps=20.0):
    """Per category and system, medians over windows: the share of frames with a foot down (no fallback), the foot
    skating, and the height of the slow feet above their lowest point."""
    heads = ("contact share", "skating m/s", "slow foot height cm")
    print("\n| category | n | " + " | ".join(f"{s} {h}" for h in heads for s in worlds) + " |")
    print("|" + "---|" * (2 + len(heads) * len(worlds)))
    for cat in [*np.unique(labels), "all"]:
        idx = np.flatnonzero((labels == cat) | (cat == "all"))
        share = [np.median([foot_contacts(w[i], fallback=0).any(0).mean() for i in idx]) for w in worlds.values()]
        skate = [np.nanmedian([foot_skating(w[i], fps) for i in idx]) for w in worlds.values()]
        lift = [np.median([stance_height(w[i], fps) for i in idx]) for w in worlds.values()]
        print(f"| {cat} | {len(idx)} | " + " | ".join(f"{v:.2f}" for v in share + skate + lift) + " |")


def posture_offsets(samples, nat, labels):
    """Per category and model, the joint whose mean root-frame pose over the category's windows sits farthest from
    NAT's on the same windows (cm), and over all windows: where a posture term on the batch's mean cannot see it."""
    print("\n| category | n | " + " | ".join(f"{m} farthest joint, cm" for m in samples) + " |")
    print("|" + "---|" * (2 + len(samples)))
    for cat in [*np.unique(labels), "all"]:
        idx = np.flatnonzero((labels == cat) | (cat == "all"))
        cells = []
        for s in samples.values():
            gap = (s[idx].mean(1) - nat[idx].mean(1)).mean(0).reshape(skeleton.N_JOINTS, 3)
            dist = np.linalg.norm(gap, axis=-1) * 100
            cells.append(f"{skeleton.JOINT_NAMES[int(dist.argmax())]} {dist.max():.1f}")
        print(f"| {cat} | {len(idx)} | " + " | ".join(cells) + " |")


def ripple(worlds):
    """Each system's mean jerk magnitude (mm per frame^3) on even and on odd frames: a flow that squeezes time in
    pairs of frames (FL) leaves them unequal, where the mocap's are alike."""
    for name, w in worlds.items():
        jerk = np.linalg.norm(np.diff(w, 3, axis=1), axis=-1).mean((0, 2)) * 1000
        print(f"{name}: jerk on even frames {jerk[0::2].mean():.2f}, on odd frames {jerk[1::2].mean():.2f} mm/frame^3")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3, help="samples of every window (one C2ST each; 0: the floor only)")
    ap.add_argument("--cnn-seeds", type=int, default=3, help="initialisations of the CNN per sample")
    ap.add_argument("--post", choices=sorted(POST), default="shipped")
    ap.add_argument("--only", choices=("MG", "FL"), default=None)
    ap.add_argument("--contacts", action="store_true", help="the contact and skating table per category")
    ap.add_argument("--posture", action="store_true", help="per category, the farthest joint of the mean pose")
    ap.add_argument("--ripple", action="store_true", help="the jerk on even and on odd frames")
    ap.add_argument(
        "--temperature",
        action="append",
        default=[],
        metavar="NAME=T",
        help="sample NAME (MG, FL) at T instead of the stimuli's temperature",
    )
    ap.add_argument(
        "--ckpt",
        action="append",
        default=[],
        metavar="NAME=PATH",
        help="sample NAME from this checkpoint instead of the shipped one",
    )
    args = ap.parse_args(argv)
    temps = {**TEMPERATURE, **{k: float(v) for k, v in (a.split("=", 1) for a in args.temperature)}}
    ckpts = {n: CHECKPOINTS[n.lower()] for n in ("MG", "FL")} | dict(a.split("=", 1) for a in args.ckpt)
    torch.set_num_threads(1)
    x, c, h, hc, labels, takes = heldout_windows(HELDOUT, ("x", "c", "hist", "hist_c", "labels", "take"))
    fps = float(read_arrays(HELDOUT, ["fps"])["fps"])
    names, groups = feature_names(skeleton.JOINT_NAMES, skeleton.PARENTS)
    worlds, firsts = {"NAT": to_world(x, c)}, {}
    floor(x, c, takes)
    for name in ("MG", "FL"):
        if args.only not in (None, name):
            continue
        model = load_model(ckpts[name], "cpu")
        runs = []
        for seed in range(args.seeds):
            s = POST[args.post](sample_windows(model, c, h, hc, temps[name], seed), h)
            runs.append(one_sample(x, s, c, takes, names, groups, args.cnn_seeds))
            worlds.setdefault(name, to_world(s, c))
            firsts.setdefault(name, s)
        if runs:
            report(f"{name} ({ckpts[name]}, temperature {temps[name]}), post-processed: {args.post}", runs)
    if args.contacts:
        contacts(worlds, labels, fps)
    if args.posture:
        posture_offsets(firsts, x, labels)
    if args.ripple:
        ripple(worlds)


if __name__ == "__main__":
    main()
