"""Fréchet motion distance (FMD): how far generated motion is, as a distribution, from real motion.

The GENEA challenges' FGD method (Yoon et al. 2020), for locomotion: a small convolutional autoencoder is
trained to reconstruct CHUNK-frame pieces of real motion (the training split's root-frame poses, standardised);
its bottleneck is the feature of a chunk. The FMD between two sets of chunks is the Fréchet distance between
Gaussians fitted to their features,

    FMD = |mu_a - mu_b|^2 + tr(S_a + S_b - 2 (S_a S_b)^(1/2)).

The encoder file holds the weights, the standardisation and the features' first and second moments per
locomotion category of the training split, so a set can be scored without the data set. They are saved as
tensors, so the file loads with torch's weights-only reader (data.torch_files); files written before that held
numpy arrays, which are read too, admitting float arrays alone. The reference is the
training motion of the same categories in the same proportions as the set scored: held-out takes are balanced
over categories while the training split is mostly turns, and against the whole split a generator that
drifts towards typical training motion would score better than real held-out motion. The estimate is biased
upwards for small sets: compare a model's FMD with the floor, real held-out motion of the same windows
(NAT) against the same reference.

    python -m generation.metrics.fmd --data runs/dataset.npz --out generation/pretrained/motion_encoder.pt
"""

import sys
from pathlib import Path

import numpy as np
import scipy.linalg
import torch
from torch import nn
from tqdm import tqdm

from moglow_eval.core import cli

from ..data.dataset import batch_indices, load_dataset, read_arrays, require
from ..data.torch_files import load_torch_file

CHUNK, STRIDE = 34, 8  # frames per chunk (GENEA's FGD uses 34) and between chunk starts within a window
FEATURES = 32
ALL = "*"  # the moments of the whole training split
# What an encoder file of the older format (numpy arrays) needs beyond tensors: numpy's rebuilding of an array of
# float32 or float64 from its bytes, under the module name of numpy 2 and of numpy 1. An array of any other dtype
# (an object array could hold a pickled callable) is still refused.
_reconstruct = (np._core if hasattr(np, "_core") else np.core).multiarray._reconstruct
NUMPY_FLOAT_ARRAYS = (
    (_reconstruct, "numpy._core.multiarray._reconstruct"),
    (_reconstruct, "numpy.core.multiarray._reconstruct"),
    np.ndarray,
    np.dtype,
    type(np.dtype(np.float32)),
    type(np.dtype(np.float64)),
)


class MotionAutoencoder(nn.Module):
    """[B, CHUNK, 63] standardised poses -> [B, FEATURES] (encode) -> [B, CHUNK, 63] (decode)."""

    def __init__(self, pose_dim=63, hidden=64, features=FEATURES):
        super().__init__()
        act = nn.LeakyReLU(0.2)
        self.encoder = nn.Sequential(
            nn.Conv1d(pose_dim, hidden, 3, padding=1),
            act,
            nn.Conv1d(hidden, hidden, 4, stride=2, padding=1),
            act,  # 34 -> 17
            nn.Conv1d(hidden, hidden, 4, stride=2, padding=1),
            act,  # 17 -> 8
            nn.Flatten(),
            nn.Linear(hidden * 8, features),
        )
        self.decoder = nn.Sequential(
            nn.Linear(features, hidden * 8),
            act,
            nn.Unflatten(1, (hidden, 8)),
            nn.ConvTranspose1d(hidden, hidden, 4, stride=2, padding=1, output_padding=1),
            act,  # 8 -> 17
            nn.ConvTranspose1d(hidden, hidden, 4, stride=2, padding=1),
            act,  # 17 -> 34
            nn.Conv1d(hidden, pose_dim, 3, padding=1),
        )

    def encode(self, x):
        return self.encoder(x.transpose(1, 2))

    def forward(self, x):
        return self.decoder(self.encode(x)).transpose(1, 2)


def chunks(windows):
    """Windows [N, T, D] -> every CHUNK-frame piece starting at 0, STRIDE, ..., window by window [N * n, CHUNK, D]."""
    windows = np.asarray(windows, dtype=np.float32)
    starts = range(0, windows.shape[1] - CHUNK + 1, STRIDE)
    return np.stack([windows[:, s : s + CHUNK] for s in starts], axis=1).reshape(-1, CHUNK, windows.shape[2])


def frechet_distance(mu_a, cov_a, mu_b, cov_b):
    """Fréchet distance between two Gaussians (float64; the imaginary rounding of sqrtm is dropped)."""
    root = scipy.linalg.sqrtm(cov_a @ cov_b)
    return float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a + cov_b - 2 * np.real(root)))


