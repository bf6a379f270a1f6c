"""Training speed alone and beside a busy core (issue 15, item 6): how gracefully mg_cpu training degrades.

    python bench/bench_train_load.py --data runs/dataset.npz [--seconds 20] [--kind mg]

Each setting runs in a fresh process (OpenMP reads its environment when torch loads) for --seconds of
training steps at mg_cpu's size on the real training set, first alone, then beside a process that keeps one
core busy (a Python busy loop). Settings: torch's defaults (all cores, OpenMP's default spin-waiting), the
CLI's default (all cores, OMP_WAIT_POLICY=PASSIVE, see generation/train.py), and one thread. Prints steps/s
and each setting's slowdown beside the busy core; run it with nothing else on the machine.
"""
import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = {
    "torch defaults (2 threads, spinning)": {"OMP_WAIT_POLICY": None, "threads": None},
    "CLI default (2 threads, PASSIVE)": {"OMP_WAIT_POLICY": "PASSIVE", "threads": None},
    "1 thread": {"OMP_WAIT_POLICY": None, "threads": "1"},
}

WORKER = """
import sys, time, torch
sys.path.insert(0, {root!r})
if {threads!r}:
    torch.set_num_threads(int({threads!r}))
from generation.dataset import load_dataset
from generation.train import build_model, draw_batch, load_config
ds = load_dataset({data!r})
cfg = load_config({kind!r}, "cpu")
torch.manual_seed(0)
net = build_model({kind!r}, cfg, ds.stats).train()
opt = torch.optim.Adam(net.parameters(), lr=cfg["lr"])
tr = ds.splits["train"]
crop = cfg["train_window"] or tr.x.shape[1]
step, start = 0, None
while True:
    if step == 3:
        start = time.perf_counter()
    x, c, keep = draw_batch(net, tr.x, tr.c, cfg, 0, step, crop)
    loss = net.nll(x, c, keep).mean()
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(net.parameters(), cfg["clip_grad"])
    opt.step()
    step += 1
    if start is not None and time.perf_counter() - start > {seconds}:
        break
print((step - 3) / (time.perf_counter() - start))
"""


def steps_per_second(setting, args):
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if setting["OMP_WAIT_POLICY"]:
        env["OMP_WAIT_POLICY"] = setting["OMP_WAIT_POLICY"]
    code = WORKER.format(root=str(ROOT), threads=setting["threads"], data=args.data, kind=args.kind,
                         seconds=args.seconds)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--kind", default="mg", choices=["mg", "fl"])
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f}; {args.kind}_cpu, {args.seconds:g} s per figure")
    print("| setting | alone (steps/s) | beside a busy core (steps/s) | slowdown |")
    print("|---|---|---|---|")
    for name, setting in SETTINGS.items():
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
