"""MG sampling speed at the paper's size (K=16 steps, 2x512 LSTMs, tau=10): ms per generated frame.

    python bench/bench_sampling.py [--frames 60] [--threads 2] [--block 4]

Compares the streaming sampler (generation.models.mg_stream.MGStream: fused weights, every product known at the start
of a frame done for all K steps in batched matmuls, no autograd) in both of its memory layouts ("row" and
"col", timed frame by frame in turn so that both see the same machine) and the one `default_layout` chooses,
with a plain baseline measured in the same run (tests/reference/moglow_naive.py: each coupling's nn.LSTM called per
frame with its carried state, also without autograd), for 1 stream and a batch of 30 streams, and with a
floor measured beside them (the fastest of four matmul forms reading the same number of weights). The samplers
and the floor forms take turns in blocks of frames (one untimed call, then `--block` timed ones), so a change in
the machine's other traffic hits them alike while each still runs warm, as it does when sampling alone.
Beside them: the chosen layout's matrix products alone, in the order the model's dependencies force
(`products_only`: what the model's structure costs above the floor, and the sampler's other work above it); the
chosen layout with precision="bfloat16" (the big products in bfloat16, accumulated in float32) and a bfloat16
floor (the same forms on bfloat16 weights).
Targets: issue 3, <= 12 ms (1) and <= 25 ms (30); issue 15, 30 streams <= 45 ms and <= 1.15x the floor, 1 stream
<= 1.3x the floor.
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
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the plain reference sampler
from reference.moglow_naive import inverse_naive  # noqa: E402

from generation.models.mg_stream import LAYOUTS, MGStream, default_layout  # noqa: E402
from generation.models.moglow import MoGlow  # noqa: E402
from generation.training.config import load_config, model_config  # noqa: E402


def paper_model():
    torch.manual_seed(0)
    model = MoGlow(model_config(load_config("mg", "paper")))
    tau = model.tau
    model(torch.randn(8, tau + 4, 63), torch.randn(8, tau + 4, 3))  # actnorm init
    with torch.no_grad():  # trained-like output layers (zero-initialised ones would be a special case)
        for step in model.flow.layers:
            out = step.layers[2].net.out
            out.weight.normal_(0, 0.01)
    return model.eval()


def time_frames(step_fn, frames, warmup=3):
    return time_interleaved({"": step_fn}, frames, warmup)[""]


def time_interleaved(step_fns, frames, warmup=3, block=1):
    """{name: fn} -> {name: (wall ms, CPU ms)}, medians over about `frames` calls each. The functions take turns
    so that a burst of other tenants' memory traffic hits all of them alike: with block > 1, each turn is one
    untimed call (bringing the function's weights back into cache) and then `block` timed ones."""
    for _ in range(warmup):
        for fn in step_fns.values():
            fn()
    times = {name: ([], []) for name in step_fns}
    for _ in range(max(1, frames // block)):
        for name, fn in step_fns.items():
            if block > 1:
                fn()
            for _ in range(block):
                t, c = time.perf_counter(), time.process_time()
                fn()
                times[name][0].append(time.perf_counter() - t)
                times[name][1].append(time.process_time() - c)
    # wall median, and CPU time median (all threads): with 1 thread on a shared machine the CPU time is the
    # steadier figure, as it leaves out the time the process waited for a core.
    return {name: (1000 * statistics.median(w), 1000 * statistics.median(c)) for name, (w, c) in times.items()}


def floor_forms(n_params, batch, dtype=torch.float32):
    """The memory/compute floor, as functions to time beside the samplers: reading as many weights (and doing as
    many multiply-adds per stream) as one MG frame, in four forms: one wide matmul X @ W, and batched matmuls over
    16 blocks [2048, n / 32768] in the column form W @ X (MGStream's "col" layout), the row form X @ W with the
    weights stored [in, out] (its "row" layout), and X @ W^T. The floor is the fastest of them (`fastest`)."""
    k, rows = 16, 2048
    cols = n_params // (k * rows)
    w = torch.randn(k, rows, cols, dtype=dtype)
    x_row, x_col = torch.randn(k, batch, cols, dtype=dtype), torch.randn(k, cols, batch, dtype=dtype)
    o_row, o_col = torch.empty(k, batch, rows, dtype=dtype), torch.empty(k, rows, batch, dtype=dtype)
    x_wide, w_wide, w_in_out = x_row.permute(1, 0, 2).reshape(batch, -1), w.view(k * cols, rows), w.view(k, cols, rows)
    return {
        "matmul": lambda: x_wide @ w_wide,
        "bmm W@X": lambda: torch.bmm(w, x_col, out=o_col),
        "bmm X@W^T": lambda: torch.bmm(x_row, w.mT, out=o_row),
        "bmm X@W": lambda: torch.bmm(x_row, w_in_out, out=o_row),
    }


def fastest(timed, prefix):
    """(wall ms, CPU ms, form) of the fastest of the timings whose names start with `prefix`."""
    name = min((n for n in timed if n.startswith(prefix)), key=lambda n: timed[n][0])
    return (*timed[name], name[len(prefix) :])


def products_only(stream):
    """One frame of `stream`'s matrix products alone, in the order its dependencies force: the batched products
    at the start of the frame, then per step layer 1's lower-half product, layer 2's input product, the output
    layer and the inverse map; no cells, no coupling. What the sampler takes above this is its elementwise work and
    per-call overhead; what this takes above the floor is the cost of the model's structure. It scribbles on the
    stream's buffers, so give it a stream of its own."""
    mm = stream._mm
    y0 = torch.randn_like(stream._y_first)

    def frame():
        stream._y_first.copy_(y0)  # as the sampler starts from z: the values stay those of a real frame
        stream._frame_start()
        for wx, wih, wo, bo, winv, bn, cells, y, y_a, _, y_next in stream._steps:
            cells[0][0].addmm_(*mm(wx, y_a))
            for layer in range(1, len(cells)):
                cells[layer][0].addmm_(*mm(wih[layer], cells[layer - 1][-1]))
            torch.addmm(bo, *mm(wo, cells[-1][-1]), out=stream.out)
            torch.addmm(bn, *mm(winv, y), out=y_next)

    return frame


BF16, PRODUCTS = "bfloat16", "products only"  # the picked layout with precision="bfloat16"; products_only of it
FLOOR, BF16_FLOOR = "floor ", "bfloat16 floor "  # name prefixes of the floor forms in the timings


def bench(model, batch, frames, block):
    tau = model.tau
    hist, hist_c = torch.randn(batch, tau, 63), torch.randn(batch, tau, 3)
    ctrl = torch.randn(batch, 3)
    gen = torch.Generator().manual_seed(0)
    picked = default_layout(next(model.parameters()).device, batch)
    n_all = sum(p.numel() for p in model.parameters())
    with torch.inference_mode():
        streams = {name: MGStream(model, hist, hist_c, 1.0, gen, layout=name) for name in LAYOUTS}
        streams[BF16] = MGStream(model, hist, hist_c, 1.0, gen, layout=picked, precision="bfloat16")
        fns = {name: (lambda st=st: st.step(ctrl)) for name, st in streams.items()}
        fns[PRODUCTS] = products_only(MGStream(model, hist, hist_c, 1.0, gen, layout=picked))
        fns.update({FLOOR + n: f for n, f in floor_forms(n_all, batch).items()})
        fns.update({BF16_FLOOR + n: f for n, f in floor_forms(n_all, batch, torch.bfloat16).items()})
        timed = time_interleaved(fns, frames, block=block)
        c_all = torch.randn(batch, tau + 1, 3)
        z = torch.randn(batch, 1, 63)
        naive = time_frames(lambda: inverse_naive(model, z, hist, c_all), max(5, frames // 3))
    return timed, naive, picked


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--block", type=int, default=4, help="timed frames per turn (after one untimed)")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    model = paper_model()
    n_lstm = sum(p.numel() for s in model.flow.layers for p in s.layers[2].net.lstm.parameters())
    print(
        f"MG paper size: K={len(model.flow.layers)}, LSTM 2x{model.config['hidden']}, tau={model.tau}; "
        f"LSTM weights {4 * n_lstm / 1e6:.0f} MB; torch threads {a.threads}; load average "
        f"{os.getloadavg()[0]:.1f} (other jobs on the machine inflate the figures)"
    )
    rows = {}
    print(
        "| streams | row ms/frame (wall, CPU) | col ms/frame (wall, CPU) | picked | plain nn.LSTM ms/frame (wall, CPU) "
        "| picked vs plain (wall, CPU) | floor ms/frame (wall, CPU; fastest matmul form reading the same weights) "
        "| picked / floor (wall, CPU) | picked's products only ms/frame (wall) | products / floor, picked / products "
        "(wall) | bfloat16 ms/frame (wall, CPU) | bfloat16 floor ms/frame (wall, CPU) | bfloat16 / its floor (wall) "
        "| bfloat16 / float32 floor (wall) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for batch in (1, 30):
        frames = a.frames if batch == 1 else max(20, a.frames // 2)
        fast, (nm, nc), picked = bench(model, batch, frames, a.block)
        fm, fc = fast[picked]
        lm, lc, form = fastest(fast, FLOOR)
        bm, bc = fast[BF16]
        blm, blc, bform = fastest(fast, BF16_FLOOR)
        pm = fast[PRODUCTS][0]
        rows[batch] = dict(
            layouts={name: dict(ms=w, cpu_ms=c) for name, (w, c) in fast.items() if name in (*LAYOUTS, BF16)},
            products_only_ms=pm,
            picked=picked,
            naive_ms=nm,
            naive_cpu_ms=nc,
            floor_ms=lm,
            floor_cpu_ms=lc,
            floor_form=form,
            bf16_floor_ms=blm,
            bf16_floor_cpu_ms=blc,
            bf16_floor_form=bform,
        )
        print(
            f"| {batch} | {fast['row'][0]:.1f}, {fast['row'][1]:.1f} | {fast['col'][0]:.1f}, {fast['col'][1]:.1f} "
            f"| {picked} | {nm:.1f}, {nc:.1f} | {nm / fm:.2f}x, {nc / fc:.2f}x "
            f"| {lm:.1f}, {lc:.1f} ({form}) | {fm / lm:.2f}, {fc / lc:.2f} | {pm:.1f} | {pm / lm:.2f}, {fm / pm:.2f} "
            f"| {bm:.1f}, {bc:.1f} "
            f"| {blm:.1f}, {blc:.1f} ({bform}) | {bm / blm:.2f} | {bm / lm:.2f} |",
            flush=True,
        )
    if a.json:
        Path(a.json).write_text(json.dumps(dict(rows=rows, threads=a.threads, load=os.getloadavg()), indent=2))


if __name__ == "__main__":
    main()
