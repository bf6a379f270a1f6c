"""Speed and acceleration histograms of a joint group, and the Hellinger distance between two of them (GENEA 2022's
numerical evaluation, after Kucherenko et al. 2021).

Each joint's speed (m/s) and acceleration (m/s^2) about the root (joint_groups.about_root) in every frame pair or
triple, pooled over the group's joints and the clips, counted in fixed bins: SPEED_BINS of SPEED_STEP m/s from 0 and
ACCEL_BINS of ACCEL_STEP m/s^2 from 0, the last bin of each taking everything above it (GENEA's bins end at their
top; here nothing is dropped). Two histograms p and q, each scaled to sum to 1, are

    H(p, q) = sqrt(1 - sum_k sqrt(p_k q_k)),

0 for the same shape, 1 for histograms with no bin in common. A clip is compared with the reference's pooled
histogram; counts add, so the reference without one item is its total less that item's.
"""

import numpy as np

from . import joint_groups

SPEED_STEP, SPEED_BINS = 0.05, 60  # m/s: 0 .. 3 m/s, then everything faster
ACCEL_STEP, ACCEL_BINS = 1.0, 60  # m/s^2: 0 .. 60 m/s^2, then everything above
KINDS = ("speed", "accel")


def _counts(values, step, n_bins):
    idx = np.minimum((np.asarray(values, float).ravel() / step).astype(np.int64), n_bins - 1)
    return np.bincount(idx[idx >= 0], minlength=n_bins).astype(np.float64)


def histograms(joints, fps, idx, parents):
    """{"speed": counts [SPEED_BINS], "accel": counts [ACCEL_BINS]} of the joints `idx` of a clip [T, J, 3]."""
    rel = joint_groups.about_root(joints, parents)[:, idx]
    speed = np.linalg.norm(np.diff(rel, axis=0), axis=-1) * fps
    accel = np.linalg.norm(np.diff(rel, n=2, axis=0), axis=-1) * fps**2
    return {"speed": _counts(speed, SPEED_STEP, SPEED_BINS), "accel": _counts(accel, ACCEL_STEP, ACCEL_BINS)}


def hellinger(p, q):
    """The Hellinger distance between two histograms (counts; each scaled to sum 1); nan where either is empty."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    if p.sum() <= 0 or q.sum() <= 0:
        return float("nan")
    bc = np.sum(np.sqrt(p / p.sum() * q / q.sum()))
    return float(np.sqrt(max(0.0, 1.0 - bc)))
