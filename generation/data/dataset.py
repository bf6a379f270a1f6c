"""The prepared dataset (CONTRACTS.md §2): the one reader of its .npz, its standardised tensors for training,
and random training batches.

Every reader of a dataset (training, sampling, the stimulus pipeline, the shipped held-out set, the benches)
goes through `read_arrays`, so a broken or foreign file fails the same way everywhere: one DatasetError line
naming the file and the key. (The invariants check of generation.motion, a room below this one, reads its one
array after core.clip.npz_headers has checked the archive.)

torch is imported inside the two functions that make tensors, not at module level: make_stimuli reads the
held-out windows through this module, and `import generation.make_stimuli` must stay torch-free (its --help,
--export-items and item checks run before any model is needed; tests/generation/test_stimuli.py guards it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import NPZ_READ_ERRORS, first_line

if TYPE_CHECKING:
    import torch

REQUIRED = ("train_x", "train_c", "valid_x", "valid_c", "x_mean", "x_std", "c_mean", "c_std", "fps", "window")
HELD_OUT = ("valid", "test")
# What each held-out window carries: the window, its control, category, take, first frame, and the tau real
# frames (and their control) before it, which MG is seeded with.
WINDOW_KEYS = ("x", "c", "labels", "take", "start", "hist", "hist_c")
ZIP_MAGIC = b"PK\x03\x04"  # how an .npz (a zip archive) begins


class DatasetError(UserError):
    """A prepared dataset that cannot be used; the message names the file and the key."""


def read_arrays(path, keys=None):
    """{key: numpy array} of a prepared dataset .npz: the `keys` it has (every key when None), reading no other
    array (the training split is most of the file). Callers check for the keys they need with `require`."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(ZIP_MAGIC))
        if head == ZIP_MAGIC:
            f = np.load(path, allow_pickle=False)
            with f:
                return {k: f[k] for k in (f.files if keys is None else keys) if k in f.files}
    except NPZ_READ_ERRORS as e:
        raise DatasetError(f"{path}: not a readable prepared dataset .npz ({first_line(e)})") from None
    # numpy's own message for a BVH, a CSV or an .npy file is about pickled data, which tells the user nothing
    raise DatasetError(f"{path}: not an .npz archive, as a prepared dataset is (generation.data.prepare makes one)")


def require(arrays, keys, path, why="see CONTRACTS.md §2"):
    """DatasetError naming the first of `keys` missing from `arrays` (as read_arrays gives them)."""
    for key in keys:
        if key not in arrays:
            raise DatasetError(f"{path}: missing key '{key}' ({why})")


def read_heldout(path):
    """The held-out windows of a prepared dataset, or of the shipped heldout.npz: ({split: {key: array}} for the
    splits that have every WINDOW_KEYS key, fps, window length). DatasetError without a test split."""
    wanted = [f"{s}_{k}" for s in HELD_OUT for k in WINDOW_KEYS] + ["fps", "window"]
    d = read_arrays(path, wanted)
    require(d, ("fps", "window"), path)
    splits = {s: {k: d[f"{s}_{k}"] for k in WINDOW_KEYS} for s in HELD_OUT if all(f"{s}_{k}" in d for k in WINDOW_KEYS)}
    if "test" not in splits:
        raise DatasetError(f"{path}: no test split with history (test_x, test_hist, ...); re-run prepare_data")
    return splits, float(d["fps"]), int(d["window"])


def heldout_windows(path, keys):
    """One array per key, every held-out split's windows joined (valid, then test): the 192 windows the
    benchmarks of the shipped models sample (bench/rigid_bones.py, bench/fl_posture.py, bench/style_retention.py)."""
    names = [f"{s}_{k}" for s in HELD_OUT for k in keys]
    d = read_arrays(path, names)
    require(d, names, path)
    return tuple(np.concatenate([d[f"{s}_{k}"] for s in HELD_OUT]) for k in keys)


@dataclass
class Split:
    x: torch.Tensor  # [N, T, 63] standardised
    c: torch.Tensor  # [N, T, 3] standardised
    hist: torch.Tensor | None = None  # [N, tau, 63] standardised frames before each window, if stored
    hist_c: torch.Tensor | None = None  # [N, tau, 3]
    labels: np.ndarray | None = None  # [N] category of each window, if stored

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
    d = read_arrays(path)
    require(d, REQUIRED, path)
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
        if f"{split}_labels" in d:
            sp.labels = np.asarray(d[f"{split}_labels"]).astype(str)
            if sp.labels.shape != (len(x),):
                raise DatasetError(f"{path}: '{split}_labels' {sp.labels.shape} does not match {len(x)} windows")
        if f"{split}_hist" in d and f"{split}_hist_c" in d:
            sp.hist = standardize(d[f"{split}_hist"], stats["x_mean"], stats["x_std"])
            sp.hist_c = standardize(d[f"{split}_hist_c"], stats["c_mean"], stats["c_std"])
        ds.splits[split] = sp
    return ds


def standardize(a, mean, std):
    import torch  # (see the module docstring)

    return torch.from_numpy(((np.asarray(a, np.float32) - mean) / std).astype(np.float32))


def batch_indices(n, batch_size, seed, step, p=None):
    """Indices of training batch `step`: a function of (seed, step) only, so a resumed run sees the same
    batches as an uninterrupted one. `p`: each window's probability (`category_weights`); None: uniform. A batch
    holds no window twice, so a category with fewer windows than its share of a batch is drawn less than `p` says
    (not so for the training split: 32 windows of 9780)."""
    import torch  # (see the module docstring)

    rng = np.random.default_rng([seed, step])
    return torch.from_numpy(rng.choice(n, size=batch_size, replace=n < batch_size, p=p))


def category_weights(labels, balance):
    """Each window's probability of being drawn, proportional to (windows in its category)^-balance: 0 draws
    every window alike, so common categories dominate; 1 draws every category alike. None for 0 (uniform)."""
    if balance == 0:
        return None
    _, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    w = counts[inverse].astype(np.float64) ** -balance
    return w / w.sum()


def eval_batches(split, batch_size, max_windows=None):
    """Deterministic batches over (the first max_windows of) a split, for validation NLL."""
    n = len(split) if max_windows is None else min(len(split), max_windows)
    for i in range(0, n, batch_size):
        yield split.x[i : min(n, i + batch_size)], split.c[i : min(n, i + batch_size)]
