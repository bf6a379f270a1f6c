"""Rigid bones: generated poses put back onto the skeleton of the item's actor.

MG and FL model free joint positions (MoGlow §5.1: 21 joints x xyz), so nothing in the flow keeps a bone's length:
the shipped MG's shins and FL's forearms change length within a window, while real bones are rigid. A projection
after sampling keeps the models as the paper has them (the same flows, the same exact likelihood) and gives every
generated clip the actor's bones. From the hips outwards, each joint goes to the point nearest to where the model
put it at the actor's bone length from its (already placed) parent, so an error of one bone's length does not carry
down the limb: a foot the model planted stays within its shin's length error of where it was, and the hips (with
them the path and the control) stay where the model put them. `make_stimuli` applies it to every generated test
condition alike (MG and FL; the bad examples stay as they are, broken on purpose) and records it in the manifest's
`postprocess` column (CONTRACTS §4). bench/rigid_bones.py measures what it does to every figure, beside keeping each
bone's sampled direction instead (the foot then carries every length error of its leg, and skates more:
bench/RESULTS.md#model-realism).

Bone lengths are not the skeleton's only rigidity: a joint with several children (the hips with the spine and both
thighs, the chest with the neck and both shoulders) places them all by its one rotation, so they keep one shape in
every real frame. `fit_skeleton` holds that too (Realism III: the exact invariants of the data held in what ships),
and it is what `fit_to_history`, and so the manifest's `rigid_skeleton` step, applies.
"""

import numpy as np

from . import skeleton

RIGID = "rigid_skeleton"  # the manifest's postprocess value for a clip put onto the actor's rigid skeleton


def frame_bone_lengths(poses, parents=skeleton.PARENTS):
    """Each bone's length in every frame [..., T, J-1] (the bone ending at joint k >= 1) of poses [..., T, J*3] or
    [..., T, J, 3]."""
    j = _joints(poses, len(parents))
    return np.linalg.norm(j[..., 1:, :] - j[..., parents[1:], :], axis=-1)


def bone_lengths(poses, parents=skeleton.PARENTS):
    """Each bone's length [..., J-1] averaged over the frames of poses: the actor's skeleton, read from real frames
    (an item's history)."""
    return frame_bone_lengths(poses, parents).mean(-2)


def fit_bones(poses, lengths, parents=skeleton.PARENTS):
    """poses [..., T, J*3] (or [..., T, J, 3]) with every bone set to `lengths` [..., J-1] (per window, or one
    skeleton for all), the same shape and dtype back. Joint 0, the root, stays; every other joint, parents first,
    goes to the point at its bone's length from its placed parent that is nearest to where the model put it. A
    joint the model put on its parent's new place (no direction) stays on it."""
    poses = np.asarray(poses)
    j = _joints(poses, len(parents)).astype(np.float64)
    lengths = np.asarray(lengths, dtype=np.float64)[..., None, :, None]  # over frames and xyz
    out = j.copy()
    for k in _parent_first(parents):
        out[..., k, :] = _along_bone(j[..., k, :], out[..., parents[k], :], lengths[..., k - 1, :])
    return out.reshape(poses.shape).astype(poses.dtype)


def _along_bone(joint, parent, length):
    """The point at `length` from the placed `parent` nearest to where the model put `joint` (the parent itself
    where the model put the joint on it: no direction)."""
    bone = joint - parent
    norm = np.linalg.norm(bone, axis=-1, keepdims=True)
    return parent + np.divide(bone, norm, out=np.zeros_like(bone), where=norm > 1e-9) * length


def rigid_groups(parents=skeleton.PARENTS):
    """{joint: its children} for every joint with two or more children. A BVH joint's rotation places all its
    children at once, so in real motion they and the joint move as one rigid body: the hips with the spine and both
    thighs (the hip width never changes), the chest with the neck and both shoulders."""
    children = {}
    for k, p in enumerate(parents):
        if p >= 0:
            children.setdefault(int(p), []).append(k)
    return {p: ks for p, ks in children.items() if len(ks) >= 2}


def fit_skeleton(poses, reference, parents=skeleton.PARENTS):
    """poses [..., T, J*3] (or [..., T, J, 3]) put onto the skeleton of one real frame reference [..., J*3] (or
    [..., J, 3]; per window, or one for all), the same shape and dtype back. As fit_bones, parents first, with one
    more rule: the children of a joint with two or more (rigid_groups) are placed together, as the reference's
    shape turned by the rotation that best fits where the model put them (Kabsch's least squares), so the hip and
    shoulder widths and the angles between the spine and the thighs are the actor's, as they are in every real
    frame. Every other joint goes along the model's direction at the reference's bone length."""
    poses = np.asarray(poses)
    j = _joints(poses, len(parents)).astype(np.float64)
    ref = _joints(np.asarray(reference), len(parents)).astype(np.float64)[..., None, :, :]  # over frames
    lengths = np.linalg.norm(ref[..., 1:, :] - ref[..., parents[1:], :], axis=-1)[..., None]
    groups = rigid_groups(parents)
    order = _parent_first(parents)
    first = {p: next(k for k in order if k in kids) for p, kids in groups.items()}  # places the whole group
    out = j.copy()
    for k in order:
        p = parents[k]
        if p not in groups:
            out[..., k, :] = _along_bone(j[..., k, :], out[..., p, :], lengths[..., k - 1, :])
        elif k == first[p]:
            kids = groups[p]
            shape = ref[..., kids, :] - ref[..., [p], :]  # [..., 1, n, 3]
            model = j[..., kids, :] - out[..., [p], :]  # [..., T, n, 3]
            out[..., kids, :] = out[..., [p], :] + shape @ _best_rotation(shape, model).swapaxes(-1, -2)
    return out.reshape(poses.shape).astype(poses.dtype)


def _best_rotation(a, b):
    """The rotations R [..., 3, 3] that best turn point sets a [..., n, 3] onto b [..., n, 3] (least squares over
    the n points, det R = +1: Kabsch's algorithm)."""
    h = np.swapaxes(a, -1, -2) @ b  # [..., 3, 3]
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
    fix = np.ones(d.shape + (3,))
    fix[..., 2] = np.where(d == 0, 1.0, d)
    return np.swapaxes(vt, -1, -2) @ (fix[..., :, None] * np.swapaxes(u, -1, -2))


def fit_to_history(x, history):
    """Generated windows x [B, T, 63] put onto the rigid skeleton of each window's actor, read from the last frame
    of its real history [B, tau, 63] (fit_skeleton): what make_stimuli ships for MG and FL, and what the quality
    guard measures."""
    return fit_skeleton(x, np.asarray(history)[:, -1])


def _joints(poses, n_joints):
    poses = np.asarray(poses)
    if poses.shape[-2:] == (n_joints, 3):
        return poses
    return poses.reshape(poses.shape[:-1] + (n_joints, 3))


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
