"""MoGlow features (CONTRACTS.md §2): 21 joints in the floor-projected root frame plus root control.

Conventions
- World: metres, Y up. Heading `yaw` is the rotation about +Y that takes +Z to the facing direction,
  so facing = (sin yaw, 0, cos yaw); the character's left is +X in its own root frame.
- Root: the hips projected on the floor (y = 0); facing from the across-vector (left minus right of
  the hips and of the shoulders), horizontal, Gaussian-smoothed over `FACING_SMOOTH_S` seconds.
- x[t] (63 values): the 21 joints of `skeleton.JOINT_NAMES` relative to the root of frame t, in its
  frame (x = left, y = up, z = forward).
- c[t] = (forward, sideways, yaw): the root's displacement from frame t-1 to t, expressed in the
  root frame of t-1 (sideways positive to the left), and yaw[t] - yaw[t-1] (positive = turning left).
  c[0] has no previous frame; `to_features` copies c[1] there, and `to_world` ignores c[0].
"""

import numpy as np
from scipy.ndimage import gaussian_filter1d

from moglow_eval.core.clip import check_frames

from . import skeleton
from .bvh import BvhError, forward_kinematics, read_bvh
from .resample import clean_fps, local_quaternions, local_quaternions_at, quat_to_matrix, resample_times

FACING_SMOOTH_S = 0.25  # sigma of the Gaussian smoothing the facing direction (s)

# Named joint maps per source skeleton: each of the 21 project joints is a source joint, or a point
# (a, b, w) = a + w (b - a) on a bone (CMU has no separate clavicle start: its shoulder joint sits
# on the spine, so our Shoulder is placed a third of the way towards the upper arm; still rigid).
SKELETON_MAPS = {
    "bandai-namco": {
        "detect": {"joint_Root", "Hips", "UpperLeg_L", "UpperArm_R"},
        "scale": 0.01,  # centimetres
        "map": {n: n for n in skeleton.JOINT_NAMES},
    },
    "cmu": {
        "detect": {"Hips", "LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm", "Spine1"},
        "scale": 2.54 / 0.45 / 100,  # CMU units: inches / 0.45 (as in the ASF files), i.e. 5.64 cm
        "map": {
            "Hips": "Hips",
            "Spine": "Spine",
            "Chest": "Spine1",
            "Neck": "Neck1",
            "Head": "Head",
            "Shoulder_L": ("LeftShoulder", "LeftArm", 1 / 3),
            "UpperArm_L": "LeftArm",
            "LowerArm_L": "LeftForeArm",
            "Hand_L": "LeftHand",
            "Shoulder_R": ("RightShoulder", "RightArm", 1 / 3),
            "UpperArm_R": "RightArm",
            "LowerArm_R": "RightForeArm",
            "Hand_R": "RightHand",
            "UpperLeg_L": "LeftUpLeg",
            "LowerLeg_L": "LeftLeg",
            "Foot_L": "LeftFoot",
            "Toes_L": "LeftToeBase",
            "UpperLeg_R": "RightUpLeg",
            "LowerLeg_R": "RightLeg",
            "Foot_R": "RightFoot",
            "Toes_R": "RightToeBase",
        },
    },
}

_I = skeleton.INDEX


def detect_skeleton(names, where):
    """Name of the joint map that fits these joint names; BvhError naming `where` when none does, or
    when the names look like a known skeleton that lacks a joint the map needs."""
    names = set(names)
    for key, spec in SKELETON_MAPS.items():
        if spec["detect"] <= names:
            needed = [n for src in spec["map"].values() for n in ((src,) if isinstance(src, str) else src[:2])]
            missing = [n for n in dict.fromkeys(needed) if n not in names]
            if missing:
                raise BvhError(f"{where}: looks like a {key} skeleton but has no joint '{missing[0]}'")
            return key
    raise BvhError(
        f"{where}: unknown skeleton (joints {', '.join(sorted(names)[:6])}, ...); known: {', '.join(SKELETON_MAPS)}"
    )


