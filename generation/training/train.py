"""Train FL or MG by exact maximum likelihood (CONTRACTS.md §3).

    python -m generation.training.train --model mg --config cpu --data dataset.npz --out runs/mg [--steps N] [--resume]
    python -m generation.training.train --model mg --config FINE.json --data dataset.npz --out runs/mg_fine --init mg.pt
    torchrun --nproc_per_node 4 -m generation.training.train ...     # several GPUs (or CPU processes): DDP

Writes OUT/config.json, OUT/checkpoints/step_XXXXXXX.pt (early ones kept: the bad examples come from them),
OUT/metrics.csv (step, train_nll, valid_nll in nats per dimension of the standardised data) and
OUT/resume.pt (optimiser state for --resume). Adam with linear warm-up, gradient-norm clipping; batches
and dropout masks are functions of (seed, step), so a run is reproducible and a resumed run continues
exactly as an uninterrupted one would. --init CKPT fine-tunes: the run starts from CKPT's weights at CKPT's step,
with Adam afresh, and trains on to the config's `steps` along the config's schedule (a fine-tune config puts its
restart at CKPT's step, so that its learning rate starts at restart_lr).

Under torchrun (WORLD_SIZE > 1) the same batch is split across the ranks: every rank draws the whole batch,
its crop, noise and dropout masks from the shared seed and keeps its own rows, DistributedDataParallel
averages the gradients, and ActNorm initialises from the statistics of the whole batch (flows.ActNorm), so
N ranks train the same model as one process would (up to float rounding). Rank 0 validates and writes.
"""

import csv
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from moglow_eval.core import cli

from ..data.dataset import batch_indices, category_weights, eval_batches, load_dataset
from ..data.torch_files import load_torch_file
from ..models import fl, flows, moglow
from .config import TrainError, as_dict, load_config, model_config, shortened, with_changes
from .devices import finite_on_every_rank, join_ranks, pick_device, set_precision
from .stance import stance_loss
from .threads import CoreShare, torch_threads

MODELS = {"fl": fl.FL, "mg": moglow.MoGlow}


# train_stance: the stance-foot loss (m/s, stance.py; with its posture term) averaged like train_nll, 0 while it is off.
METRICS_COLUMNS = ["step", "train_nll", "valid_nll", "lr", "grad_norm", "elapsed_s", "steps_per_s", "train_stance"]


def learning_rate(cfg, step):
    """Linear warm-up over `warmup` steps to `lr`; then constant, or, with `lr_min` set, a cosine decay that
    reaches lr_min at the last step (a function of the step alone, so a resumed run follows the same curve).
    With `restart_step` set, the first phase ends there and a second one, warm-up and cosine from `restart_lr`
    to `restart_lr_min`, runs to `steps` (a warm restart; the training loop also resets Adam's moments there)."""
    start, end, lr, lr_min = 0, cfg.steps, cfg.lr, cfg.lr_min
    if cfg.restart_step is not None:
        if step >= cfg.restart_step:
            start, lr, lr_min = cfg.restart_step, cfg.restart_lr, cfg.restart_lr_min
        else:
            end = cfg.restart_step
    step -= start
    if step < cfg.warmup:
        return lr * (step + 1) / cfg.warmup
    if lr_min is None:
        return lr
    progress = (step - cfg.warmup) / max(1, end - start - 1 - cfg.warmup)
    return lr_min + (lr - lr_min) * 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))


class _BatchLoss(nn.Module):
    """The model's NLL, and with `stance` its stance-foot loss (stance.py), per batch element, as a module's
    forward, so that DistributedDataParallel can wrap it."""

    def __init__(self, net, fps, posture_weight=0.0, spread_weight=0.0, height_weight=0.0):
        super().__init__()
        self.net, self.fps = net, fps
        self.posture_weight, self.spread_weight, self.height_weight = posture_weight, spread_weight, height_weight

    def forward(self, x, c, keep, history, stance_z, stance, categories=None):
        nll = self.net.nll(x, c, keep, history)
        if not stance:
            return nll, torch.zeros_like(nll)
        weights = (self.posture_weight, self.spread_weight, self.height_weight)
        return nll, stance_loss(self.net, x, c, self.fps, keep, history, stance_z, *weights, categories)


def build_model(kind, cfg, stats=None):
    net = MODELS[kind](model_config(cfg))
    if stats is not None:
        net.set_stats(stats["x_mean"], stats["x_std"], stats["c_mean"], stats["c_std"])
    return net


