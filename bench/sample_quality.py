"""How trained generators move, against the held-out mocap driven by the same control.

    python bench/sample_quality.py --data runs/dataset.npz --model MG=runs/mg_cpu/checkpoints/step_0003000.pt \
        [--model FL=runs/fl_cpu/checkpoints/step_0003000.pt] [--temperature 1.0] [--figure out.png]

Every window of the test split (or --split valid) is sampled once per model (MG seeded with the tau real frames
before the window), or --seeds N times with the seeds --seed .. --seed + N - 1: then each window's figures are
their means over its samples (a category's late stepping rests on 9-25 windows, and one sample per window moves
its worst category by up to 0.1 from seed to seed), and the FMD pools every sample.
Per category it prints the median of three figures per clip:
- late stepping (m): how far the feet swing about each other over the last 2 s (objective.late_stepping;
  a gait that dies out into a standing pose gives ~0). Given beside NAT's, and as the median ratio to NAT on the
  same window.
- jerk (m/s^3), foot skating (m/s) and control following (m): generation.metrics.objective, on the clip in world
  coordinates.
Over all windows it also prints each system's Fréchet motion distance to training motion of the same categories
(generation.metrics.fmd; NAT's is the floor), the medians as ratios to NAT's, and each model's classifier
two-sample test against NAT (generation.metrics.c2st), once per seed, with its spread over seeds, and what tells
each model apart: the test per feature group and its strongest single features (generation.metrics.c2st_features).
The figure shows the feet of the first window of five categories (rows: NAT, then each model).
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.dataset import read_arrays, require  # noqa: E402
from generation.metrics import c2st  # noqa: E402
from generation.metrics.c2st_features import feature_names, feature_report  # noqa: E402
from generation.metrics.fmd import MotionEncoder  # noqa: E402
from generation.metrics.objective import (  # noqa: E402
    control_following,
    foot_skating,
    jerk,
    late_stepping,
)
from generation.models.flows import PRECISIONS  # noqa: E402
from generation.motion import skeleton
from generation.motion.features import to_world  # noqa: E402
from generation.sampling.pretrained import MOTION_ENCODER  # noqa: E402
from generation.sampling.sample import load_model, nonfinite_windows, sample_split  # noqa: E402
from moglow_eval.core.study import NATURAL as NAT  # noqa: E402

FOOT_L, FOOT_R = skeleton.INDEX["Foot_L"], skeleton.INDEX["Foot_R"]
SHOWN = ("walk", "run", "walk_backward", "walk_turn_left", "sidestep_left")


def median_finite(values):
    """Median over the finite values (a diverged model's windows give NaN figures; they are counted apart)."""
    values = np.array(list(values), dtype=np.float64)
    return float(np.median(values[np.isfinite(values)])) if np.isfinite(values).any() else float("nan")


def clip_figures(x, c, fps):
    world = to_world(x, c)
    return dict(
        stepping=late_stepping(x, fps),
        jerk=float(jerk(world, fps)),
        skating=float(foot_skating(world, fps)),
        following=float(control_following(world, c)),
    )


def mean_figures(per_sample):
    """One window's figures (clip_figures dicts, one per sample) -> their means over the finite samples."""
    return {key: _finite_mean([f[key] for f in per_sample]) for key in per_sample[0]}


def window_figures(xs, c, fps):
    """Per window, its figures averaged over its samples: xs holds the windows [N, T, 63] of each seed."""
    return [mean_figures([clip_figures(x[i], c[i], fps) for x in xs]) for i in range(len(c))]


def _finite_mean(values):
    values = np.array(values, dtype=np.float64)
    return float(values[np.isfinite(values)].mean()) if np.isfinite(values).any() else float("nan")


def pooled_fmd(encoder, xs, finite, labels):
    """The FMD of every finite sampled window of every seed together, against training motion of its category."""
    x = np.concatenate([x[f] for x, f in zip(xs, finite)])
    return encoder.fmd(x, np.concatenate([labels[f] for f in finite])) if len(x) else float("nan")


def sample_systems(a, x_nat, n):
    """{name: [windows of each seed]} with NAT first, and {name: [finite window indices of each seed]}."""
    if a.seeds < 1:
        sys.exit(f"--seeds must be at least 1, got {a.seeds}")
    systems = {NAT: [x_nat]}  # per system, one array of windows per seed
    for spec in a.model:
        name, _, ckpt = spec.partition("=")
        model = load_model(ckpt)
        systems[name] = [
            sample_split(model, a.data, a.split, temperature=a.temperature, seed=seed, precision=a.precision)[0]
            for seed in range(a.seed, a.seed + a.seeds)
        ]
    finite = {}  # per system and seed, the windows without NaN or inf
    for name, xs in systems.items():
        finite[name] = [np.setdiff1d(np.arange(len(x)), nonfinite_windows(x)) for x in xs]
        bad = sum(len(x) - len(f) for x, f in zip(xs, finite[name]))
        if bad:
            print(
                f"{name}: {bad} of {len(xs) * n} sampled windows are not finite (NaN or inf); "
                "figures and FMD use the rest"
            )
    return systems, finite


def print_c2st(systems, finite, c, fps):
    """Each model's classifier two-sample test against NAT (generation.metrics.c2st: per-window motion statistics, a
    logistic regression, folds grouped by window), once per seed: the mean AUC and its spread over seeds."""

    def feats(x, idx):
        return {int(i): c2st.clip_features(to_world(x[i], c[i]), fps, skeleton.PARENTS) for i in idx}

    nat = feats(systems[NAT][0], finite[NAT][0])
    print("\nclassifier two-sample test against NAT (AUC: 0.5 = indistinguishable, 1 = always told apart)")
    print("| system | AUC, mean over seeds | sd over seeds | seeds |")
    print("|---|---|---|---|")
    print(f"| NAT split in two | {c2st.c2st_self(nat)['auc']:.3f} | {c2st.c2st_self(nat)['auc_sd']:.3f} | 10 splits |")
    for name, xs in list(systems.items())[1:]:
        aucs = [c2st.c2st(nat, feats(x, f), seeds=1)["auc"] for x, f in zip(xs, finite[name])]
        print(f"| {name} | {np.mean(aucs):.3f} | {np.std(aucs):.3f} | {len(aucs)} |")
    names, groups = feature_names(skeleton.JOINT_NAMES, skeleton.PARENTS)
    for name, xs in list(systems.items())[1:]:
        reports = [feature_report(nat, feats(x, f), names, groups, seeds=1) for x, f in zip(xs, finite[name])]
        print_features(name, reports)


def print_features(name, reports, top=8):
    """What tells a system from NAT (generation.metrics.c2st_features), over seeds: per feature group the AUC of the
    classifier on that group alone, and the `top` single features (direction-free AUC, and which way it differs),
    each as mean (sd) over seeds."""

    def spread(kind):
        values = {}
        for rows in reports:
            for r in rows:
                if r["kind"] == kind:
                    values.setdefault(r["feature"] or r["group"], []).append((r["auc"], r["direction"]))
        return sorted(values.items(), key=lambda kv: -np.mean([a for a, _ in kv[1]]))

    print(f"\n{name}: what tells it from NAT, AUC mean (sd) over seeds")
    print(
        "  groups: "
        + "; ".join(
            f"{g} {np.mean([a for a, _ in v]):.3f} ({np.std([a for a, _ in v]):.3f})" for g, v in spread("group")
        )
    )
    for feature, v in spread("feature")[:top]:
        print(f"  {feature}: {np.mean([a for a, _ in v]):.3f} ({np.std([a for a, _ in v]):.3f}), {v[0][1]} in {name}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="prepared dataset .npz")
    ap.add_argument("--model", action="append", required=True, metavar="NAME=CHECKPOINT")
    ap.add_argument("--temperature", type=float, default=1.0, help="(make_stimuli's default is 1.0)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", type=int, default=1, help="samples per window (seeds --seed, --seed + 1, ...)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument(
        "--precision", default="float32", choices=sorted(PRECISIONS), help="MG's sampler (mg_stream.MGStream)"
    )
    ap.add_argument("--split", default="test", help="held-out split to score: test (default) or valid")
    ap.add_argument("--figure", default=None, help="write the feet figure to this PNG")
    ap.add_argument("--encoder", default=str(MOTION_ENCODER), help="motion encoder for the FMD")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    keys = [f"{a.split}_{k}" for k in ("x", "c", "labels")]
    d = read_arrays(a.data, [*keys, "fps"])
    require(d, [*keys, "fps"], a.data)
    (x_nat, c, labels), fps = (d[k] for k in keys), float(d["fps"])
    systems, finite = sample_systems(a, x_nat, len(c))
    figures = {name: window_figures(xs, c, fps) for name, xs in systems.items()}

    cats = sorted(set(labels.tolist()))
    names = list(systems)
    head = (
        ["category", "n"]
        + [f"{n} stepping" for n in names]
        + [f"{n}/NAT stepping" for n in names[1:]]
        + [f"{n} jerk" for n in names]
        + [f"{n} skating" for n in names]
        + [f"{n} following" for n in names]
    )
    print(f"{a.split} split, temperature {a.temperature}, {a.seeds} sample(s) per window, medians per category")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for cat in cats + ["all"]:
        idx = [i for i in range(len(c)) if cat == "all" or labels[i] == cat]
        med = lambda name, key: median_finite(figures[name][i][key] for i in idx)  # noqa: E731
        ratio = lambda name: median_finite(  # noqa: E731
            figures[name][i]["stepping"] / max(figures[NAT][i]["stepping"], 1e-6) for i in idx
        )
        row = (
            [cat, str(len(idx))]
            + [f"{med(n, 'stepping'):.3f}" for n in names]
            + [f"{ratio(n):.2f}" for n in names[1:]]
            + [f"{med(n, 'jerk'):.0f}" for n in names]
            + [f"{med(n, 'skating'):.2f}" for n in names]
            + [f"{med(n, 'following'):.3f}" for n in names]
        )
        print("| " + " | ".join(row) + " |")

    encoder = MotionEncoder.load(a.encoder)
    fmd = {name: pooled_fmd(encoder, xs, finite[name], labels) for name, xs in systems.items()}
    overall = lambda name, key: median_finite(f[key] for f in figures[name])  # noqa: E731
    print("\nall windows: FMD to training motion of the same categories, and medians as ratios to NAT's")
    print(
        "| system | FMD | FMD / NAT | skating / NAT | jerk / NAT | following (m) "
        "| late stepping / NAT, worst category |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in names:
        worst = min(
            median_finite(
                figures[name][i]["stepping"] / max(figures[NAT][i]["stepping"], 1e-6)
                for i in range(len(c))
                if labels[i] == cat
            )
            for cat in cats
        )
        print(
            f"| {name} | {fmd[name]:.0f} | {fmd[name] / fmd['NAT']:.2f} | "
            f"{overall(name, 'skating') / overall('NAT', 'skating'):.1f} | "
            f"{overall(name, 'jerk') / overall('NAT', 'jerk'):.2f} | {overall(name, 'following'):.3f} | {worst:.2f} |"
        )

    print_c2st(systems, finite, c, fps)

    if a.figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        shown = [cat for cat in SHOWN if cat in cats]
        fig, axes = plt.subplots(
            len(names),
            len(shown),
            figsize=(3.2 * len(shown), 2.1 * len(names)),
            sharex=True,
            sharey=True,
            squeeze=False,
        )
        t = np.arange(x_nat.shape[1]) / fps
        for col, cat in enumerate(shown):
            i = int(np.flatnonzero(labels == cat)[0])
            for row, name in enumerate(names):
                j = systems[name][0][i].reshape(-1, skeleton.N_JOINTS, 3)
                ax = axes[row, col]
                for foot, colour in ((FOOT_L, "tab:blue"), (FOOT_R, "tab:red")):
                    ax.plot(t, j[:, foot, 1], color=colour, lw=1)
                    ax.plot(t, j[:, foot, 2], color=colour, lw=1, ls=":")
                ax.set_title(f"{name}: {cat}", fontsize=8)
                if col == 0:
                    ax.set_ylabel("m (root frame)")
                if row == len(names) - 1:
                    ax.set_xlabel("s")
        axes[0, 0].legend(
            ["left foot height", "left foot forward", "right foot height", "right foot forward"],
            fontsize=6,
            loc="upper left",
        )
        fig.tight_layout()
        fig.savefig(a.figure, dpi=90)
        print(f"figure -> {a.figure}")


if __name__ == "__main__":
    main()