def map_joints(positions, names, key):
    """Pick the 21 project joints [T, 21, 3] out of source positions [T, J, 3] with map `key`."""
    idx = {n: i for i, n in enumerate(names)}
    out = np.empty(positions.shape[:1] + (skeleton.N_JOINTS, 3), dtype=positions.dtype)
    for j, name in enumerate(skeleton.JOINT_NAMES):
        src = SKELETON_MAPS[key]["map"][name]
        if isinstance(src, str):
            out[:, j] = positions[:, idx[src]]
        else:
            a, b, w = src
            out[:, j] = positions[:, idx[a]] + w * (positions[:, idx[b]] - positions[:, idx[a]])
    return out


def bvh_world_positions(bvh, fps=None):
    """FK positions [T, J, 3] of all joints of a Bvh in file units, resampled to `fps` (None: native)."""
    fps_in = clean_fps(bvh.fps)
    if fps is not None:
        check_frames(len(resample_times(bvh.n_frames, fps_in, float(fps))), f"{bvh.path}: resampled to {fps:g} fps")
    q, trans = local_quaternions(bvh) if fps is None else local_quaternions_at(bvh, fps_in, float(fps))
    pos, _ = forward_kinematics(bvh.parents, quat_to_matrix(q), trans)
    return pos


def load_take(path, fps=20.0):
    """A BVH take as 21 joints [T, 21, 3] float32, metres, Y up, resampled to `fps`."""
    bvh = read_bvh(path)
    if bvh.n_frames < 2:
        raise BvhError(f"{path}:1: take has {bvh.n_frames} frame(s); need at least 2")
    key = detect_skeleton(bvh.names, f"{path}:1")
    pos = bvh_world_positions(bvh, fps)
    return (map_joints(pos, bvh.names, key) * SKELETON_MAPS[key]["scale"]).astype(np.float32)


def root_trajectory(joints, fps=20.0):
    """Root position on the floor [T, 2] (x, z) and unwrapped heading yaw [T] (rad) of joints [T, 21, 3]."""
    joints = _np(joints, np.float64)
    across = (
        joints[:, _I["UpperLeg_L"]]
        - joints[:, _I["UpperLeg_R"]]
        + joints[:, _I["UpperArm_L"]]
        - joints[:, _I["UpperArm_R"]]
    )
    # forward = across x up, horizontal
    fwd = np.stack([-across[:, 2], across[:, 0]], axis=-1)  # (x, z)
    fwd /= np.maximum(np.linalg.norm(fwd, axis=-1, keepdims=True), 1e-9)
    if len(fwd) > 1:
        fwd = gaussian_filter1d(fwd, FACING_SMOOTH_S * fps, axis=0, mode="nearest")
    yaw = np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 1]))
    return joints[:, _I["Hips"]][:, [0, 2]], yaw


def _np(a, dtype=None):
    """numpy view of an array-like; torch tensors (any device) are detached and copied to the CPU."""
    if hasattr(a, "detach"):
        a = a.detach().cpu().numpy()
    return np.asarray(a, dtype=dtype)


def rotate_y(v, yaw):
    """Rotate vectors v [..., 3] (or [..., 2] as (x, z)) about +Y by yaw [...]: the one yaw rotation of the
    project (features, their inverse, time reversal and systems.canonical_placement all use it)."""
    c, s = np.cos(yaw), np.sin(yaw)
    if v.shape[-1] == 2:
        return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], -1)
    return np.stack([c * v[..., 0] + s * v[..., 2], v[..., 1], -s * v[..., 0] + c * v[..., 2]], -1)


