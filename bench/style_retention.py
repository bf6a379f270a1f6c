"""Does a generated window keep the style of its history? (issue 34, item 4)

    python bench/style_retention.py [--seeds 3] [--temperature 1.0] [--start 40] [--mg CKPT] [--fl CKPT] [--only MG]
    python bench/style_retention.py --seed-frames 10 20 40 [--temperature 0.5]
    python bench/style_retention.py --profile [--figure PNG] [--data runs/dataset.npz] [--temperature 0.5]

Every held-out window of generation/pretrained/heldout.npz (valid + test: 192 windows of styled Bandai-Namco takes,
proud, old, feminine, ... in the take names) is sampled by the shipped MG (from its 10 real history frames) and FL
(control only), the hips put on the root and the poses onto the actor's bones as make_stimuli ships them.
objective.style_retention compares each window's mean root-frame pose from frame --start on (default 40: the
window's second half, from 2 s) with its own NAT window's and with the average of its category's NAT windows from
the other takes. Printed per model: the share of windows closer to their own NAT (1 = every window keeps its style,
0.5 or below = an average walker), the median distance ratio (own / average), each as mean and sd over seeds; and
the same for NAT's first half against its second (real motion's own drift: the ceiling) and for the category average
itself (the floor).

--seed-frames L ... asks whether a longer real seed would carry more style. The held-out windows of a take overlap
(one every 20 frames), so a window from the take's third on has up to 40 real frames before it. For each L, on the
windows that have L real frames before them, it prints: the mean pose of those L frames held still for the whole
window (what the seed itself says of the style), and MG (with `history_style`) given that mean as its style input
instead of the mean of its 10 history frames, beside MG as trained on the same windows.

--profile asks when the style is lost, if it is, and how much of it: the same share, each window's mean pose taken
over each second of the window in turn (frames 0-19, 20-39, ...) instead of its second half, for NAT's first half
(the ceiling, against each second), MG, FL and the 10 history frames' mean held still (what MG is told). A model
that forgets its history falls from second to second towards FL's share; one that keeps it stays level. --figure
draws the case issue 34 names, the sad side-steps (head hanging), as the head's pitch over each window: NAT, MG, FL
and the average of the other side-step takes, and every window's head pitch against NAT's. It also prints how
closely each model's per-window posture (head pitch, trunk lean, hand height) follows NAT's: the slope of one on the
other, over every window and, with --data, over the windows whose posture some training window has.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.dataset import heldout_windows, read_arrays  # noqa: E402
from generation.metrics.objective import style_retention  # noqa: E402
from generation.motion import invariants, skeleton  # noqa: E402
from generation.sampling.pretrained import CHECKPOINTS, HELDOUT  # noqa: E402
from generation.sampling.sample import load_model, sample_mg, sample_windows  # noqa: E402


def seed_frames(x, h, takes, start):
    """{(take, frame): root-frame pose} of every real frame the held-out windows and their histories hold."""
    frames = {}
    for i in range(len(x)):
        for k in range(len(x[i])):
            frames.setdefault((takes[i], start[i] + k), x[i, k])
        for k in range(len(h[i])):
            frames.setdefault((takes[i], start[i] - len(h[i]) + k), h[i, k])
    return frames


def longer_seeds(args, x, c, h, hc, takes, cats, start):
    """The --seed-frames comparison (see the module docstring)."""
    frames = seed_frames(x, h, takes, start)
    model = load_model(args.mg, "cpu")
    pool = (x, takes, cats)
    for n in args.seed_frames:
        idx = [i for i in range(len(x)) if all((takes[i], start[i] - j) in frames for j in range(1, n + 1))]
        style = np.stack([np.mean([frames[(takes[i], start[i] - j)] for j in range(1, n + 1)], axis=0) for i in idx])
        held = np.repeat(style[:, None], x.shape[1], axis=1)

        def share(y):
            return style_retention(y, x[idx], takes[idx], cats[idx], start=args.start, reference=pool)[0]

        kept = {"as trained": [], f"style input over {n} frames": []}
        for seed in range(args.seeds):
            for label, s in zip(kept, (None, style)):
                y = sample_mg(model, c[idx], h[idx], hc[idx], args.temperature, seed, style=s)
                kept[label].append(share(invariants.fit_to_actor(y, h[idx])))
        print(
            f"{n} real seed frames ({len(idx)} windows): their mean held still {share(held):.2f}; MG T="
            f"{args.temperature} " + ", ".join(f"{k} {np.mean(v):.2f} (sd {np.std(v):.2f})" for k, v in kept.items())
        )


def lean(poses, top="Head", bottom="Neck"):
    """Degrees the bottom-to-top segment leans forward from vertical, in the root frame, of poses [..., T, 63]:
    Neck to Head (a hanging head: large), or Hips to Neck (a stoop)."""
    j = poses.reshape(poses.shape[:-1] + (skeleton.N_JOINTS, 3))
    bone = j[..., skeleton.INDEX[top], :] - j[..., skeleton.INDEX[bottom], :]
    return np.degrees(np.arctan2(bone[..., 2], bone[..., 1]))


SAD = "_sad_"  # the take names of the case issue 34 names: the sad side-steps, head hanging

STYLE_FEATURES = {  # per window, over its second half: what a styled take does to the posture
    "head pitch (deg)": lambda p: lean(p),
    "trunk lean (deg)": lambda p: lean(p, "Neck", "Hips"),
    "hand height (cm)": lambda p: (
        50 * (p[..., 3 * skeleton.INDEX["Hand_L"] + 1] + p[..., 3 * skeleton.INDEX["Hand_R"] + 1])
    ),
}


def second_half(f, ys, half):
    """A style feature `f` per window, averaged over the windows' second halves and over the samples `ys` (a list
    of [B, T, 63] arrays, one per seed): [B]."""
    return np.mean([f(y[:, half:]).mean(axis=1) for y in ys], axis=0)


def followed(x, ys, half, train=None):
    """{feature: (slope, slope within the training range)}: the least-squares slope of the model's per-window
    feature (mean over seeds) on NAT's, over the windows' second halves (1 follows each take's style, 0 gives
    every window the same), over every window and over those whose NAT value lies within the range of the
    training windows' (`train` [N, T, 63]; NaN without it): a style no training take has, a model cannot know."""
    out = {}
    for name, f in STYLE_FEATURES.items():
        nat, model = second_half(f, [x], half), second_half(f, ys, half)
        inside = np.nan
        if train is not None:
            seen = f(train).mean(axis=1)
            k = (nat >= seen.min()) & (nat <= seen.max())
            inside = float(np.polyfit(nat[k], model[k], 1)[0])
        out[name] = (float(np.polyfit(nat, model, 1)[0]), inside)
    return out


