"""Train FL or MG by exact maximum likelihood (CONTRACTS.md §3).

    python -m generation.train --model mg --config cpu --data dataset.npz --out runs/mg [--steps N] [--resume]
    torchrun --nproc_per_node 4 -m generation.train ...     # several GPUs (or CPU processes): DDP

Writes OUT/config.json, OUT/checkpoints/step_XXXXXXX.pt (early ones kept: the bad examples come from them),
OUT/metrics.csv (step, train_nll, valid_nll in nats per dimension of the standardised data) and
OUT/resume.pt (optimiser state for --resume). Adam with linear warm-up, gradient-norm clipping; batches
and dropout masks are functions of (seed, step), so a run is reproducible and a resumed run continues
exactly as an uninterrupted one would.

Under torchrun (WORLD_SIZE > 1) the same batch is split across the ranks: every rank draws the whole batch,
its crop, noise and dropout masks from the shared seed and keeps its own rows, DistributedDataParallel
averages the gradients, and ActNorm initialises from the statistics of the whole batch (flows.ActNorm), so
N ranks train the same model as one process would (up to float rounding). Rank 0 validates and writes.
"""

import csv
import json
import math
import os
import sys
import time
from pathlib import Path

import torch
from torch import nn
from tqdm import tqdm

from core import cli
from core.cli import UserError

from . import fl, moglow
from .core_share import CoreShare
from .dataset import batch_indices, eval_batches, load_dataset

CONFIG_DIR = Path(__file__).resolve().parent / "configs"
MODELS = {"fl": fl.FL, "mg": moglow.MoGlow}
MODEL_DEFAULTS = {"fl": fl.DEFAULTS, "mg": moglow.DEFAULTS}
TRAIN_DEFAULTS = dict(
    batch_size=32,
    lr=1e-3,
    lr_min=None,
    warmup=200,
    clip_grad=5.0,
    steps=10000,
    valid_every=500,
    valid_windows=256,
    ckpt_every=2000,
    early_ckpts=[50, 100, 200, 500],
    train_window=None,
    noise=0.01,
)


class TrainError(UserError):
    """Bad training input (config, model name, diverged run); one-line message."""


def learning_rate(cfg, step):
    """Linear warm-up over `warmup` steps to `lr`; then constant, or, with `lr_min` set, a cosine decay that
    reaches lr_min at the last step (a function of the step alone, so a resumed run follows the same curve)."""
    if step < cfg["warmup"]:
        return cfg["lr"] * (step + 1) / cfg["warmup"]
    if cfg["lr_min"] is None:
        return cfg["lr"]
    progress = (step - cfg["warmup"]) / max(1, cfg["steps"] - 1 - cfg["warmup"])
    return cfg["lr_min"] + (cfg["lr"] - cfg["lr_min"]) * 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))


def pick_device(device=None):
    if device:
        return torch.device(device)
    if torch.cuda.is_available():
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
    return torch.device("cpu")


