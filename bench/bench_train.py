"""Training speed of the cpu configs (steps/s), and the valid NLL finished runs reached.

    python bench/bench_train.py --data dataset.npz [--steps 20] [--threads N] [--precision P] [--models mg fl]
                                [--runs RUN_DIR ...]

Times `--steps` optimiser steps of mg_cpu and fl_cpu on the real training set (after 2 warm-up steps), as
generation.training.train takes them (its optimiser, the networks in `--precision`);
for every run folder given with --runs (written by generation.training.train) it also reports the steps, wall
time, overall steps/s and the last valid NLL from its metrics.csv.
"""

import argparse
import csv
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.dataset import batch_indices, load_dataset  # noqa: E402
from generation.models.flows import PRECISIONS, set_net_precision  # noqa: E402
from generation.training.train import build_model, load_config, make_optimiser  # noqa: E402


def time_steps(kind, ds, steps, precision="float32"):
    cfg = replace(load_config(kind, "cpu"), precision=precision)
    torch.manual_seed(0)
    net = build_model(kind, cfg, ds.stats).train()
    set_net_precision(net, PRECISIONS[precision])
    opt = make_optimiser(net, cfg)
    tr = ds.splits["train"]
    crop = cfg.train_window or tr.x.shape[1]
    times, cpu = [], []
    for step in range(steps + 2):
        idx = batch_indices(len(tr), cfg.batch_size, 0, step)
        x, c = tr.x[idx, :crop], tr.c[idx, :crop]
        t, t_cpu = time.perf_counter(), time.process_time()
        loss = net.nll(x, c).mean()
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.clip_grad, foreach=True)
        opt.step()
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - t_cpu)
    return 1 / statistics.median(times[2:]), 1 / statistics.median(cpu[2:]), cfg


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--precision", choices=sorted(PRECISIONS), default="float32")
    ap.add_argument("--models", nargs="+", choices=["mg", "fl"], default=["mg", "fl"])
    ap.add_argument("--runs", nargs="*", default=[])
    a = ap.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    ds = load_dataset(a.data)
    print(f"torch threads {torch.get_num_threads()}; {a.precision}; load average {os.getloadavg()[0]:.1f}")
    print("| config | steps/s wall (median of %d) | steps per CPU-second | windows x frames per step |" % a.steps)
    print("|---|---|---|---|")
    for kind in a.models:
        sps, sps_cpu, cfg = time_steps(kind, ds, a.steps, a.precision)
        print(
            f"| {kind}_cpu | {sps:.2f} | {sps_cpu:.2f} | {cfg.batch_size} x {cfg.train_window or ds.window} |",
            flush=True,
        )
    if a.runs:
        print("\n| run | steps | wall min | steps/s | last valid NLL (nats/dim) |\n|---|---|---|---|---|")
        for run in a.runs:
            rows = list(csv.DictReader(open(Path(run) / "metrics.csv")))
            last = rows[-1]
            print(
                f"| {run} | {last['step']} | {float(last['elapsed_s']) / 60:.1f} | "
                f"{int(last['step']) / float(last['elapsed_s']):.2f} | {float(last['valid_nll']):.3f} |"
            )


if __name__ == "__main__":
    main()
