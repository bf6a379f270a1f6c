"""Does a model move worse on held-out takes than on the takes it was trained on? Per category.

    python bench/train_vs_heldout.py --data runs/dataset.npz --model generation/pretrained/mg.pt \
        [--per-category 40] [--figure bench/figures/train_vs_heldout.png]

For each category it samples up to --per-category windows of the training split (unaugmented ones only, drawn at
random with a fixed seed) and of the test split, and gives each clip's foot skating and jerk as the median ratio
to the real motion of the same windows. Both splits are treated alike: the first tau frames of each window are
the history (and are not scored), and MG generates the remaining frames on the window's control. FL, which has
no history, makes the whole window and loses its first tau frames alike. A model that
skates on held-out takes of a category but not on its training takes generalises poorly there, which more training
steps will not fix.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sample_quality import clip_figures, median_finite  # noqa: E402  (bench/, this script's folder)

from generation.data.dataset import read_arrays, require  # noqa: E402
from generation.sampling.sample import load_model, sample_windows  # noqa: E402

SPLITS = ("train", "test")


def compare(model, d, split, cat, n, seed):
    """-> dict(n windows, skating and jerk as ratios to real, generated skating in m/s), medians over the windows of
    one category."""
    labels, aug = d[f"{split}_labels"], d[f"{split}_aug"]
    idx = np.flatnonzero((labels == cat) & (aug == 0))
    idx = np.sort(np.random.default_rng(seed).permutation(idx)[:n])
    tau = int(d["tau"])
    x, c = d[f"{split}_x"][idx], d[f"{split}_c"][idx]
    if model.kind == "mg":
        gen = sample_windows(model, c[:, tau:], x[:, :tau], c[:, :tau], 1.0, seed)
    else:  # FL makes whole windows from the control alone; its first tau frames are dropped alike
        gen = sample_windows(model, c, temperature=1.0, seed=seed)[:, tau:]
    real = [clip_figures(x[i, tau:], c[i, tau:], float(d["fps"])) for i in range(len(idx))]
    fake = [clip_figures(gen[i], c[i, tau:], float(d["fps"])) for i in range(len(idx))]
    med = lambda figs, key: median_finite(f[key] for f in figs)  # noqa: E731
    return dict(
        n=len(idx),
        skating=med(fake, "skating") / med(real, "skating"),
        jerk=med(fake, "jerk") / med(real, "jerk"),
        skating_ms=med(fake, "skating"),
    )


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cats = list(rows)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=False)
    for ax, key, name, target in ((axes[0], "skating", "foot skating / real", 3), (axes[1], "jerk", "jerk / real", 2)):
        for j, split in enumerate(SPLITS):
            vals = [rows[cat][split][key] for cat in cats]
            ax.bar(np.arange(len(cats)) + (j - 0.5) * 0.4, vals, 0.4, label=f"{split} takes")
        ax.axhline(target, color="k", lw=0.8, ls="--", label=f"target {target}x")
        ax.set_xticks(np.arange(len(cats)), [cat.replace("_", "\n") for cat in cats], fontsize=7)
        ax.set_title(name)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="prepared dataset .npz")
    ap.add_argument("--model", required=True, help="checkpoint")
    ap.add_argument("--per-category", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--figure", default=None, help="write a bar chart to this PNG")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    keys = [f"{s}_{k}" for s in SPLITS for k in ("x", "c", "labels", "aug")] + ["tau", "fps"]
    d = read_arrays(a.data, keys)
    require(d, keys, a.data)
    model = load_model(a.model)
    # Categories with unaugmented windows in both splits.
    cats = sorted(set(d["test_labels"].tolist()) & set(d["train_labels"][d["train_aug"] == 0].tolist()))
    train_share = {cat: float(np.mean(d["train_labels"] == cat)) for cat in cats}
    test_share = {cat: float(np.mean(d["test_labels"] == cat)) for cat in cats}
    rows = {cat: {s: compare(model, d, s, cat, a.per_category, a.seed) for s in SPLITS} for cat in cats}
    print(f"{a.model}: medians per category as ratios to the real motion of the same windows")
    print(
        "| category | share of training windows | share of test windows | skating, training takes "
        "| skating, held-out takes | jerk, training takes | jerk, held-out takes | generated skating (m/s), "
        "training / held-out |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for cat in cats:
        tr, te = rows[cat]["train"], rows[cat]["test"]
        print(
            f"| {cat} | {train_share[cat]:.1%} | {test_share[cat]:.0%} | {tr['skating']:.1f}x (n={tr['n']}) | "
            f"{te['skating']:.1f}x (n={te['n']}) | {tr['jerk']:.2f}x | {te['jerk']:.2f}x | "
            f"{tr['skating_ms']:.3f} / {te['skating_ms']:.3f} |"
        )
    if a.figure:
        plot(rows, a.figure)
        print(f"wrote {a.figure}")


if __name__ == "__main__":
    main()
