"""Sample motion from trained FL / MG checkpoints.

    python -m generation.sampling.sample --checkpoint CKPT --data FILE.npz --split test --n N --out DIR
        [--temperature 1.0]

API (arrays in and out are un-standardised features, numpy or torch; outputs are numpy float32):
    model = load_model(ckpt_path)                                     # eval mode, carries its stats/config
    x = sample_mg(model, control [B,T,3], history [B,tau,63], history_control [B,tau,3], temperature, seed)
    x = sample_fl(model, control [B,T,3], temperature, seed)
    x = sample_windows(model, control, history, history_control, temperature, seed)   # either kind
    stream = mg_stream(model, history [B,tau,63], history_control [B,tau,3], temperature, seed)
    pose = stream(control_t [B,3])                                    # one frame in, one pose out [B,63]
"""

import sys
from pathlib import Path

import numpy as np
import torch

from moglow_eval.core import cli
from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import save_clip

from ..data.dataset import read_arrays, require
from ..data.torch_files import load_torch_file
from ..models.fl import FL
from ..models.flows import PRECISIONS
from ..models.mg_stream import MGStream
from ..models.moglow import MoGlow
from ..motion import skeleton
from ..training.devices import pick_device
from ..training.train import MODELS


class SampleError(UserError):
    """Bad sampling input (checkpoint, data, arguments); one-line message."""


def load_model(ckpt_path, device=None):
    """A checkpoint written by generation.training.train -> model in eval mode, with .kind, .config, .step, .fps,
    .window and its data statistics (buffers x_mean/x_std/c_mean/c_std)."""
    device = pick_device(device)
    ck = load_torch_file(ckpt_path, device, SampleError)
    try:
        model = MODELS[ck["kind"]](ck["model_config"])
        model.load_state_dict(ck["state"])
    except Exception as e:  # any unreadable or foreign file: one clear line, not a traceback
        raise SampleError(f"{ckpt_path}: not a usable checkpoint ({type(e).__name__}: {e})".splitlines()[0]) from None
    model.to(device).eval()
    model.step, model.fps, model.window = ck["step"], ck["fps"], ck["window"]
    model.checkpoint = str(ckpt_path)
    return model


def _tensor(a, model):
    p = next(model.parameters())
    return torch.as_tensor(np.asarray(a) if not torch.is_tensor(a) else a).to(p.device, p.dtype)


def _generator(seed):
    return torch.Generator().manual_seed(int(seed))  # CPU generator: the same samples on any device


def _mg_stream(model, history, history_control, temperature, seed, precision="float32", style=None):
    """MGStream seeded with the last tau frames of un-standardised history (and `style`, un-standardised)."""
    hist = model.standardize_x(_tensor(history, model)[:, -model.tau :])
    hist_c = model.standardize_c(_tensor(history_control, model)[:, -model.tau :])
    style = None if style is None else model.standardize_x(_tensor(style, model))
    return MGStream(model, hist, hist_c, temperature, _generator(seed), precision=precision, style=style)


def mg_stream(model, history, history_control, temperature=1.0, seed=0, precision="float32"):
    """Real-time form of MG: returns f(control_t [B, 3]) -> pose [B, 63] (numpy, un-standardised).
    `precision`: "bfloat16" for many streams on CPUs where it pays (mg_stream.MGStream says which)."""
    stream = _mg_stream(model, history, history_control, temperature, seed, precision)

    @torch.inference_mode()
    def step(control):
        y = stream.step(model.standardize_c(_tensor(control, model)))
        return model.unstandardize_x(y).cpu().numpy()

    step.stream = stream
    return step


@torch.inference_mode()
def sample_mg(model, control, history, history_control, temperature=1.0, seed=0, precision="float32", style=None):
    """MG batch sampling: control [B, T, 3] of the frames to generate, the real frames just before them
    (history [B, >=tau, 63], history_control [B, >=tau, 3]) -> poses [B, T, 63]. LSTM state starts at 0.
    `precision`: the streaming sampler's (mg_stream.MGStream). `style` [B, 63]: with `history_style`, the style
    input in place of the mean of the last tau history frames (e.g. a longer real seed's mean pose)."""
    if not isinstance(model, MoGlow):
        raise SampleError("sample_mg needs an MG model")
    control = _tensor(control, model)
    if control.ndim != 3 or history.shape[1] < model.tau or np.shape(history_control)[1] < model.tau:
        raise SampleError(f"sample_mg: need control [B,T,3] and >= tau={model.tau} history frames")
    stream = _mg_stream(model, history, history_control, temperature, seed, precision, style)
    c = model.standardize_c(control)
    out = torch.stack([stream.step(c[:, t]) for t in range(c.shape[1])], dim=1)
    return model.unstandardize_x(out).cpu().numpy().astype(np.float32)


