"""Does a generated window keep the style of its history? (issue 34, item 4)

    python bench/style_retention.py [--seeds 3] [--temperature 1.0] [--start 40] [--mg CKPT] [--fl CKPT] [--only MG]
    python bench/style_retention.py --seed-frames 10 20 40 [--temperature 0.5]

Every held-out window of generation/pretrained/heldout.npz (valid + test: 192 windows of styled Bandai-Namco takes,
proud, old, feminine, ... in the take names) is sampled by the shipped MG (from its 10 real history frames) and FL
(control only), put onto the actor's bones as make_stimuli ships them. generation.metrics.style_retention compares
each window's mean root-frame pose from frame --start on (default 40: the window's second half, from 2 s) with its
own NAT window's and with the average of its category's NAT windows from the other takes. Printed per model: the
share of windows closer to their own NAT (1 = every window keeps its style, 0.5 or below = an average walker), the
median distance ratio (own / average), each as mean and sd over seeds; and the same for NAT's first half against
its second (real motion's own drift: the ceiling) and for the category average itself (the floor).

--seed-frames L ... asks whether a longer real seed would carry more style. The held-out windows of a take overlap
(one every 20 frames), so a window from the take's third on has up to 40 real frames before it. For each L, on the
windows that have L real frames before them, it prints: the mean pose of those L frames held still for the whole
window (what the seed itself says of the style), and MG (with `history_style`) given that mean as its style input
instead of the mean of its 10 history frames, beside MG as trained on the same windows.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation import rigid  # noqa: E402
from generation.dataset import heldout_windows  # noqa: E402
from generation.metrics import style_retention  # noqa: E402
from generation.pretrained import CHECKPOINTS, HELDOUT  # noqa: E402
from generation.sample import load_model, sample_mg, sample_windows  # noqa: E402


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
                kept[label].append(share(rigid.fit_to_history(y, h[idx])))
        print(
            f"{n} real seed frames ({len(idx)} windows): their mean held still {share(held):.2f}; MG T="
            f"{args.temperature} " + ", ".join(f"{k} {np.mean(v):.2f} (sd {np.std(v):.2f})" for k, v in kept.items())
        )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--temperature", type=float, default=1.0)
    ap.add_argument("--start", type=int, default=40)
    ap.add_argument("--mg", default=str(CHECKPOINTS["mg"]), help="MG checkpoint (default: the shipped one)")
    ap.add_argument("--fl", default=str(CHECKPOINTS["fl"]), help="FL checkpoint (default: the shipped one)")
    ap.add_argument("--only", choices=("MG", "FL"), default=None, help="one model only")
    ap.add_argument("--seed-frames", type=int, nargs="+", help="compare longer real seeds (MG with history_style)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    x, c, h, hc, takes, cats, start = heldout_windows(HELDOUT, ("x", "c", "hist", "hist_c", "take", "labels", "start"))
    if args.seed_frames:
        return longer_seeds(args, x, c, h, hc, takes, cats, start)
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
            y = rigid.fit_to_history(sample_windows(model, c, h, hc, args.temperature, seed), h)
            got.append(style_retention(y, x, takes, cats, start=args.start))
        got = np.array(got)
        print(
            f"{name} T={args.temperature}: closer to own {got[:, 0].mean():.2f} (sd {got[:, 0].std():.2f}), "
            f"distance ratio {got[:, 1].mean():.2f} (sd {got[:, 1].std():.2f}) over {len(x)} windows"
        )


if __name__ == "__main__":
    main()