def to_features(joints, fps=20.0):
    """joints [T, 21, 3] (metres) -> (x float32 [T, 63], c float32 [T, 3]); see the module docstring."""
    joints = _np(joints, np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (skeleton.N_JOINTS, 3):
        raise ValueError(f"to_features: joints must be [T, {skeleton.N_JOINTS}, 3], got {joints.shape}")
    T = joints.shape[0]
    root, yaw = root_trajectory(joints, fps)
    rel = joints.copy()
    rel[..., 0] -= root[:, None, 0]
    rel[..., 2] -= root[:, None, 1]
    x = rotate_y(rel, -yaw[:, None]).reshape(T, skeleton.POSE_DIM)
    c = np.zeros((T, skeleton.CONTROL_DIM))
    if T > 1:
        step = rotate_y(np.diff(root, axis=0), -yaw[:-1])  # (sideways, forward) in frame t-1
        c[1:, 0] = step[:, 1]
        c[1:, 1] = step[:, 0]
        c[1:, 2] = np.diff(yaw)
        c[0] = c[1]
    return x.astype(np.float32), c.astype(np.float32)


def to_world(x, c, start_xz=(0.0, 0.0), start_yaw=0.0):
    """Integrate control back to world joints [..., T, 21, 3] float32 (inverse of `to_features`).

    The root of frame 0 is placed at `start_xz` with heading `start_yaw`; c[..., 0, :] is ignored.
    """
    x = _np(x, np.float64)
    c = _np(c, np.float64)
    if x.shape[-1] != skeleton.POSE_DIM or c.shape[-1] != skeleton.CONTROL_DIM or x.shape[:-1] != c.shape[:-1]:
        raise ValueError(f"to_world: need x [..., T, 63] and c [..., T, 3], got {x.shape} and {c.shape}")
    yaw = _np(start_yaw, np.float64)[..., None] + np.concatenate(
        [np.zeros(c.shape[:-1][:-1] + (1,)), np.cumsum(c[..., 1:, 2], axis=-1)], axis=-1
    )
    step = rotate_y(np.stack([c[..., 1:, 1], c[..., 1:, 0]], -1), yaw[..., :-1])  # world (x, z)
    start = _np(start_xz, np.float64)
    root = np.concatenate([np.zeros(step.shape[:-2] + (1, 2)), np.cumsum(step, axis=-2)], axis=-2) + start[..., None, :]
    local = x.reshape(x.shape[:-1] + (skeleton.N_JOINTS, 3))
    world = rotate_y(local, yaw[..., None])
    world[..., 0] += root[..., None, 0]
    world[..., 2] += root[..., None, 1]
    return world.astype(np.float32)


_MIRROR_IDX = (skeleton.MIRROR[:, None] * 3 + np.arange(3)).ravel()
_MIRROR_SIGN = np.tile([-1.0, 1.0, 1.0], skeleton.N_JOINTS)


def mirror(x, c):
    """Left/right mirror image: swap _L/_R joints, reflect x; sideways and yaw control change sign."""
    x = _np(x)
    c = _np(c)
    return ((x[..., _MIRROR_IDX] * _MIRROR_SIGN).astype(x.dtype), (c * np.array([1.0, -1.0, -1.0])).astype(c.dtype))


def _reverse_step(c):
    """Control of the reversed step: the same root move backwards, seen from the frame it arrives at."""
    d = -c[..., 2]
    # -R(-yaw_step) applied to (side, fwd) as an (x, z) vector
    back = rotate_y(np.stack([c[..., 1], c[..., 0]], axis=-1), d)
    return np.stack([-back[..., 1], -back[..., 0], d], axis=-1)


def reverse(x, c):
    """Time reversal: frames in reverse order, control of every step reversed (an involution).

    c'[t] for t >= 1 is the reversed step c[T - t]; c'[0] (no previous frame) holds the reversed c[0],
    which keeps reverse(reverse(.)) exact; to_world ignores it.
    """
    x = _np(x)
    c = _np(c)
    rc = _reverse_step(c.astype(np.float64))
    c_new = np.concatenate([rc[..., :1, :], rc[..., 1:, :][..., ::-1, :]], axis=-2)
    return x[..., ::-1, :].copy(), c_new.astype(c.dtype)
