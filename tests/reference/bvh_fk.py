"""BVH forward kinematics the plain way (rotation matrices straight from the Euler channels): the reference for
the product's quaternion path (generation.motion.resample.local_quaternions + bvh.forward_kinematics)."""

import numpy as np

from generation.motion.bvh import AXIS, forward_kinematics


def _axis_rotations(axis, degrees):
    """Rotation matrices [T, 3, 3] about one coordinate axis (0=X, 1=Y, 2=Z)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def local_transforms(bvh, frames=None):
    """Local rotation matrices [T, J, 3, 3] and translations [T, J, 3] of every joint.

    `frames` optionally selects frames (index or slice) before any work is done.
    """
    motion = bvh.motion if frames is None else bvh.motion[frames]
    T, J = motion.shape[0], len(bvh.names)
    rot = np.broadcast_to(np.eye(3), (T, J, 3, 3)).copy()
    trans = np.broadcast_to(bvh.offsets, (T, J, 3)).copy()
    for j, (chans, col) in enumerate(zip(bvh.channels, bvh.channel_columns())):
        R = None
        for k, ch in enumerate(chans):
            axis = AXIS[ch[0]]
            if ch.endswith("position"):
                trans[:, j, axis] = motion[:, col + k]
            else:
                Ra = _axis_rotations(axis, motion[:, col + k])
                R = Ra if R is None else R @ Ra
        if R is not None:
            rot[:, j] = R
    return rot, trans


def fk_positions(bvh, end_sites=False):
    """World positions [T, J, 3] of every joint in file units (End Sites appended when asked)."""
    rot, trans = local_transforms(bvh)
    pos, g_rot = forward_kinematics(bvh.parents, rot, trans)
    if end_sites and bvh.end_sites:
        ends = [pos[:, p] + g_rot[:, p] @ off for p, off in bvh.end_sites]
        pos = np.concatenate([pos, np.stack(ends, axis=1)], axis=1)
    return pos