class MotionEncoder:
    """A trained encoder with its standardisation and the training split's feature statistics."""

    def __init__(self, state):
        self.net = MotionAutoencoder()
        self.net.load_state_dict(state["state"])
        self.net.eval()
        self.x_mean, self.x_std = (_array(state[k], np.float32) for k in ("x_mean", "x_std"))
        self.moments = {k: (_array(m1, np.float64), _array(m2, np.float64)) for k, (m1, m2) in state["moments"].items()}

    @classmethod
    def load(cls, path):
        return cls(load_torch_file(path, allow=NUMPY_FLOAT_ARRAYS))

    def features(self, poses):
        """Root-frame poses [N, T, 63] in metres -> chunk features [N * n_chunks, FEATURES] (float64)."""
        return encode_windows(self.net, (np.asarray(poses, np.float32) - self.x_mean) / self.x_std)

    def reference(self, categories=None):
        """Mean and covariance of training features for a category mix: a list of categories, one per window
        of the set scored (None: the whole training split)."""
        if categories is None:
            return self.moments[ALL]
        names, counts = np.unique(np.asarray(categories, dtype=str), return_counts=True)
        unknown = [n for n in names if n not in self.moments]
        if unknown:
            raise ValueError(f"motion encoder: no training motion of category {unknown[0]!r}")
        w = counts / counts.sum()
        m1 = sum(wk * self.moments[n][0] for wk, n in zip(w, names))
        m2 = sum(wk * self.moments[n][1] for wk, n in zip(w, names))
        return m1, m2 - np.outer(m1, m1)

    def fmd(self, poses, categories=None):
        """FMD of windows [N, T, 63] (root-frame poses, metres) against training motion of their categories."""
        f = self.features(poses)
        mu, cov = self.reference(categories)
        return frechet_distance(f.mean(0), np.cov(f, rowvar=False), mu, cov)


def _array(value, dtype):
    """A tensor (today's files) or a numpy array (older ones) as a numpy array of `dtype`."""
    return np.asarray(value.numpy() if torch.is_tensor(value) else value, dtype)


def as_tensors(state):
    """An encoder state with its arrays as tensors of the same dtype and values, as train_encoder writes it."""
    tensor = torch.as_tensor
    moments = {k: (tensor(m1), tensor(m2)) for k, (m1, m2) in state["moments"].items()}
    return {**state, "x_mean": tensor(state["x_mean"]), "x_std": tensor(state["x_std"]), "moments": moments}


@torch.no_grad()
def encode_windows(net, windows, block=256):
    """Features of every chunk of standardised windows [N, T, 63], a block of windows at a time (float64)."""
    out = [net.encode(torch.from_numpy(chunks(windows[i : i + block]))) for i in range(0, len(windows), block)]
    return torch.cat(out).double().numpy()


def train_encoder(data_path, steps=3000, batch_size=128, lr=1e-3, seed=0, progress=True):
    """Train the autoencoder on random chunks of the training split; returns the state MotionEncoder loads."""
    ds = load_dataset(data_path)
    windows = ds.splits["train"].x  # standardised already (load_dataset)
    n, length = windows.shape[:2]
    torch.manual_seed(seed)
    net = MotionAutoencoder()
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    rows = torch.arange(CHUNK)
    for step in tqdm(range(steps), desc="motion encoder", disable=not progress):
        idx = batch_indices(n, batch_size, seed, step)
        start = torch.randint(0, length - CHUNK + 1, (len(idx), 1))
        x = windows[idx[:, None], start + rows]  # [B, CHUNK, 63]: one random chunk of each window
        loss = (net(x) - x).pow(2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    net.eval()
    feats = encode_windows(net, windows.numpy())
    d = read_arrays(data_path, ["train_labels"])
    require(d, ["train_labels"], data_path)
    labels = np.repeat(d["train_labels"].astype(str), len(feats) // n)  # chunks come window by window
    state = dict(
        state=net.state_dict(),
        x_mean=ds.stats["x_mean"],
        x_std=ds.stats["x_std"],
        moments=_moments(feats, labels),
        steps=steps,
        seed=seed,
        recon_mse=loss.item(),
    )
    return as_tensors(state)  # tensors, not numpy arrays: the file then loads weights-only


def _moments(feats, labels):
    """{category: (mean, mean of outer products)} of features, plus ALL for every chunk."""
    out = {ALL: (feats.mean(0), feats.T @ feats / len(feats))}
    for name in np.unique(labels):
        f = feats[labels == name]
        out[str(name)] = (f.mean(0), f.T @ f / len(f))
    return out


def _main(argv):
    ap = cli.ArgumentParser(prog="python -m generation.metrics.fmd", description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="prepared dataset .npz (its training split is used)")
    ap.add_argument("--out", required=True, help="encoder file to write (.pt)")
    ap.add_argument("--steps", type=cli.number(int, 1, 10**6), default=3000)
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    cli.file_to_write(a.out, "the encoder file to write", reads=[("--data", a.data)])  # before the training
    state = train_encoder(a.data, a.steps, seed=a.seed, progress=not a.quiet)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    torch.save(state, a.out)
    print(f"wrote {a.out} (reconstruction MSE {state['recon_mse']:.4f} in standardised units)")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
