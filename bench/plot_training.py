"""Training and held-out NLL against steps, from the metrics.csv of one or more training runs.

    python bench/plot_training.py --run MG=runs/mg_cpu/metrics.csv [--run ...] --figure out.png

Two panels (train NLL, valid NLL), one line per run, and a dotted line at the first row where a run's stance-foot
loss is on (its train_stance column turns non-zero). Prints each run's last row.
"""

import argparse
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_metrics(path):
    """{column: list of floats} of a run's metrics.csv (generation.training.train.METRICS_COLUMNS)."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"error: {path}: {e.strerror}")
    if not rows or "valid_nll" not in rows[0]:
        sys.exit(f"error: {path}: not a training run's metrics.csv (no valid_nll column)")
    return {k: [float(r[k]) for r in rows] for k in rows[0]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", action="append", required=True, metavar="NAME=METRICS_CSV")
    ap.add_argument("--figure", required=True)
    a = ap.parse_args()
    runs = {}
    for spec in a.run:
        name, _, path = spec.partition("=")
        runs[name] = read_metrics(path)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharex=True)
    for name, m in runs.items():
        for ax, key in zip(axes, ("train_nll", "valid_nll")):
            (line,) = ax.plot(m["step"], m[key], label=name)
            start = next((s for s, v in zip(m["step"], m["train_stance"]) if v > 0), None)
            if start is not None:
                ax.axvline(start, color=line.get_color(), linestyle=":", linewidth=1)
        print(f"{name}: step {m['step'][-1]:.0f}, train {m['train_nll'][-1]:.3f}, valid {m['valid_nll'][-1]:.3f}")
    for ax, title in zip(axes, ("training NLL (nats/dim)", "valid NLL (nats/dim)")):
        ax.set_xlabel("step")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(a.figure, dpi=110)
    print(f"figure -> {a.figure}")


if __name__ == "__main__":
    main()
