"""Training speed alone and beside a busy core (issue 15, item 6): how gracefully mg_cpu training degrades.

    python bench/bench_train_load.py --data runs/dataset.npz [--seconds 20] [--kind mg]

Each setting runs in a fresh process (OpenMP reads its environment when torch loads) for --seconds of
training steps at mg_cpu's size on the real training set, first alone, then beside a process that keeps one
core busy (a Python busy loop). Settings: torch's defaults (all cores, OpenMP's default spin-waiting), all cores
with OpenMP's waiting threads sleeping at once (OMP_WAIT_POLICY=PASSIVE) or after a bounded spin (GOMP_SPINCOUNT,
libgomp's), one thread, and the CLI's default, the cores other processes leave free (generation/training/threads.py).
Prints steps/s and each setting's slowdown beside the busy core; run it with nothing else on the machine.
"""

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = {
    "torch defaults (2 threads, spinning)": {"threads": None},
    "2 threads, OMP_WAIT_POLICY=PASSIVE": {"OMP_WAIT_POLICY": "PASSIVE", "threads": None},
    "2 threads, GOMP_SPINCOUNT=10000": {"GOMP_SPINCOUNT": "10000", "threads": None},
    "2 threads, GOMP_SPINCOUNT=100000": {"GOMP_SPINCOUNT": "100000", "threads": None},
    "1 thread": {"threads": "1"},
    "auto: the free cores (the CLI default)": {"threads": "auto"},
}
OMP_ENV = ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")

WORKER = """
import sys, time, torch
sys.path.insert(0, {root!r})
share = None
if {threads!r} == "auto":
    from generation.training.threads import CoreShare
    share = CoreShare()
elif {threads!r}:
    torch.set_num_threads(int({threads!r}))
from generation.data.dataset import load_dataset
from generation.training.train import build_model, draw_batch, load_config
ds = load_dataset({data!r})
cfg = load_config({kind!r}, "cpu")
torch.manual_seed(0)
net = build_model({kind!r}, cfg, ds.stats).train()
opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
tr = ds.splits["train"]
crop = cfg.train_window or tr.x.shape[1]
step, start = 0, None
while True:
    if step == 3:
        start = time.perf_counter()
    if share is not None:
        share.step()
    x, c, keep, history, _ = draw_batch(net, tr.x, tr.c, cfg, 0, step, crop)
    loss = net.nll(x, c, keep, history).mean()
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.clip_grad)
    opt.step()
    step += 1
    if start is not None and time.perf_counter() - start > {seconds}:
        break
print((step - 3) / (time.perf_counter() - start))
"""


def steps_per_second(setting, args):
    env = {k: v for k, v in os.environ.items() if k not in OMP_ENV}
    env.update({k: setting[k] for k in OMP_ENV if k in setting})
    code = WORKER.format(
        root=str(ROOT), threads=setting["threads"], data=args.data, kind=args.kind, seconds=args.seconds
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--kind", default="mg", choices=["mg", "fl"])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--only", nargs="*", help="run only the settings whose names contain one of these words")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f}; {args.kind}_cpu, {args.seconds:g} s per figure")
    print("| setting | alone (steps/s) | beside a busy core (steps/s) | slowdown |")
    print("|---|---|---|---|")
    for name, setting in SETTINGS.items():
        if args.only and not any(w in name for w in args.only):
            continue
        alone = steps_per_second(setting, args)
        busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        try:
            time.sleep(0.5)
            beside = steps_per_second(setting, args)
        finally:
            busy.kill()
            busy.wait()
        print(f"| {name} | {alone:.2f} | {beside:.2f} | {alone / beside:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