def profile(args, x, c, h, hc, takes, cats):
    """The --profile comparison (see the module docstring): the share per second of the window, and the figure."""
    held = np.repeat(h.mean(axis=1, keepdims=True), x.shape[1], axis=1)
    models = {n: load_model(ckpt, "cpu") for n, ckpt in (("MG", args.mg), ("FL", args.fl))}
    samples = {
        n: [
            invariants.fit_to_actor(sample_windows(m, c, h, hc, args.temperature, seed), h)
            for seed in range(args.seeds)
        ]
        for n, m in models.items()
    }
    second, half = int(read_arrays(HELDOUT, ["fps"])["fps"]), x.shape[1] // 2
    spans = [(a, a + second) for a in range(0, x.shape[1] - second + 1, second)]
    print("share of windows whose mean pose over each second is closer to their own NAT's than to the category's")
    print(f"{'':28s}" + "".join(f"{a // second}-{b // second} s    " for a, b in spans))
    # NAT's first half is compared whole with each second (the ceiling); the others second by second
    rows = {"NAT first half (ceiling)": ([x[:, :half]], False), "history mean held still": ([held], True)}
    rows.update({f"{n} T={args.temperature}": (v, True) for n, v in samples.items()})
    for label, (ys, by_second) in rows.items():
        cells = []
        for a, b in spans:
            got = [style_retention(y[:, a:b] if by_second else y, x[:, a:b], takes, cats)[0] for y in ys]
            cells.append(f"{np.mean(got):.2f}" + (f" ({np.std(got):.2f})" if len(got) > 1 else "       "))
        print(f"{label:28s}" + "  ".join(cells))
    train = None if args.data is None else read_arrays(args.data, ["train_x"])["train_x"]
    for n, ys in samples.items():
        print(
            f"{n}: slope of its per-window posture on NAT's (second halves; 1 = follows each take), every window /"
            " within the training windows' range: "
            + ", ".join(f"{k} {a:.2f} / {b:.2f}" for k, (a, b) in followed(x, ys, half, train).items())
        )
    sad = np.char.find(takes.astype(str), SAD) >= 0
    others = (cats[:, None] == cats[sad][None]).any(axis=1) & ~sad
    pitch = {"NAT": lean(x[sad]), "category average": lean(x[others])}
    pitch.update({n: np.concatenate([lean(y[sad]) for y in v]) for n, v in samples.items()})
    print(
        "head pitch forward over the second half of the sad side-steps' windows (degrees, median): "
        + ", ".join(f"{k} {np.median(v[:, half:]):.0f}" for k, v in pitch.items())
    )
    if args.figure:
        style_figure(args.figure, x, samples, takes, cats, args.temperature, second)


