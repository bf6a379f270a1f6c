"""The prepared dataset (CONTRACTS.md §2) as standardised tensors, and random training batches."""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from core.cli import UserError

REQUIRED = ("train_x", "train_c", "valid_x", "valid_c", "x_mean", "x_std", "c_mean", "c_std", "fps", "window")


class DatasetError(UserError):
    """A prepared dataset that cannot be used; the message names the file and the key."""


@dataclass
class Split:
    x: torch.Tensor  # [N, T, 63] standardised
    c: torch.Tensor  # [N, T, 3] standardised
    hist: torch.Tensor | None = None  # [N, tau, 63] standardised frames before each window, if stored
    hist_c: torch.Tensor | None = None  # [N, tau, 3]

    def __len__(self):
        return self.x.shape[0]


@dataclass
class Dataset:
    path: str
    stats: dict  # x_mean, x_std, c_mean, c_std (float32 numpy)
    fps: float
    window: int
    tau: int
    splits: dict = field(default_factory=dict)


def load_dataset(path):
    """Read a prepared .npz; returns a Dataset with standardised train/valid(/test) splits."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as f:
            d = {k: f[k] for k in f.files}
    except (OSError, ValueError) as e:
        raise DatasetError(f"{path}: not a readable prepared dataset .npz ({e})") from None
    for key in REQUIRED:
        if key not in d:
            raise DatasetError(f"{path}: missing key '{key}' (see CONTRACTS.md §2)")
    stats = {k: d[k].astype(np.float32) for k in ("x_mean", "x_std", "c_mean", "c_std")}
    if np.any(stats["x_std"] <= 0) or np.any(stats["c_std"] <= 0):
        raise DatasetError(f"{path}: 'x_std'/'c_std' must be positive")
    ds = Dataset(str(path), stats, float(d["fps"]), int(d["window"]), int(d["tau"]) if "tau" in d else 10)
    for split in ("train", "valid", "test"):
        if f"{split}_x" not in d:
            continue
        x, c = d[f"{split}_x"], d[f"{split}_c"]
        if (
            x.ndim != 3
            or x.shape[2] != stats["x_mean"].shape[0]
            or c.shape != x.shape[:2] + (stats["c_mean"].shape[0],)
        ):
            raise DatasetError(
                f"{path}: '{split}_x' {x.shape} and '{split}_c' {c.shape} do not match [N, T, 63] / [N, T, 3]"
            )
        if len(x) == 0:
            raise DatasetError(f"{path}: split '{split}' is empty")
        if not (np.isfinite(x).all() and np.isfinite(c).all()):
            raise DatasetError(f"{path}: '{split}_x' or '{split}_c' holds NaN or inf")
        sp = Split(standardize(x, stats["x_mean"], stats["x_std"]), standardize(c, stats["c_mean"], stats["c_std"]))
        if f"{split}_hist" in d and f"{split}_hist_c" in d:
            sp.hist = standardize(d[f"{split}_hist"], stats["x_mean"], stats["x_std"])
            sp.hist_c = standardize(d[f"{split}_hist_c"], stats["c_mean"], stats["c_std"])
        ds.splits[split] = sp
    return ds


def standardize(a, mean, std):
    return torch.from_numpy(((np.asarray(a, np.float32) - mean) / std).astype(np.float32))


def batch_indices(n, batch_size, seed, step):
    """Indices of training batch `step`: a function of (seed, step) only, so a resumed run sees the same
    batches as an uninterrupted one."""
    rng = np.random.default_rng([seed, step])
    return torch.from_numpy(rng.choice(n, size=batch_size, replace=n < batch_size))


def eval_batches(split, batch_size, max_windows=None):
    """Deterministic batches over (the first max_windows of) a split, for validation NLL."""
    n = len(split) if max_windows is None else min(len(split), max_windows)
    for i in range(0, n, batch_size):
        yield split.x[i : min(n, i + batch_size)], split.c[i : min(n, i + batch_size)]
