"""MG sampling speed at the paper's size (K=16 steps, 2x512 LSTMs, tau=10): ms per generated frame.

    python bench/bench_sampling.py [--frames 60] [--threads 2]

Compares the streaming sampler (generation.moglow.MGStream: fused weights, the history/control part of
every coupling LSTM's gates for all K steps in one matmul, no autograd) with a plain baseline measured in
the same run (MoGlow.inverse_naive: each coupling's nn.LSTM called per frame with its carried state, also
without autograd), for 1 stream and a batch of 30 streams. Targets (issue 3): <= 12 ms (1) and <= 25 ms (30).
"""
import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.moglow import MGStream, MoGlow  # noqa: E402
from generation.train import load_config, model_config  # noqa: E402


def paper_model():
    torch.manual_seed(0)
    model = MoGlow(model_config("mg", load_config("mg", "paper")))
    tau = model.tau
    model(torch.randn(8, tau + 4, 63), torch.randn(8, tau + 4, 3))  # actnorm init
    with torch.no_grad():  # trained-like output layers (zero-initialised ones would be a special case)
        for step in model.flow.layers:
            out = step.layers[2].net.out
            out.weight.normal_(0, 0.01)
    return model.eval()


def time_frames(step_fn, frames, warmup=3):
    for _ in range(warmup):
        step_fn()
    times, cpu = [], []
    for _ in range(frames):
        t, c = time.perf_counter(), time.process_time()
        step_fn()
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    # wall median, and CPU time median (all threads): with 1 thread on a shared machine the CPU time is the
    # steadier figure, as it leaves out the time the process waited for a core.
    return 1000 * statistics.median(times), 1000 * statistics.median(cpu)


def floor(n_params, batch, frames):
    """The memory/compute floor measured here and now: one matmul that reads as many weights (and does as
    many multiply-adds per stream) as one MG frame, so contention from other jobs hits it the same way."""
    w = torch.randn(4096, n_params // 4096)
    x = torch.randn(batch, 4096)
    with torch.inference_mode():
        return time_frames(lambda: x @ w, frames)


def bench(model, batch, frames):
    tau = model.tau
    hist, hist_c = torch.randn(batch, tau, 63), torch.randn(batch, tau, 3)
    ctrl = torch.randn(batch, 3)
    gen = torch.Generator().manual_seed(0)
    with torch.inference_mode():
        stream = MGStream(model, hist, hist_c, 1.0, gen)
        fast = time_frames(lambda: stream.step(ctrl), frames)
        c_all = torch.randn(batch, tau + 1, 3)
        z = torch.randn(batch, 1, 63)
        naive = time_frames(lambda: model.inverse_naive(z, hist, c_all), max(5, frames // 3))
    return fast, naive


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    model = paper_model()
    n_lstm = sum(p.numel() for s in model.flow.layers for p in s.layers[2].net.lstm.parameters())
    print(f"MG paper size: K={len(model.flow.layers)}, LSTM 2x{model.config['hidden']}, tau={model.tau}; "
          f"LSTM weights {4 * n_lstm / 1e6:.0f} MB; torch threads {a.threads}; load average "
          f"{os.getloadavg()[0]:.1f} (other jobs on the machine inflate the figures)")
    rows = {}
    n_all = sum(p.numel() for p in model.parameters())
    print("| streams | fast ms/frame (wall, CPU) | plain nn.LSTM ms/frame (wall, CPU) | speed-up vs plain (wall, CPU) "
          "| floor ms/frame (wall, CPU; one matmul, same weights) | fast / floor (wall, CPU) |")
    print("|---|---|---|---|---|---|")
    for batch in (1, 30):
        frames = a.frames if batch == 1 else max(20, a.frames // 2)
        (fm, fc), (nm, nc) = bench(model, batch, frames)
        lm, lc = floor(n_all, batch, frames)
        rows[batch] = dict(fast_ms=fm, fast_cpu_ms=fc, naive_ms=nm, naive_cpu_ms=nc, floor_ms=lm, floor_cpu_ms=lc)
        print(f"| {batch} | {fm:.1f}, {fc:.1f} | {nm:.1f}, {nc:.1f} | {nm / fm:.2f}x, {nc / fc:.2f}x | {lm:.1f}, {lc:.1f} "
              f"| {fm / lm:.2f}, {fc / lc:.2f} |", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(dict(rows=rows, threads=a.threads, load=os.getloadavg()), indent=2))


if __name__ == "__main__":
    main()