def join_ranks():
    """(rank, world size): (0, 1) alone; under torchrun, after joining the process group (nccl on CUDA)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world == 1:
        return 0, 1
    if not torch.distributed.is_initialized():
        torch.distributed.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return torch.distributed.get_rank(), world


class _BatchNLL(nn.Module):
    """The model's NLL as a module's forward, so that DistributedDataParallel can wrap it."""

    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, x, c, keep):
        return self.net.nll(x, c, keep)


def load_config(model, config):
    """`config`: a dict, 'tiny'/'cpu'/'paper' (meaning configs/{model}_{name}.json) or a JSON file path."""
    if model not in MODELS:
        raise TrainError(f"--model must be one of {sorted(MODELS)}, got '{model}'")
    if isinstance(config, dict):
        cfg, where = dict(config), "config"
    else:
        path = Path(config)
        if not path.suffix and not path.exists():
            path = CONFIG_DIR / f"{model}_{config}.json"
        if not path.is_file():
            raise TrainError(f"config '{config}' not found (tried {path})")
        try:
            cfg = json.loads(path.read_text())
        except json.JSONDecodeError as e:
            raise TrainError(f"{path}:{e.lineno}: invalid JSON ({e.msg})") from None
        where = str(path)
    if cfg.get("model", model) != model:
        raise TrainError(f"{where}: field 'model' is '{cfg['model']}' but --model is '{model}'")
    allowed = set(TRAIN_DEFAULTS) | set(MODEL_DEFAULTS[model]) | {"model", "name", "note"}
    for key, value in cfg.items():
        if key not in allowed:
            raise TrainError(f"{where}: unknown field '{key}'")
        if key not in ("model", "name", "note", "early_ckpts", "train_window") and not isinstance(value, (int, float)):
            raise TrainError(f"{where}: field '{key}' must be a number, got {value!r}")
    return {**TRAIN_DEFAULTS, **cfg, "model": model}


def model_config(kind, cfg):
    return {k: cfg[k] for k in MODEL_DEFAULTS[kind] if k in cfg}


def build_model(kind, cfg, stats=None):
    net = MODELS[kind](model_config(kind, cfg))
    if stats is not None:
        net.set_stats(stats["x_mean"], stats["x_std"], stats["c_mean"], stats["c_std"])
    return net


def save_checkpoint(path, net, cfg, ds, step, valid_nll):
    """Everything needed to sample without the dataset."""
    torch.save(
        dict(
            kind=net.kind,
            config=cfg,
            model_config=net.config,
            state=net.state_dict(),
            step=step,
            valid_nll=valid_nll,
            stats={k: v.tolist() for k, v in ds.stats.items()},
            tau=getattr(net, "tau", ds.tau),
            fps=ds.fps,
            window=ds.window,
        ),
        path,
    )


@torch.no_grad()
def evaluate(net, split, cfg, device):
    """Mean NLL (nats/dim) over the first valid_windows windows of a split."""
    was = net.training
    net.eval()
    total, n = 0.0, 0
    for x, c in eval_batches(split, cfg["batch_size"], cfg["valid_windows"]):
        nll = net.nll(x.to(device), c.to(device))
        total += nll.sum().item()
        n += len(nll)
    net.train(was)
    return total / n


def train(
    model, config, data_path, out_dir, steps=None, seed=0, progress=True, resume=False, device=None, threads=None
):
    """Train `model` ('fl' or 'mg') with `config` on a prepared dataset; returns out_dir (see module doc).
    `threads`: CPU threads for torch: None keeps torch's choice, a number fixes it (and the bits of the result),
    "auto" follows the cores other processes leave free (core_share.CoreShare; the command's default)."""
    share = CoreShare() if threads == "auto" else None
    if threads not in (None, "auto"):
        torch.set_num_threads(int(threads))
    cfg = load_config(model, config)
    if steps is not None:
        cfg["steps"] = int(steps)
    ds = load_dataset(data_path)
    if "valid" not in ds.splits or "train" not in ds.splits:
        raise TrainError(f"{data_path}: needs 'train' and 'valid' splits")
    rank, world = join_ranks()
    if cfg["batch_size"] % world:
        raise TrainError(f"batch_size {cfg['batch_size']} does not split evenly over {world} ranks")
    device = pick_device(device)
    out = Path(out_dir)
    writes = rank == 0  # validation, metrics and checkpoints: rank 0 only
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    train_split, valid_split = ds.splits["train"], ds.splits["valid"]
    torch.manual_seed(seed)
    net = build_model(model, cfg, ds.stats).to(device)
    if model == "fl":
        net.check_length(cfg["train_window"] or ds.window)
    opt = torch.optim.Adam(net.parameters(), lr=cfg["lr"])
    start, elapsed = 0, 0.0
    resume_path = out / "resume.pt"
    if resume and resume_path.exists():
        state = torch.load(resume_path, map_location=device, weights_only=False)
        net.load_state_dict(state["state"])
        opt.load_state_dict(state["opt"])
        start, elapsed = state["step"], state.get("elapsed", 0.0)
    elif resume:
        raise TrainError(f"{resume_path}: nothing to resume")
    metrics_path = out / "metrics.csv"
    if writes:
        (out / "config.json").write_text(
            json.dumps({**cfg, "data": str(data_path), "seed": seed, "device": str(device), "ranks": world}, indent=2)
        )
        if start == 0 or not metrics_path.exists():
            with open(metrics_path, "w", newline="") as f:
                csv.writer(f).writerow(
                    ["step", "train_nll", "valid_nll", "lr", "grad_norm", "elapsed_s", "steps_per_s"]
                )

    tx, tc = train_split.x.to(device), train_split.c.to(device)
    window = tx.shape[1]
    crop = cfg["train_window"] or window
    early = set(cfg["early_ckpts"])
    rows = slice(rank * cfg["batch_size"] // world, (rank + 1) * cfg["batch_size"] // world)
    step_nll = _BatchNLL(net)
    if world > 1:
        step_nll = nn.parallel.DistributedDataParallel(step_nll, device_ids=[device] if device.type == "cuda" else None)
    net.train()
    bar = tqdm(
        range(start, cfg["steps"]),
        initial=start,
        total=cfg["steps"],
        disable=not (progress and writes),
        desc=f"train {model}",
        unit="step",
        dynamic_ncols=True,
    )
    run_nll, run_n, bad, t0, valid_nll, t_row, s_row = (
        0.0,
        0,
        0,
        time.perf_counter(),
        float("nan"),
        time.perf_counter(),
        start,
    )
    for step in bar:
        lr = learning_rate(cfg, step)
        for group in opt.param_groups:
            group["lr"] = lr
        if share is not None and device.type == "cpu":
            share.step()
        x, c, keep = draw_batch(net, tx, tc, cfg, seed, step, crop)
        loss = step_nll(x[rows], c[rows], None if keep is None else keep[rows]).mean()
        opt.zero_grad(set_to_none=True)
        if not _finite_on_every_rank(loss, world):
            bad += 1
            if bad > 20:
                raise TrainError(f"training diverged: NLL not finite at step {step + 1} (lower 'lr' in the config)")
            continue
        loss.backward()
        grad_norm = float(torch.nn.utils.clip_grad_norm_(net.parameters(), cfg["clip_grad"]))
        opt.step()
        run_nll += loss.item()
        run_n += 1
        done = step + 1
        last = done == cfg["steps"]
        if not writes:
            continue
        if done % cfg["valid_every"] == 0 or last or done == 1:
            valid_nll = evaluate(net, valid_split, cfg, device)
            now = time.perf_counter()
            sps = (done - s_row) / max(1e-9, now - t_row)
            t_row, s_row = now, done
            with open(metrics_path, "a", newline="") as f:
                csv.writer(f).writerow(
                    [
                        done,
                        f"{run_nll / max(1, run_n):.5f}",
                        f"{valid_nll:.5f}",
                        f"{lr:.3g}",
                        f"{grad_norm:.3f}",
                        f"{elapsed + now - t0:.1f}",
                        f"{sps:.3f}",
                    ]
                )
            run_nll, run_n = 0.0, 0
        bar.set_postfix(nll=f"{loss.item():.3f}", valid=f"{valid_nll:.3f}")
        if done in early or done % cfg["ckpt_every"] == 0 or last:
            save_checkpoint(out / "checkpoints" / f"step_{done:07d}.pt", net, cfg, ds, done, valid_nll)
            torch.save(
                dict(
                    state=net.state_dict(), opt=opt.state_dict(), step=done, elapsed=elapsed + time.perf_counter() - t0
                ),
                resume_path,
            )
    bar.close()
    if world > 1:
        torch.distributed.barrier()  # rank 0's last checkpoint is written before any rank returns
    return out


def draw_batch(net, tx, tc, cfg, seed, step, crop):
    """The whole training batch of `step` (every rank draws the same): windows, their random crop, the
    dequantisation noise and MG's history dropout mask (None for FL), all functions of (seed, step)."""
    idx = batch_indices(len(tx), cfg["batch_size"], seed, step).to(tx.device)
    x, c = tx[idx], tc[idx]
    torch.manual_seed(seed * 1_000_003 + step)
    if crop < x.shape[1]:
        s = int(torch.randint(0, x.shape[1] - crop + 1, (1,)))
        x, c = x[:, s : s + crop], c[:, s : s + crop]
    if cfg["noise"] > 0:
        # Small Gaussian noise (standardised units) bounds the density on (near-)deterministic dimensions,
        # e.g. the root's own x/z in the root frame, which are exactly 0 (dequantisation, as in Glow).
        x = x + cfg["noise"] * torch.randn_like(x)
    keep = None
    if net.kind == "mg" and net.config["dropout"] > 0:
        keep = net.history_keep(x.shape[0], x.shape[1], x.device)
    return x, c, keep


def _finite_on_every_rank(loss, world):
    """Whether the loss is finite on every rank (a rank that skipped its step alone would hang the others)."""
    finite = torch.isfinite(loss.detach()).to(torch.int32)
    if world > 1:
        torch.distributed.all_reduce(finite, op=torch.distributed.ReduceOp.MIN)
    return bool(finite)


def _threads(text):
    return text if text == "auto" else cli.number(int, 1, 1024)(text)


def _main(argv):
    ap = cli.ArgumentParser(prog="python -m generation.train", description=__doc__.split("\n")[0])
    ap.add_argument("--model", required=True, choices=sorted(MODELS))
    ap.add_argument("--config", default="cpu", help="tiny | cpu | paper | path to a JSON config")
    ap.add_argument("--data", required=True, help="prepared dataset .npz (python -m generation.prepare_data)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--steps", type=cli.number(int, 1), default=None, help="override the config's number of steps")
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    ap.add_argument("--resume", action="store_true", help="continue from OUT/resume.pt")
    ap.add_argument("--device", default=None, help="default: cuda when present, else cpu")
    ap.add_argument(
        "--threads",
        type=_threads,
        default="auto",
        help="CPU threads, fixed (and then the same bits run after run), or 'auto' (default): the cores "
        "other processes leave free, checked every 2 s",
    )
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)
    out = train(
        a.model,
        a.config,
        a.data,
        a.out,
        steps=a.steps,
        seed=a.seed,
        progress=not a.no_progress,
        resume=a.resume,
        device=a.device,
        threads=a.threads,
    )
    print(f"trained {a.model}: {out}")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
