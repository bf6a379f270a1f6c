"""The Fréchet gesture distance (FGD, Yoon et al. 2020) of a study of your own motion, and its diversity, on an
encoder trained on the study's own reference motion.

GENEA's FGD trains an autoencoder on the data set's real motion and compares the Gaussians fitted to the bottleneck
features of chunks of generated and of real motion. Here the data set is the study's reference condition, so the
encoder is trained when the study is built: fmd.MotionAutoencoder (the FMD's network, HIDDEN wide; its input each
frame's joint positions about the root with their velocities and accelerations, 9 values a joint, each standardised
by the reference's mean and spread, the spread at least MIN_SPREAD) on fmd.CHUNK-frame chunks drawn at random from
the reference's clips, STEPS steps of BATCH chunks at LR, seeded, on one torch thread (the thread count is put back
after), so that the same study trains the same encoder on any machine of the same torch. Its time is in
bench/RESULTS.md "gesture-measures". The trained encoder is cached under the user's cache folder
($XDG_CACHE_HOME/moglow-eval/gesture_encoders, else ~/.cache/...), named by a hash of the reference motion and these
settings, so a study built again reuses it; a cache that cannot be read or written is trained past, never fatal.

Positions alone would not do: an autoencoder of the positions of real motion learns to smooth noise away, so a clip
shaking by centimetres every frame came out nearer the reference than another half of the reference did
(bench/RESULTS.md "gesture-measures"); its velocities and accelerations put the shaking in the features.

A clip's features are those of its chunks every fmd.STRIDE frames. The FGD between two sets of chunk features is the
Fréchet distance between the Gaussians fitted to them,

    FGD = |mu_a - mu_b|^2 + tr(S_a + S_b - 2 (S_a^1/2 S_b S_a^1/2)^1/2),

the trace taken through the symmetric form, which stays exact where a clip has fewer chunks than features (a
singular covariance, where fmd.frechet_distance's matrix square root fails). A clip's diversity feature is the mean
of its chunk features; diversity is the mean Euclidean distance between the features of different clips.
"""

import contextlib
import hashlib
import logging
import os
import time
from pathlib import Path

import numpy as np

from . import joint_groups
from .fmd import CHUNK, FEATURES, MotionAutoencoder, encode_windows

log = logging.getLogger(__name__)

STEPS, BATCH, LR = 500, 32, 1e-3
HIDDEN = 32  # the network's width: half the FMD's, for its cost on a 2-core build (its input is 9 values a joint)
MIN_SPREAD = 0.01  # a coordinate the reference holds still (the root, about itself) is not blown up
VERSION = 1  # part of the cache key: a change to the training or the features makes new encoders
CACHE_FOLDER = "gesture_encoders"


