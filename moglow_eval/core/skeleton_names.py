"""What a joint's name says about it, for any skeleton: its side, and whether it is a finger or face joint.

Skeletons name sides in many ways: `LeftArm` (CMU, Mixamo `mixamorig:LeftArm`), `UpperArm_L` (Bandai-Namco),
`b_l_shoulder` (GENEA), `L_Wrist`, `lShldr` (DAZ/Poser), `Bip01 L Hand` (3ds Max). A name is cut into tokens at
`_ . : - ` and spaces and at lower-to-upper case changes; a token `left`/`l` or `right`/`r` gives the side.
The renderer colours limbs by side (a neutral colour where no side can be told) and draws finger and face
bones thinner; the metrics find the feet by side.
"""

import re

_TOKEN = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|[0-9]+")
_LEFT, _RIGHT = {"left", "l"}, {"right", "r"}
FINGER_WORDS = {"thumb", "index", "middle", "ring", "pinky", "pinkie", "little", "finger", "fingers", "carpal"}
FACE_WORDS = {
    "eye",
    "eyes",
    "jaw",
    "brow",
    "eyebrow",
    "lip",
    "lips",
    "nose",
    "cheek",
    "ear",
    "tongue",
    "teeth",
    "chin",
    "mouth",
    "lid",
    "eyelid",
    "face",
}


def tokens(name):
    """Lower-case word tokens of a joint name, digits dropped: 'RightHandIndex1' -> ['right', 'hand', 'index']."""
    return [t.lower() for part in re.split(r"[_.:\- ]+", name) for t in _TOKEN.findall(part) if not t.isdigit()]


def side(name):
    """'left', 'right' or None for a joint name."""
    words = tokens(name)
    if any(w in _LEFT for w in words):
        return "left"
    if any(w in _RIGHT for w in words):
        return "right"
    return None


def root_markers(names, parents):
    """Indices of the top-level joints named like a root (`joint_Root`, `b_root`): a marker on the floor or at the
    scene's origin, no part of the body. No bone is drawn from one, and the body's up axis and height are measured
    without it: Bandai-Namco's `joint_Root` stays at the origin while the body walks metres away from it."""
    return [j for j, p in enumerate(parents) if p < 0 and "root" in tokens(names[j])]


def body_skeleton(names, parents):
    """(the kept joints' indices, their names, their parents renumbered) of the skeleton without its root markers
    (`root_markers`), a marker's children made roots: what the measures of the body (its height and up axis, the
    C2ST's features) are taken on, so that a marker left at the scene's origin does not carry a walk's path into
    them."""
    markers = set(root_markers(names, parents))
    keep = [j for j in range(len(names)) if j not in markers] or list(range(len(names)))
    renumber = {j: k for k, j in enumerate(keep)}
    return keep, [names[j] for j in keep], [renumber.get(int(parents[j]), -1) for j in keep]


def is_hips(name):
    """Whether a joint is named as the body's hips or pelvis (`Hips`, `pelvis`, `b_hips`), not one side's hip."""
    words = tokens(name)
    return side(name) is None and any(w in ("hips", "hip", "pelvis") for w in words)


def body_root(names, parents):
    """Index of the joint the body hangs from: the first joint, or where that is a root marker (`root_markers`),
    its first child that is not one (Bandai-Namco's `Hips` under `joint_Root`). The camera follows this joint and
    a clip is placed by it: a marker left at the scene's origin would leave a walker metres from the look-at
    point."""
    markers = set(root_markers(names, parents))
    if 0 not in markers:
        return 0
    return next((j for j, p in enumerate(parents) if p in markers and j not in markers), 0)


def is_detail(name):
    """True for a finger or face joint (drawn thinner): a token of FINGER_WORDS or FACE_WORDS."""
    return any(w in FINGER_WORDS or w in FACE_WORDS for w in tokens(name))
