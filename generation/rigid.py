"""Rigid bones: generated poses put back onto the skeleton of the item's actor (issue 34, item 1).

MG and FL model free joint positions (MoGlow §5.1: 21 joints x xyz), so nothing in the flow keeps a bone's
length: the shipped MG's shins vary by 24 mm within a window and FL's forearms come out 10-15% long, while
real bones are rigid. A projection after sampling keeps the models as the paper has them (the same flows, the
same exact likelihood) and gives every generated clip the actor's bones: each joint keeps the direction from its
parent that the model sampled, at the actor's length, placed from the parent outwards, so the hips (and with them
the path and the control) stay where the model put them. `make_stimuli` applies it to every generated test
condition alike (MG and FL; the bad examples stay as they are, broken on purpose) and records it in the
manifest's `postprocess` column (CONTRACTS §4). bench/RESULTS.md gives what it does to every metric.
"""

import numpy as np

from . import skeleton

RIGID = "rigid_bones"  # the manifest's postprocess value for a projected clip


def bone_lengths(poses, parents=skeleton.PARENTS):
    """Each bone's length [..., J-1] (the bone ending at joint k >= 1), averaged over the frames of poses
    [..., T, J*3] or [..., T, J, 3]: the actor's skeleton, read from real frames (an item's history)."""
    j = _joints(poses, len(parents))
    return np.linalg.norm(j[..., 1:, :] - j[..., parents[1:], :], axis=-1).mean(-2)


# Two-bone chains whose far joint can keep its place (hip, knee, ankle), so that a planted foot stays planted while
# the knee bends to reach it. Measured and not the default (bench/rigid_bones.py, bench/RESULTS.md): where the
# model's leg is longer than the actor's the foot must be pulled in anyway, and the knee, bending in the model's
# plane of an almost straight leg, jerks 1.5-2x NAT's; placing joints along their directions adds less skating
# (MG 1.9x -> 2.4x NAT's) and no jerk.
LEGS = tuple(tuple(skeleton.INDEX[f"{j}_{side}"] for j in ("UpperLeg", "LowerLeg", "Foot")) for side in ("L", "R"))


def fit_bones(poses, lengths, parents=skeleton.PARENTS, chains=()):
    """poses [..., T, J*3] (or [..., T, J, 3]) with every bone set to `lengths` [..., J-1] (per window, or one
    skeleton for all), the same shape and dtype back. Each joint keeps the direction from its parent that the
    model sampled, placed from the root outwards; in each (top, middle, end) joint chain of `chains` the end
    keeps its place where the two bones reach it (else it is pulled in along the line to it) and the middle
    joint bends in the plane the model bent it in (two-bone inverse kinematics). A bone the model collapsed to a
    point keeps its child on its parent."""
    poses = np.asarray(poses)
    j = _joints(poses, len(parents)).astype(np.float64)
    lengths = np.asarray(lengths, dtype=np.float64)[..., None, :, None]  # over frames and xyz
    out = j.copy()
    middle = {mid: (top, end) for top, mid, end in chains}
    ends = {end for _, _, end in chains}
    for k in _parent_first(parents):
        if k in ends:
            continue  # placed with its chain's middle joint
        p = parents[k]
        if k in middle:
            top, end = middle[k]
            out[..., k, :], out[..., end, :] = _two_bones(
                out[..., top, :], j[..., k, :], j[..., end, :], lengths[..., k - 1, :], lengths[..., end - 1, :]
            )
            continue
        out[..., k, :] = out[..., p, :] + _unit(j[..., k, :] - j[..., p, :]) * lengths[..., k - 1, :]
    return out.reshape(poses.shape).astype(poses.dtype)


def fit_to_history(x, history):
    """Generated windows x [B, T, 63] put onto the bones of each window's actor, read from its real history
    [B, tau, 63]: what make_stimuli ships for MG and FL, and what the quality guard measures."""
    return fit_bones(x, bone_lengths(history))


def _unit(v):
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, norm, out=np.zeros_like(v), where=norm > 1e-9)


def _two_bones(top, mid, end, a, b):
    """The middle and end joints of a chain from `top` (placed) with bone lengths a (top-middle) and b
    (middle-end): the end at its target `end` where a and b reach it, the middle in the plane of (top, mid, end)."""
    to_end = end - top
    d = np.linalg.norm(to_end, axis=-1, keepdims=True)
    u = _unit(to_end)
    d = np.clip(d, np.abs(a - b) + 1e-6, a + b - 1e-6)
    bend = mid - top
    v = _unit(bend - (bend * u).sum(-1, keepdims=True) * u)  # the model's bend direction, across the line
    cos = np.clip((a * a + d * d - b * b) / (2 * a * d), -1.0, 1.0)
    new_mid = top + a * (cos * u + np.sqrt(1.0 - cos * cos) * v)
    return new_mid, top + d * u


def _joints(poses, n_joints):
    poses = np.asarray(poses)
    return (
        poses
        if poses.shape[-1] == 3 and poses.shape[-2] == n_joints
        else poses.reshape(poses.shape[:-1] + (n_joints, 3))
    )


def _parent_first(parents):
    """Joints 1.. (joint 0 is the root, as in every skeleton of the project) in an order that places every parent
    before its children."""
    placed, order = {0}, []
    while len(order) < len(parents) - 1:
        for k, p in enumerate(parents):
            if k not in placed and p in placed:
                placed.add(k)
                order.append(k)
    return order
