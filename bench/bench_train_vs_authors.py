"""Training speed of mg_cpu against the authors' StyleGestures MoGlow at the same size, side by side.

    python bench/bench_train_vs_authors.py --data dataset.npz --anchor ANCHOR [--rounds 3] [--steps 30]

ANCHOR is the scratch folder that ../shared/anchor_bench/README.md describes (their code unpacked beside
bench_official_train.py; nothing of theirs is copied into the project). Each round runs, in turn and each in a
fresh process with 2 torch threads: their training step at K=8, 2x128 LSTMs, batch 32, 30 frames; ours in
float32; ours with the coupling networks in bfloat16 (train.py's 'precision'). It prints steps/s per round and
the ratios of ours to theirs from the medians, with the load average before every run.
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def steps_per_s(cmd, cwd, pattern):
    out = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=True).stdout
    return float(re.search(pattern, out).group(1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--anchor", required=True, help="folder with the authors' glow/ and bench_official_train.py")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=30)
    a = ap.parse_args()
    data = str(Path(a.data).resolve())
    ours = [sys.executable, str(ROOT / "bench" / "bench_train.py"), "--data", data, "--threads", "2"]
    ours += ["--steps", str(a.steps), "--models", "mg", "--precision"]
    runs = {
        "authors (float32)": (
            [sys.executable, "bench_official_train.py", "8", "128", "32", "30", str(a.steps)],
            a.anchor,
            r"([\d.]+) steps/s",
        ),
        "ours, float32": (ours + ["float32"], ROOT, r"\| mg_cpu \| ([\d.]+) \|"),
        "ours, bfloat16 networks": (ours + ["bfloat16"], ROOT, r"\| mg_cpu \| ([\d.]+) \|"),
    }
    got = {name: [] for name in runs}
    for r in range(a.rounds):
        for name, (cmd, cwd, pattern) in runs.items():
            load = os.getloadavg()[0]
            got[name].append(steps_per_s(cmd, cwd, pattern))
            print(f"round {r + 1}: {name}: {got[name][-1]:.2f} steps/s (load average {load:.2f})", flush=True)
    base = statistics.median(got["authors (float32)"])
    print("\n| code | steps/s per round | median | / authors |\n|---|---|---|---|")
    for name, values in got.items():
        med = statistics.median(values)
        print(f"| {name} | {', '.join(f'{v:.2f}' for v in values)} | {med:.2f} | {med / base:.2f}x |")


if __name__ == "__main__":
    main()