def save_checkpoint(path, net, cfg, ds, step, valid_nll):
    """Everything needed to sample without the dataset."""
    torch.save(
        dict(
            kind=net.kind,
            config=as_dict(cfg),  # plain data, so the checkpoint loads weights-only
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
    for x, c in eval_batches(split, cfg.batch_size, cfg.valid_windows):
        nll = net.nll(x.to(device), c.to(device))
        total += nll.sum().item()
        n += len(nll)
    net.train(was)
    return total / n


def train(
    model,
    config,
    data_path,
    out_dir,
    steps=None,
    seed=0,
    progress=True,
    resume=False,
    device=None,
    threads=None,
    precision=None,
    init=None,
):
    """Train `model` ('fl' or 'mg') with `config` on a prepared dataset; returns out_dir (see module doc).
    `init`: a checkpoint to fine-tune from (its weights and step; --resume of the same out_dir wins over it).
    `steps` and `precision` (None: the config's) override the config's fields of those names.
    `threads`: CPU threads for torch: None keeps torch's choice, a number fixes it (and the bits of the result),
    "auto" follows the cores other processes leave free (threads.CoreShare; the command's default). The
    thread count is restored on return."""
    with torch_threads(None if threads in (None, "auto") else threads):
        cfg, ds = _config_and_data(model, config, steps, data_path, precision)
        return _train(model, cfg, ds, data_path, out_dir, seed, progress, resume, device, threads == "auto", init)


def _run_config(model, config, steps=None, precision=None):
    """The config a run of `model` trains with: `config` with train()'s `steps` and `precision` overrides."""
    cfg = load_config(model, config)
    if precision is not None:
        cfg = with_changes(cfg, "--precision", precision=precision)
    if steps is not None:
        cfg = shortened(cfg, steps)
    return cfg


def finished(model, config, out_dir, steps=None, precision=None):
    """Whether `out_dir` holds a run that train() with these arguments and `resume` would only load and return: its
    resume state is there and its checkpoint at the config's last step was written by this model and config. A
    caller that needs only the checkpoints (make_stimuli reusing its runs) asks first: resuming builds the
    optimiser, and a process's first optimiser loads torch's compiler, which a run that only gives its checkpoints
    does not need."""
    cfg = _run_config(model, config, steps, precision)
    out = Path(out_dir)
    last = out / "checkpoints" / f"step_{cfg.steps:07d}.pt"
    if not ((out / "resume.pt").is_file() and last.is_file()):
        return False
    ck = load_torch_file(last, "cpu", TrainError)
    return isinstance(ck, dict) and ck.get("kind") == model and ck.get("config") == as_dict(cfg)


def _config_and_data(model, config, steps, data_path, precision=None):
    cfg = _run_config(model, config, steps, precision)
    ds = load_dataset(data_path)
    if "valid" not in ds.splits or "train" not in ds.splits:
        raise TrainError(f"{data_path}: needs 'train' and 'valid' splits")
    if cfg.category_balance > 0 and ds.splits["train"].labels is None:
        raise TrainError(f"{data_path}: config field 'category_balance' needs 'train_labels' (re-run prepare_data)")
    return cfg, ds


def _train(model, cfg, ds, data_path, out_dir, seed, progress, resume, device, share_cores, init=None):
    device = pick_device(device)
    rank, world = join_ranks(device)
    if cfg.batch_size % world:
        raise TrainError(f"batch_size {cfg.batch_size} does not split evenly over {world} ranks")
    out = Path(out_dir)
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    net = build_model(model, cfg, ds.stats).to(device)
    if model == "fl":
        net.check_length(cfg.train_window or ds.window)
    set_precision(net, cfg.precision, device, rank == 0)
    opt = make_optimiser(net, cfg)
    start, elapsed = _first_step(out, resume, init, net, opt, cfg, ds, device)
    run = _Run(out, rank == 0, cfg, ds, net, opt, start, elapsed)
    if run.writes:
        run.write_config(data_path, seed, device, world)
    tx, tc = ds.splits["train"].x.to(device), ds.splits["train"].c.to(device)
    crop = cfg.train_window or tx.shape[1]
    weights = category_weights(ds.splits["train"].labels, cfg.category_balance)
    codes = category_codes(ds.splits["train"].labels) if cfg.posture_by_category else None
    rows = slice(rank * cfg.batch_size // world, (rank + 1) * cfg.batch_size // world)
    step_loss = _wrap_ranks(net, ds.fps, world, device, cfg.posture_weight, cfg.spread_weight, cfg.foot_height_weight)
    net.train()
    share = CoreShare() if share_cores and device.type == "cpu" else None
    bar = tqdm(
        range(start, cfg.steps),
        initial=start,
        total=cfg.steps,
        disable=not (progress and run.writes),
        desc=f"train {model}",
        unit="step",
        dynamic_ncols=True,
    )
    bad = 0
    for step in bar:
        lr = learning_rate(cfg, step)
        for group in opt.param_groups:
            group["lr"] = lr
        if step == cfg.restart_step:
            opt.state.clear()  # a warm restart starts Adam afresh: its moments belong to the finished phase
        if share is not None:
            share.step()
        idx = batch_indices(len(tx), cfg.batch_size, seed, step, weights)
        x, c, keep, history, stance_z = draw_batch(net, tx, tc, cfg, seed, step, crop, weights, idx)
        stance = stance_on(cfg, step)
        cats = None if codes is None else codes[idx]
        nll, foot = step_loss(
            *(None if v is None else v[rows] for v in (x, c, keep, history, stance_z)),
            stance,
            None if cats is None else cats[rows].to(device),
        )
        nll, foot = nll.mean(), foot.mean()
        grad_norm = _optimise(nll + cfg.stance_weight * foot if stance else nll, net, opt, cfg, world)
        if grad_norm is None:
            bad += 1
            if bad > 20:
                raise TrainError(f"training diverged: NLL not finite at step {step + 1} (lower 'lr' in the config)")
            continue
        if run.writes:
            run.after_step(step + 1, nll.item(), foot.item(), lr, grad_norm, device)
            bar.set_postfix(nll=f"{nll.item():.3f}", valid=f"{run.valid_nll:.3f}")
    bar.close()
    if world > 1:
        torch.distributed.barrier()  # rank 0's last checkpoint is written before any rank returns
    return out


def make_optimiser(net, cfg):
    """Adam over all weights at once. In float32 the foreach form, which gives the same bits as the
    one-tensor-at-a-time form that trained the shipped models; the fused kernel rounds differently. With bfloat16
    networks the bits differ anyway, so there the fused kernel, which is faster beside bfloat16's shorter steps."""
    fused = cfg.precision != "float32"
    return torch.optim.Adam(net.parameters(), lr=cfg.lr, foreach=not fused, fused=fused or None)


def _optimise(loss, net, opt, cfg, world):
    """One optimiser step on `loss` with gradient-norm clipping; returns the norm, or None (no step) when the loss
    is not finite on some rank."""
    opt.zero_grad(set_to_none=True)
    if not finite_on_every_rank(loss, world):
        return None
    loss.backward()
    grad_norm = float(torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.clip_grad, foreach=True))
    opt.step()
    return grad_norm


def _wrap_ranks(net, fps, world, device, posture_weight=0.0, spread_weight=0.0, height_weight=0.0):
    """The model's loss as a module, wrapped for DistributedDataParallel under torchrun."""
    step_loss = _BatchLoss(net, fps, posture_weight, spread_weight, height_weight)
    if world > 1:
        ids = [device] if device.type == "cuda" else None
        step_loss = nn.parallel.DistributedDataParallel(step_loss, device_ids=ids)
    return step_loss


def _resume(path, resume, net, opt, device):
    """(first step, seconds trained so far): from `path` with `resume` (net and opt loaded), else (0, 0)."""
    if not resume:
        return 0, 0.0
    if not path.exists():
        raise TrainError(f"{path}: nothing to resume")
    state = load_torch_file(path, device, TrainError)
    try:
        net.load_state_dict(state["state"])
        opt.load_state_dict(state["opt"])
        return int(state["step"]), float(state.get("elapsed", 0.0))
    except Exception as e:  # another model's or another tool's file: one line, not a traceback
        first = (str(e).strip().splitlines() or [""])[0]
        raise TrainError(f"{path}: not a resume state of this run's model ({type(e).__name__}: {first})") from None


def _first_step(out, resume, init, net, opt, cfg, ds, device):
    """(first step, seconds trained so far): a resumed run's (OUT/resume.pt), a fine-tune's (`init`) or (0, 0)."""
    if init is not None and not resume:
        return _init_from(Path(init), net, cfg, ds, device), 0.0
    return _resume(out / "resume.pt", resume, net, opt, device)


def _init_from(path, net, cfg, ds, device):
    """Load a finished checkpoint's weights into `net` for a fine-tune and return its step (the run's first). The
    checkpoint must be of the same kind and size, trained on data with the same statistics (the weights read
    standardised inputs), and end before the config's last step; else TrainError, one line naming the file."""
    ck = load_torch_file(path, device, TrainError)
    if not isinstance(ck, dict) or "state" not in ck or "kind" not in ck:
        raise TrainError(f"{path}: not a checkpoint of generation.training.train")
    if ck["kind"] != net.kind or dict(ck.get("model_config", {})) != dict(net.config):
        raise TrainError(
            f"{path}: a {ck['kind']} checkpoint of size {ck.get('model_config')}, but the config builds a "
            f"{net.kind} of size {net.config}"
        )
    for key, value in ds.stats.items():
        theirs = np.asarray(ck.get("stats", {}).get(key, []), dtype=np.float64)
        if theirs.shape != value.shape or not np.allclose(theirs, value, rtol=1e-5, atol=1e-7):
            raise TrainError(f"{path}: trained on data whose statistics differ from this data set's ('{key}')")
    step = int(ck.get("step", 0))
    if step >= cfg.steps:
        raise TrainError(f"{path}: already at step {step}; the config's 'steps' ({cfg.steps}) must be beyond it")
    net.load_state_dict(ck["state"])
    return step


class _Run:
    """What rank 0 writes while training: config.json, metrics.csv rows, checkpoints and resume.pt."""

    def __init__(self, out, writes, cfg, ds, net, opt, start, elapsed):
        self.out, self.writes, self.cfg, self.ds, self.net, self.opt = out, writes, cfg, ds, net, opt
        self.start, self.elapsed, self.metrics = start, elapsed, out / "metrics.csv"
        self.early = set(cfg.early_ckpts)
        self.run_nll, self.run_stance, self.run_n, self.valid_nll = 0.0, 0.0, 0, float("nan")
        self.t0 = self.t_row = time.perf_counter()
        self.s_row = start

    def write_config(self, data_path, seed, device, world):
        info = {**as_dict(self.cfg), "data": str(data_path), "seed": seed, "device": str(device), "ranks": world}
        (self.out / "config.json").write_text(json.dumps(info, indent=2))
        if self.start == 0 or not self.metrics.exists():
            with open(self.metrics, "w", newline="") as f:
                csv.writer(f).writerow(METRICS_COLUMNS)

    def after_step(self, done, nll, stance, lr, grad_norm, device):
        """Book step `done`: validate and write a metrics row, and checkpoint, when due."""
        self.run_nll += nll
        self.run_stance += stance
        self.run_n += 1
        last = done == self.cfg.steps
        if done % self.cfg.valid_every == 0 or last or done == 1:
            self._metrics_row(done, lr, grad_norm, device)
        if done in self.early or done % self.cfg.ckpt_every == 0 or last:
            self._checkpoint(done)

    def _metrics_row(self, done, lr, grad_norm, device):
        self.valid_nll = evaluate(self.net, self.ds.splits["valid"], self.cfg, device)
        now = time.perf_counter()
        sps = (done - self.s_row) / max(1e-9, now - self.t_row)
        self.t_row, self.s_row = now, done
        row = [
            done,
            f"{self.run_nll / max(1, self.run_n):.5f}",
            f"{self.valid_nll:.5f}",
            f"{lr:.3g}",
            f"{grad_norm:.3f}",
            f"{self.elapsed + now - self.t0:.1f}",
            f"{sps:.3f}",
            f"{self.run_stance / max(1, self.run_n):.5f}",
        ]
        with open(self.metrics, "a", newline="") as f:
            csv.writer(f).writerow(row)
        self.run_nll, self.run_stance, self.run_n = 0.0, 0.0, 0

    def _checkpoint(self, done):
        ckpt = self.out / "checkpoints" / f"step_{done:07d}.pt"
        save_checkpoint(ckpt, self.net, self.cfg, self.ds, done, self.valid_nll)
        elapsed = self.elapsed + time.perf_counter() - self.t0
        state = dict(state=self.net.state_dict(), opt=self.opt.state_dict(), step=done, elapsed=elapsed)
        torch.save(state, self.out / "resume.pt")


def category_codes(labels):
    """Integer codes [N] (a CPU tensor) of the training windows' category labels, for the posture term by
    category; TrainError without labels."""
    if labels is None:
        raise TrainError("config field 'posture_by_category' needs 'train_labels' in the data set (re-run prepare)")
    return torch.as_tensor(np.unique(labels, return_inverse=True)[1].reshape(-1), dtype=torch.long)


def stance_on(cfg, step):
    """Whether the stance-foot loss joins the NLL at `step`."""
    return cfg.stance_weight > 0 and step >= cfg.stance_start


def draw_batch(net, tx, tc, cfg, seed, step, crop, weights=None, idx=None):
    """The whole training batch of `step` (every rank draws the same): windows (drawn with probabilities
    `weights`, None: uniform), their random crop, the dequantisation noise, for MG the history dropout mask and
    the history the conditioning reads, and the latents of the stance loss's prediction (None where unused), all
    functions of (seed, step)."""
    if idx is None:  # the windows of (seed, step); the training loop draws them once and passes them in
        idx = batch_indices(len(tx), cfg.batch_size, seed, step, weights)
    idx = idx.to(tx.device)
    x, c = tx[idx], tc[idx]
    torch.manual_seed(seed * 1_000_003 + step)
    if crop < x.shape[1]:
        s = int(torch.randint(0, x.shape[1] - crop + 1, (1,)))
        x, c = x[:, s : s + crop], c[:, s : s + crop]
    if cfg.noise > 0:
        # Small Gaussian noise (standardised units) bounds the density on (near-)deterministic dimensions,
        # e.g. the root's own x/z in the root frame, which are exactly 0 (dequantisation, as in Glow).
        x = x + cfg.noise * torch.randn_like(x)
    keep = None
    if net.kind == "mg" and net.config["dropout"] > 0:
        keep = net.history_keep(x.shape[0], x.shape[1], x.device)
    history = None
    if net.kind == "mg" and cfg.history_noise > 0:
        # The history with noise of its own, the target clean: at sampling time the history is the model's own
        # output, slightly off, and a model trained only on clean histories lets such errors add up frame after
        # frame (exposure bias). Drawn after the mask, so that runs without it draw as before.
        history = x + cfg.history_noise * torch.randn_like(x)
    stance_z = None
    if stance_on(cfg, step) and cfg.stance_temperature > 0:
        stance_z = cfg.stance_temperature * torch.randn_like(x)  # drawn last: other runs draw as before
    return x, c, keep, history, stance_z


def _threads(text):
    return text if text == "auto" else cli.number(int, 1, 1024)(text)


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.training.train", description=__doc__.split("\n")[0])
    ap.add_argument("--model", required=True, choices=sorted(MODELS))
    ap.add_argument("--config", default="cpu", help="tiny | cpu | paper | path to a JSON config")
    ap.add_argument("--data", required=True, help="prepared dataset .npz (python -m generation.data.prepare)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--steps", type=cli.number(int, 1), default=None, help="override the config's number of steps")
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    ap.add_argument("--resume", action="store_true", help="continue from OUT/resume.pt")
    ap.add_argument("--init", default=None, metavar="CKPT", help="fine-tune: start from CKPT's weights at its step")
    ap.add_argument("--device", default=None, help="default: cuda when present, else cpu")
    ap.add_argument(
        "--threads",
        type=_threads,
        default="auto",
        help="CPU threads, fixed (and then the same bits run after run), or 'auto' (default): the cores "
        "other processes leave free, checked every 2 s",
    )
    ap.add_argument(
        "--precision",
        choices=sorted(flows.PRECISIONS),
        default=None,
        help="override the config's: bfloat16 runs the coupling networks in bfloat16 (faster on AMD Zen 4, slower on "
        "Intel CPUs without AMX; bench/RESULTS.md)",
    )
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def _main(argv):
    a = build_parser().parse_args(argv)
    cli.folder_to_write(a.out, "the run's folder")
    out = train(
        a.model,
        a.config,
        a.data,
        a.out,
        steps=a.steps,
        seed=a.seed,
        progress=not a.quiet,
        resume=a.resume,
        device=a.device,
        threads=a.threads,
        precision=a.precision,
        init=a.init,
    )
    print(f"trained {a.model}: {out}")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