@torch.inference_mode()
def sample_fl(model, control, temperature=1.0, seed=0):
    """FL: whole windows from their control [B, T, 3] (T divisible by 2^(L-1)) -> poses [B, T, 63]."""
    if not isinstance(model, FL):
        raise SampleError("sample_fl needs an FL model")
    c = model.standardize_c(_tensor(control, model))
    x = model.sample(c, temperature, _generator(seed))
    return model.unstandardize_x(x).cpu().numpy().astype(np.float32)


def sample_windows(model, control, history=None, history_control=None, temperature=1.0, seed=0, precision="float32"):
    """The one entry point for sampling windows of either kind: MG from the real frames before each window
    (sample_mg), FL from the control alone (sample_fl, which ignores the history). `precision` is MG's sampler's
    (mg_stream.MGStream); FL samples in its weights' precision."""
    if model.kind == "mg":
        if history is None or history_control is None:
            raise SampleError("sample_windows: MG needs the frames before each window (history, history_control)")
        return sample_mg(model, control, history, history_control, temperature, seed, precision)
    return sample_fl(model, control, temperature, seed)


def nonfinite_windows(x):
    """Indices of the windows of x [B, T, D] that hold a NaN or inf: a flow whose inverse overflows (a diverged
    or barely trained model, a high temperature) gives such windows, which must never reach a video."""
    x = np.asarray(x)
    return np.flatnonzero(~np.isfinite(x.reshape(len(x), -1)).all(axis=1))


def require_finite(x, checkpoint):
    """x, where every window is finite; else a one-line SampleError naming the checkpoint. Whatever writes clips
    calls it: a broken clip renders as an empty or frozen video, which would tell raters the condition."""
    bad = nonfinite_windows(x)
    if len(bad):
        raise SampleError(
            f"{checkpoint}: {len(bad)} of {len(x)} sampled windows hold NaN or inf (first: window {bad[0]}); "
            "the model diverged or is barely trained: try another checkpoint or a lower --temperature"
        )
    return x


def sample_split(model, data_path, split="test", n=None, temperature=1.0, seed=0, precision="float32"):
    """Sample for the first n windows of a split of a prepared dataset -> (x [n,T,63], c [n,T,3])."""
    d = read_arrays(data_path, [f"{split}_c", f"{split}_hist", f"{split}_hist_c"])
    require(d, [f"{split}_c"], data_path, f"no split '{split}'")
    if model.kind == "mg":
        require(d, [f"{split}_hist", f"{split}_hist_c"], data_path, "MG needs the frames before each window")
    c = d[f"{split}_c"][:n]
    hist, hist_c = (d[k][:n] if k in d else None for k in (f"{split}_hist", f"{split}_hist_c"))
    return sample_windows(model, c, hist, hist_c, temperature, seed, precision), c


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.sampling.sample", description="Sample clips from a checkpoint.")
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--data", required=True, help="prepared dataset .npz whose control (and history) to use")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n", type=cli.number(int, 1), default=None, help="number of windows (default: all)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--temperature", type=cli.number(float, 0, 10), default=1.0)
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    ap.add_argument("--device", default=None)
    ap.add_argument(
        "--precision",
        choices=sorted(PRECISIONS),
        default="float32",
        help="MG's sampler: bfloat16 reads its big products in bfloat16, faster for many streams on some CPU kinds "
        "and slower on others (bench/RESULTS.md#sampling-bfloat16; default float32)",
    )
    return ap


def _main(argv):
    a = build_parser().parse_args(argv)
    cli.folder_to_write(a.out, "the clips' folder")
    model = load_model(a.checkpoint, a.device)
    x, c = sample_split(model, a.data, a.split, a.n, a.temperature, a.seed, a.precision)
    require_finite(x, a.checkpoint)
    from ..motion.features import to_world

    out = Path(a.out)
    for i in range(len(x)):
        save_clip(
            out / f"{model.kind}_{a.split}_{i:03d}.npz",
            to_world(x[i], c[i]),
            skeleton.PARENTS,
            skeleton.JOINT_NAMES,
            model.fps,
            control=c[i],
            seed=np.int64(a.seed),
            temperature=np.float64(a.temperature),
            checkpoint=np.str_(a.checkpoint),
        )
    print(f"wrote {len(x)} {model.kind.upper()} clips to {out}")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