def cache_folder(env=None):
    """$XDG_CACHE_HOME/moglow-eval/gesture_encoders, else ~/.cache/moglow-eval/gesture_encoders."""
    env = os.environ if env is None else env
    return Path(env.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "moglow-eval" / CACHE_FOLDER


def _derivative(rows, fps):
    """Per-frame rate of change of rows [T, D], the first frame's taken as the next one's."""
    d = np.diff(rows, axis=0, prepend=rows[:1]) * fps
    if len(d) > 1:
        d[0] = d[1]
    return d


def pose_rows(joints, parents, fps):
    """A clip's frames as rows of joint positions about the root, their velocities and their accelerations [T, 9J]
    (float32; m, m/s, m/s^2)."""
    rel = joint_groups.about_root(joints, parents).reshape(len(joints), -1)
    vel = _derivative(rel, fps)
    return np.concatenate([rel, vel, _derivative(vel, fps)], axis=1).astype(np.float32)


@contextlib.contextmanager
def _one_thread(torch):
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


class GestureEncoder:
    """The encoder of one study, with its standardisation: `features(joints)` gives a clip's chunk features."""

    def __init__(self, net, mean, std, parents, fps):
        self.net, self.mean, self.std, self.parents, self.fps = net, mean, std, parents, fps

    def features(self, joints):
        """A clip's chunk features [n_chunks, FEATURES] (float64); none for a clip shorter than fmd.CHUNK frames."""
        rows = (pose_rows(joints, self.parents, self.fps) - self.mean) / self.std
        if len(rows) < CHUNK:
            return np.zeros((0, FEATURES))
        return encode_windows(self.net, rows[None])

    @classmethod
    def train(cls, clips, parents, fps, seed=0, steps=STEPS, cache=None):
        """The encoder of the reference's `clips` (joints [T, J, 3] each, at `fps`), trained or read from `cache` (a
        folder; None: cache_folder(); False: no cache)."""
        import torch

        rows = [pose_rows(j, parents, fps) for j in clips]
        data = np.concatenate(rows)
        mean, std = data.mean(axis=0), np.maximum(data.std(axis=0), MIN_SPREAD).astype(np.float32)
        key = _key(rows, parents, fps, seed, steps)
        folder = cache_folder() if cache is None else cache
        net = _cached(folder, key, data.shape[1]) if folder else None
        if net is None:
            t0 = time.perf_counter()
            net = _fit(torch, [(r - mean) / std for r in rows], data.shape[1], seed, steps)
            log.info("gesture encoder: trained on %d reference clips in %.1f s", len(rows), time.perf_counter() - t0)
            if folder:
                _store(folder, key, net)
        return cls(net, mean, std, parents, fps)


def _key(rows, parents, fps, seed, steps):
    h = hashlib.sha256(
        f"v{VERSION} chunk {CHUNK} fps {fps:g} hidden {HIDDEN} steps {steps} batch {BATCH} lr {LR} seed {seed}".encode()
    )
    h.update(np.asarray(parents, np.int64).tobytes())
    for r in rows:
        h.update(np.int64(len(r)).tobytes())
        h.update(np.ascontiguousarray(r).tobytes())
    return h.hexdigest()[:32]


def _fit(torch, rows, dim, seed, steps):
    """The autoencoder trained on random chunks of the standardised clips `rows` ([T, dim] each)."""
    starts = [(k, s) for k, r in enumerate(rows) for s in range(len(r) - CHUNK + 1)]
    if not starts:
        raise ValueError(f"no reference clip is {CHUNK} frames long")
    rng = np.random.default_rng(seed)
    with _one_thread(torch):
        torch.manual_seed(seed)
        net = MotionAutoencoder(pose_dim=dim, hidden=HIDDEN)
        opt = torch.optim.Adam(net.parameters(), lr=LR)
        for _ in range(steps):
            pick = rng.integers(0, len(starts), BATCH)
            x = torch.from_numpy(np.stack([rows[starts[i][0]][starts[i][1] : starts[i][1] + CHUNK] for i in pick]))
            loss = (net(x) - x).pow(2).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
    net.eval()
    return net


def _cached(folder, key, dim):
    """The cached network of `key`, or None (absent, or unreadable: trained again)."""
    from ..data.torch_files import load_torch_file

    path = Path(folder) / f"{key}.pt"
    if not path.is_file():
        return None
    try:
        net = MotionAutoencoder(pose_dim=dim, hidden=HIDDEN)
        net.load_state_dict(load_torch_file(path))
    except Exception as e:  # any damage to a cache file: train again
        log.warning("note: the cached gesture encoder %s cannot be read (%s); training it again", path, e)
        return None
    net.eval()
    return net


def _store(folder, key, net):
    import torch

    path = Path(folder) / f"{key}.pt"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        torch.save(net.state_dict(), tmp)
        tmp.replace(path)
    except OSError as e:
        log.warning("note: cannot cache the gesture encoder in %s (%s); it is trained again next time", folder, e)


# ---------------------------------------------------------------- distances
def moments(features):
    """(n, sum, sum of outer products) of features [n, d]: moments add, so a reference less an item is a subtraction."""
    f = np.asarray(features, np.float64)
    return len(f), f.sum(axis=0), f.T @ f


def gaussian(m):
    """(mean, covariance) from moments (n, sum, sum of outer products); the covariance with n - 1."""
    n, s1, s2 = m
    mu = s1 / n
    return mu, (s2 - n * np.outer(mu, mu)) / max(n - 1, 1)


def frechet(a, b):
    """The Fréchet distance between Gaussians a and b, each (mean, covariance), exact for singular covariances."""
    (mu_a, cov_a), (mu_b, cov_b) = a, b
    w, v = np.linalg.eigh((cov_a + cov_a.T) / 2)
    root_a = (v * np.sqrt(np.clip(w, 0, None))) @ v.T
    inner = root_a @ cov_b @ root_a
    cross = np.sqrt(np.clip(np.linalg.eigvalsh((inner + inner.T) / 2), 0, None)).sum()
    # A distance is never below 0: what rounding leaves there (about 1e-8 of the traces) is 0.
    return max(0.0, float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a) + np.trace(cov_b) - 2 * cross))


def fgd(features_a, features_b):
    """FGD between two sets of chunk features [n, d] (nan where either has fewer than two chunks)."""
    if len(features_a) < 2 or len(features_b) < 2:
        return float("nan")
    return frechet(gaussian(moments(features_a)), gaussian(moments(features_b)))


def diversity(clip_features):
    """The mean Euclidean distance between every two of the clips' features [n_clips, d] (nan for under two)."""
    f = np.asarray(clip_features, np.float64)
    if len(f) < 2:
        return float("nan")
    d = np.linalg.norm(f[:, None] - f[None, :], axis=-1)
    return float(d[np.triu_indices(len(f), 1)].mean())