def style_figure(path, x, samples, takes, cats, temperature, fps):
    """The head's pitch over the sad side-step windows: NAT, each MG and FL sample, the category's average."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sad = [t for t in np.unique(takes) if SAD in t]
    fig, axes = plt.subplots(1, len(sad) + 1, figsize=(5 * (len(sad) + 1), 3.8), squeeze=False)
    half = x.shape[1] // 2
    ax = axes[0][-1]
    nat = second_half(lean, [x], half)
    for name, colour in (("MG", "tab:blue"), ("FL", "tab:orange")):
        got = second_half(lean, samples[name], half)
        ax.scatter(nat, got, s=8, c=colour, alpha=0.7, label=f"{name} (slope {np.polyfit(nat, got, 1)[0]:.2f})")
    lim = [min(nat.min(), -20), max(nat.max(), 90)]
    ax.plot(lim, lim, "k:", lw=1, label="follows its take exactly")
    ax.set_xlabel("NAT's head pitch, second half of the window (deg)")
    ax.set_ylabel("the model's, mean over seeds (deg)")
    ax.set_title("every held-out window (192)", fontsize=9)
    ax.legend(fontsize=8)
    seconds = np.arange(x.shape[1]) / fps
    for ax, take in zip(axes[0][:-1], sad):
        idx = np.flatnonzero(takes == take)
        others = (cats == cats[idx[0]]) & (takes != take)
        ax.plot(seconds, lean(x[others]).mean(axis=0), "k--", lw=1, label="category average (other takes)")
        for k, i in enumerate(idx):
            ax.plot(seconds, lean(x[i]), "k", lw=2, label="NAT" if k == 0 else None)
            for name, colour in (("MG", "tab:blue"), ("FL", "tab:orange")):
                for s, y in enumerate(samples[name]):
                    first = k == 0 and s == 0
                    ax.plot(seconds, lean(y[i]), colour, lw=0.8, alpha=0.6, label=name if first else None)
        ax.set_title(f"{take} ({len(idx)} windows)", fontsize=9)
        ax.set_xlabel("seconds after the 10 history frames")
        ax.set_ylim(-20, 100)
    axes[0][0].set_ylabel("head pitch forward (degrees)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(
        f"Does MG keep a hanging head? Sad side-steps, T={temperature}, {len(samples['MG'])} seeds", fontsize=10
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"figure -> {path}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--temperature", type=float, default=1.0)
    ap.add_argument("--start", type=int, default=40)
    ap.add_argument("--mg", default=str(CHECKPOINTS["mg"]), help="MG checkpoint (default: the shipped one)")
    ap.add_argument("--fl", default=str(CHECKPOINTS["fl"]), help="FL checkpoint (default: the shipped one)")
    ap.add_argument("--only", choices=("MG", "FL"), default=None, help="one model only")
    ap.add_argument("--seed-frames", type=int, nargs="+", help="compare longer real seeds (MG with history_style)")
    ap.add_argument("--profile", action="store_true", help="the share second by second (see above)")
    ap.add_argument("--figure", help="with --profile: draw the sad side-steps' head pitch to this PNG")
    ap.add_argument("--data", help="with --profile: the prepared dataset, for the training windows' range")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    x, c, h, hc, takes, cats, start = heldout_windows(HELDOUT, ("x", "c", "hist", "hist_c", "take", "labels", "start"))
    if args.seed_frames:
        return longer_seeds(args, x, c, h, hc, takes, cats, start)
    if args.profile:
        return profile(args, x, c, h, hc, takes, cats)
    # NAT's ceiling: its first half stands in for a sample (the same take, an earlier stretch of it)
    half = x.shape[1] // 2
    ceiling = style_retention(x[:, :half], x, takes, cats, start=0)
    print(f"NAT first half vs second: closer to own {ceiling[0]:.2f}, distance ratio {ceiling[1]:.2f}")
    for name, ckpt in (("MG", args.mg), ("FL", args.fl)):
        if args.only not in (None, name):
            continue
        model = load_model(ckpt, "cpu")
        got = []
        for seed in range(args.seeds):
            y = invariants.fit_to_actor(sample_windows(model, c, h, hc, args.temperature, seed), h)
            got.append(style_retention(y, x, takes, cats, start=args.start))
        got = np.array(got)
        print(
            f"{name} T={args.temperature}: closer to own {got[:, 0].mean():.2f} (sd {got[:, 0].std():.2f}), "
            f"distance ratio {got[:, 1].mean():.2f} (sd {got[:, 1].std():.2f}) over {len(x)} windows"
        )


if __name__ == "__main__":
    main()
