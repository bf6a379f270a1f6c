"""Motion clip files (CONTRACTS.md §1): world joint positions in metres, Y up, floor at y = 0."""
from pathlib import Path

import numpy as np
from core.cli import UserError


class ClipError(UserError):
    """A clip file that does not follow CONTRACTS.md §1; the message names the file and key."""


def save_clip(path, joints, parents, joint_names, fps, control=None, **extra):
    """Write a clip .npz. `extra` keys are stored too (the contract allows added keys)."""
    joints = np.asarray(joints, dtype=np.float32)
    if joints.ndim != 3 or joints.shape[2] != 3:
        raise ClipError(f"{path}: joints must be [T, J, 3], got {joints.shape}")
    arrays = dict(joints=joints, parents=np.asarray(parents, dtype=np.int64),
                  joint_names=np.asarray(joint_names, dtype=str), fps=np.float64(fps), **extra)
    if control is not None:
        arrays["control"] = np.asarray(control, dtype=np.float32)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)


def load_clip(path):
    """Read and check a clip .npz; returns a dict with at least joints, parents, joint_names, fps."""
    try:
        with np.load(path, allow_pickle=False) as f:
            d = {k: f[k] for k in f.files}
    except (OSError, ValueError) as e:
        raise ClipError(f"{path}: not a readable .npz clip ({e})") from None
    for key in ("joints", "parents", "joint_names", "fps"):
        if key not in d:
            raise ClipError(f"{path}: missing key '{key}'")
    j = d["joints"]
    if j.ndim != 3 or j.shape[2] != 3:
        raise ClipError(f"{path}: 'joints' must be [T, J, 3], got {j.shape}")
    if d["parents"].shape != (j.shape[1],) or d["joint_names"].shape != (j.shape[1],):
        raise ClipError(f"{path}: 'parents' and 'joint_names' must have J={j.shape[1]} entries")
    if "control" in d and d["control"].shape != (j.shape[0], 3):
        raise ClipError(f"{path}: 'control' must be [T, 3], got {d['control'].shape}")
    d["joints"] = j.astype(np.float32)
    d["fps"] = float(d["fps"])
    d["joint_names"] = [str(n) for n in d["joint_names"]]
    return d
