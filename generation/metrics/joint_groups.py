"""The joint groups of the gesture measures (GENEA 2022's hands, arms and head), found by name in any skeleton.

A joint's name is cut into words by moglow_eval.core.skeleton_names.tokens (`LeftForeArm` -> left, fore, arm;
`b_l_wrist` -> b, l, wrist; `left_index1` -> left, index). Then:
- hands: a hand or wrist joint, or a finger joint (skeleton_names.FINGER_WORDS);
- arms: a shoulder, collar, clavicle, arm or elbow joint that is not a hand's;
- head: the head, the neck, or a face joint (skeleton_names.FACE_WORDS).
The wrists (a hand joint that is not a finger's) carry the motion beats of BeatAlign (gesture_timing).
Positions are measured about the skeleton's root (its first joint without a parent), so that walking or turning on
the spot does not count as a gesture.
"""

import numpy as np

from moglow_eval.core.skeleton_names import FACE_WORDS, FINGER_WORDS, tokens

HAND_WORDS = {"hand", "hands", "wrist", "palm"}
ARM_WORDS = {"arm", "forearm", "upperarm", "lowerarm", "elbow", "shoulder", "collar", "clavicle"}
HEAD_WORDS = {"head", "neck"}


def group_of(name):
    """'hands', 'arms', 'head' or None for a joint name (see the module's docstring)."""
    words = set(tokens(name))
    if words & (HAND_WORDS | FINGER_WORDS):
        return "hands"
    if words & ARM_WORDS:
        return "arms"
    if words & (HEAD_WORDS | FACE_WORDS):
        return "head"
    return None


def groups(names):
    """{group: [joint indices]} of the groups the skeleton has (a group it lacks is absent)."""
    out = {}
    for j, name in enumerate(names):
        g = group_of(name)
        if g is not None:
            out.setdefault(g, []).append(j)
    return out


def wrists(names):
    """Indices of the hand joints that are not fingers' (a wrist or a hand), where BeatAlign reads the beats."""
    return [j for j, name in enumerate(names) if group_of(name) == "hands" and not set(tokens(name)) & FINGER_WORDS]


def root_index(parents):
    """The skeleton's root: its first joint without a parent."""
    return int(np.flatnonzero(np.asarray(parents) < 0)[0])


def about_root(joints, parents):
    """Joint positions [T, J, 3] less the root's in each frame (float64)."""
    joints = np.asarray(joints, dtype=np.float64)
    return joints - joints[:, root_index(parents)][:, None]
