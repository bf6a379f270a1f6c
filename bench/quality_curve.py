"""Quality against training steps: every checkpoint of training runs, scored on the test split against NAT.

    python bench/quality_curve.py --data runs/dataset.npz --run MG=runs/mg_cpu --run FL=runs/fl_cpu \
        [--every 1000] [--figure bench/figures/quality_vs_steps.png]

For each checkpoint whose step is a multiple of --every: the medians over the test split of foot skating and jerk
as ratios to NAT's on the same windows, the median control following (m) and the worst category's late stepping
(bench/sample_quality.py's figures), printed as a table and drawn against the step with the targets (skating 3x,
jerk 2x, late stepping 0.9) as lines. Temperature 1, seed 0, as make_stimuli samples; with --seeds N each window is
sampled N times (seeds 0 .. N-1) and its figures are their means (bench/sample_quality.py --seeds).
"""

import argparse
import statistics
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sample_quality import window_figures  # noqa: E402

from generation.data.dataset import read_arrays, require  # noqa: E402
from generation.data.torch_files import load_torch_file  # noqa: E402
from generation.sampling.sample import load_model, sample_split  # noqa: E402
from generation.stimuli.checkpoints import checkpoints_in  # noqa: E402

TARGETS = {"skating": 3.0, "jerk": 2.0, "stepping": 0.9}
LABELS = {
    "skating": "foot skating / NAT's",
    "jerk": "jerk / NAT's",
    "stepping": "late stepping / NAT's, worst category",
}


def score(xs, ref, c, labels, fps):
    """xs: the sampled windows of each seed; ref: NAT's clip_figures per window."""
    figs = window_figures(xs, c, fps)
    med = lambda f, k: statistics.median(v[k] for v in f)  # noqa: E731
    worst = min(
        statistics.median(
            figs[i]["stepping"] / max(ref[i]["stepping"], 1e-6) for i in range(len(c)) if labels[i] == cat
        )
        for cat in set(labels.tolist())
    )
    return dict(
        skating=med(figs, "skating") / med(ref, "skating"),
        jerk=med(figs, "jerk") / med(ref, "jerk"),
        following=med(figs, "following"),
        stepping=worst,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--run", action="append", required=True, metavar="NAME=RUN_DIR")
    ap.add_argument("--every", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seeds", type=int, default=1, help="samples per window (seeds 0 .. N-1)")
    ap.add_argument("--figure", default=None)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    d = read_arrays(a.data, ["test_x", "test_c", "test_labels", "fps"])
    require(d, ["test_x", "test_c", "test_labels", "fps"], a.data)
    nat, c, labels, fps = d["test_x"], d["test_c"], d["test_labels"], float(d["fps"])
    ref = window_figures([nat], c, fps)  # NAT's, once for every checkpoint
    curves = {}
    print(
        "| run | step | valid NLL | skating / NAT | jerk / NAT | following (m) | late stepping / NAT, worst category |"
    )
    print("|---|---|---|---|---|---|---|")
    for spec in a.run:
        name, _, folder = spec.partition("=")
        for ckpt in checkpoints_in(folder):
            model = load_model(ckpt, "cpu")
            if model.step % a.every:
                continue
            xs = [sample_split(model, a.data, "test", temperature=1.0, seed=seed)[0] for seed in range(a.seeds)]
            s = score(xs, ref, c, labels, fps)
            curves.setdefault(name, []).append((model.step, s))
            valid = load_torch_file(ckpt)["valid_nll"]
            print(
                f"| {name} | {model.step} | {valid:.3f} | {s['skating']:.1f} | {s['jerk']:.2f} | "
                f"{s['following']:.3f} | {s['stepping']:.2f} |",
                flush=True,
            )
    if a.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 3, figsize=(13, 3.4))
        for ax, key in zip(axes, TARGETS):
            for name, points in curves.items():
                ax.plot([p[0] for p in points], [p[1][key] for p in points], "o-", label=name)
            ax.axhline(TARGETS[key], color="grey", ls="--", lw=1, label=f"target {TARGETS[key]:g}x")
            ax.set_xscale("log")
            if key != "stepping":
                ax.set_yscale("log")
            ax.set_xlabel("training steps (batches of 32)")
            ax.set_ylabel(LABELS[key])
            ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(a.figure, dpi=90)
        print(f"figure -> {a.figure}")


if __name__ == "__main__":
    main()
