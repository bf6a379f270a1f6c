"""Small BVH files of the skeleton families people bring, written by the tests (nothing copied from a data set).

Each family's file has that family's real joint names, root and hierarchy layout, and its unit (CMU's 5.64 cm,
centimetres for the others), on one body about 1.73 m tall standing in an A-pose, with a few frames of gentle
motion. `write_family(path, name)` writes one; `write_zeroeggs(path)` writes the ZeroEGGS-like take of 75 joints
with fingers, in centimetres at 30 fps (the shape of the take in which the unit detection went wrong).
"""

import numpy as np

from .own_study_data import write_bvh

CMU_UNIT = 0.0254 / 0.45  # metres per CMU unit
FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")
ROT = ["Zrotation", "Xrotation", "Yrotation"]
POS_ROT = ["Xposition", "Yposition", "Zposition", *ROT]


class Body:
    """A joint list being built: (name, parent index, offset in metres); left is +X, up +Y, forward +Z."""

    def __init__(self):
        self.names, self.parents, self.offsets = [], [], []

    def add(self, name, parent, offset):
        self.names.append(name)
        self.parents.append(-1 if parent is None else self.names.index(parent))
        self.offsets.append(np.array(offset, float))
        return name

    def chain(self, parent, names, step):
        for name in names:
            parent = self.add(name, parent, step)
        return parent


def _spine(b, root, spine, neck, head, head_end=None):
    """Spine joints up 0.50 m from the hips, the neck 0.12 m, the head 0.08 m above it (and a head-top joint)."""
    top = b.chain(root, spine, (0, 0.50 / len(spine), 0))
    neck_top = b.chain(top, neck, (0, 0.12 / len(neck), 0))
    b.add(head, neck_top, (0, 0.08, 0))
    if head_end:
        b.add(head_end, head, (0, 0.08, 0))
    return top


def _arm(b, chest, s, names, fingers=(), finger_parts=3, extra=()):
    """Collar, upper arm, forearm and hand hanging at 45 degrees; `fingers` (names per finger), `extra` end joints."""
    collar, upper, fore, hand = names
    b.add(collar, chest, (s * 0.03, 0.0, 0))
    b.add(upper, collar, (s * 0.15, -0.02, 0))
    b.add(fore, upper, (s * 0.19, -0.19, 0))
    b.add(hand, fore, (s * 0.17, -0.17, 0))
    for f, finger in enumerate(fingers):
        parent = hand
        for k in range(finger_parts):
            step = (s * 0.03, -0.03, (f - 2) * 0.01) if k == 0 else (s * 0.02, -0.02, 0)
            parent = b.add(finger[k], parent, step)
    for name, parent, offset in extra:
        b.add(name, parent, (s * offset[0], offset[1], offset[2]))


def _leg(b, hips, s, names, hip_joint=None, extra=()):
    """(Hip joint,) upper leg, lower leg, foot, toe: the hip 5 cm below the root, the toes on the floor."""
    upleg, leg, foot, toe = names
    parent = hips
    if hip_joint:
        parent = b.add(hip_joint, hips, (0, 0, 0))
    b.add(upleg, parent, (s * 0.09, -0.05, 0))
    b.add(leg, upleg, (0, -0.43, 0))
    b.add(foot, leg, (0, -0.42, 0))
    b.add(toe, foot, (0, -0.05, 0.12))
    for name, parent, offset in extra:
        b.add(name, parent, offset)


def cmu():
    b = Body()
    b.add("Hips", None, (0, 0, 0))
    for side, s, short in (("Left", 1, "L"), ("Right", -1, "R")):
        _leg(
            b, "Hips", s, [f"{side}UpLeg", f"{side}Leg", f"{side}Foot", f"{side}ToeBase"], hip_joint=f"{short}HipJoint"
        )
    b.add("LowerBack", "Hips", (0, 0, 0))
    _spine(b, "LowerBack", ["Spine", "Spine1"], ["Neck", "Neck1"], "Head")
    for side, s, short in (("Left", 1, "L"), ("Right", -1, "R")):
        hand = f"{side}Hand"
        extra = [
            (f"{side}FingerBase", hand, (0.03, -0.03, 0)),
            (f"{side}HandIndex1", f"{side}FingerBase", (0.02, -0.02, 0)),
        ]
        extra.append((f"{short}Thumb", hand, (0.02, -0.02, 0.02)))
        _arm(b, "Spine1", s, [f"{side}Shoulder", f"{side}Arm", f"{side}ForeArm", hand], extra=extra)
    return b, "cmu", 1.0 / CMU_UNIT, ["Zrotation", "Yrotation", "Xrotation"]


def _cm_family(prefix="", spine=("Spine", "Spine1", "Spine2"), neck=("Neck",), head_end=None, finger_parts=3):
    """The CMU-like names that Mixamo, ZeroEGGS, BEAT and LaFAN1 share, with their own spine, neck and fingers."""
    p = prefix
    b = Body()
    b.add(f"{p}Hips", None, (0, 0, 0))
    top = _spine(b, f"{p}Hips", [p + n for n in spine], [p + n for n in neck], f"{p}Head", head_end and p + head_end)
    for side, s in (("Left", 1), ("Right", -1)):
        fingers = [[f"{p}{side}Hand{f}{k + 1}" for k in range(finger_parts)] for f in FINGERS] if finger_parts else ()
        names = [f"{p}{side}{n}" for n in ("Shoulder", "Arm", "ForeArm", "Hand")]
        _arm(b, top, s, names, fingers, finger_parts)
    for side, s in (("Left", 1), ("Right", -1)):
        _leg(b, f"{p}Hips", s, [f"{p}{side}{n}" for n in ("UpLeg", "Leg", "Foot", "ToeBase")])
    return b


def mixamo():
    return _cm_family("mixamorig:", head_end="HeadTop_End"), "mixamo", 100.0, ROT


def lafan1():
    b = Body()
    b.add("Hips", None, (0, 0, 0))
    for side, s in (("Left", 1), ("Right", -1)):
        _leg(b, "Hips", s, [f"{side}UpLeg", f"{side}Leg", f"{side}Foot", f"{side}Toe"])
    top = _spine(b, "Hips", ["Spine", "Spine1", "Spine2"], ["Neck"], "Head")
    for side, s in (("Left", 1), ("Right", -1)):
        _arm(b, top, s, [f"{side}{n}" for n in ("Shoulder", "Arm", "ForeArm", "Hand")])
    return b, "lafan1", 100.0, ROT


def zeroeggs():
    """75 joints: Hips, Spine..Spine3, Neck, Neck1, Head, HeadEnd; per arm shoulder to hand, five fingers of four
    joints, ForeArmEnd and ArmEnd; per leg UpLeg, Leg, Foot, ToeBase, ToeBaseEnd, LegEnd, UpLegEnd."""
    b = Body()
    b.add("Hips", None, (0, 0, 0))
    top = _spine(b, "Hips", ["Spine", "Spine1", "Spine2", "Spine3"], ["Neck", "Neck1"], "Head", "HeadEnd")
    for side, s in (("Right", -1), ("Left", 1)):
        fingers = [[f"{side}Hand{f}{k + 1}" for k in range(4)] for f in FINGERS]
        extra = [
            (f"{side}ForeArmEnd", f"{side}ForeArm", (0.05, -0.05, 0)),
            (f"{side}ArmEnd", f"{side}Arm", (0.05, -0.05, 0)),
        ]
        _arm(b, top, s, [f"{side}{n}" for n in ("Shoulder", "Arm", "ForeArm", "Hand")], fingers, 4, extra)
    for side, s in (("Right", -1), ("Left", 1)):
        extra = [
            (f"{side}ToeBaseEnd", f"{side}ToeBase", (0, 0, 0.04)),
            (f"{side}LegEnd", f"{side}Leg", (0, -0.1, 0)),
            (f"{side}UpLegEnd", f"{side}UpLeg", (0, -0.1, 0)),
        ]
        _leg(b, "Hips", s, [f"{side}{n}" for n in ("UpLeg", "Leg", "Foot", "ToeBase")], extra=extra)
    assert len(b.names) == 75, len(b.names)
    return b, "zeroeggs", 100.0, POS_ROT


def genea():
    """GENEA 2022/2023 (Talking With Hands): body_world on the floor, b_root at the hips, b_ names."""
    b = Body()
    b.add("body_world", None, (0, 0, 0))
    b.add("b_root", "body_world", (0, 0.95, 0))
    top = _spine(b, "b_root", ["b_spine0", "b_spine1", "b_spine2", "b_spine3"], ["b_neck0"], "b_head")
    b.add("b_jaw", "b_head", (0, -0.04, 0.08))
    for side, s in (("l", 1), ("r", -1)):
        fingers = [[f"b_{side}_{f.lower()}{k + 1}" for k in range(3)] for f in FINGERS]
        names = [f"b_{side}_shoulder", f"b_{side}_arm", f"b_{side}_forearm", f"b_{side}_wrist"]
        _arm(b, top, s, names, fingers)
    for side, s in (("l", 1), ("r", -1)):
        _leg(b, "b_root", s, [f"b_{side}_upleg", f"b_{side}_leg", f"b_{side}_foot", f"b_{side}_foot_end"])
    return b, "genea", 100.0, ROT


def bandai():
    """Bandai-Namco: joint_Root on the floor, Hips above it, suffixes _L and _R."""
    b = Body()
    b.add("joint_Root", None, (0, 0, 0))
    b.add("Hips", "joint_Root", (0, 0.95, 0))
    top = _spine(b, "Hips", ["Spine", "Chest"], ["Neck"], "Head")
    for side, s in (("L", 1), ("R", -1)):
        _arm(b, top, s, [f"Shoulder_{side}", f"UpperArm_{side}", f"LowerArm_{side}", f"Hand_{side}"])
    for side, s in (("L", 1), ("R", -1)):
        _leg(b, "Hips", s, [f"UpperLeg_{side}", f"LowerLeg_{side}", f"Foot_{side}", f"Toes_{side}"])
    return b, "bandai", 100.0, POS_ROT


FAMILIES = {"cmu": cmu, "mixamo": mixamo, "zeroeggs": zeroeggs, "genea": genea, "lafan1": lafan1, "bandai": bandai}


def write_family(path, family, frames=40, fps=30.0, seed=0, units_per_metre=None, turns=None, degrees=4.0):
    """Write a BVH of `family` (a key of FAMILIES) in its own unit, or in `units_per_metre`; returns (path, joint
    names, units per metre). The root stands with its hips 0.95 m up (or, for a floor root, its child does) and
    sways; every joint turns a little, each at its own phase. `turns`: {joint name: {rotation channel: degrees}}
    added to the pose throughout (SPEAKER: a speaker's arms, upper arms down and forearms forward); `degrees`: the
    amplitude of every joint's turning."""
    body, _, per_metre, channels = FAMILIES[family]()
    per_metre = units_per_metre or per_metre
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    floor_root = body.names[0] in ("body_world", "joint_Root")
    cols = []
    for j in range(len(body.names)):
        chans = POS_ROT if j == 0 else channels
        for c in chans:
            if c.endswith("position"):
                base = body.offsets[j]["XYZ".index(c[0])] * per_metre
                if j == 0 and c == "Yposition" and not floor_root:
                    base = 0.95 * per_metre
                cols.append(base + 0.02 * per_metre * np.sin(2 * np.pi * 0.5 * t + rng.uniform(0, 6)))
            else:
                turn = (turns or {}).get(body.names[j], {}).get(c, 0.0)
                cols.append(turn + degrees * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6)))
    motion = np.stack(cols, axis=1)
    offsets = [o * per_metre for o in body.offsets]
    all_channels = [POS_ROT if j == 0 else channels for j in range(len(body.names))]
    write_bvh(path, body.names, body.parents, offsets, all_channels, motion, 1.0 / fps)
    return path, list(body.names), per_metre


# A speaker's pose for write_family's `turns`: the upper arms turned down from the A-pose, the forearms forward.
SPEAKER = {
    "LeftArm": {"Zrotation": -35.0},
    "RightArm": {"Zrotation": 35.0},
    "LeftForeArm": {"Xrotation": -60.0},
    "RightForeArm": {"Xrotation": -60.0},
}


def write_zeroeggs(path, frames=90, fps=30.0, seed=0, turns=None, degrees=4.0):
    """The ZeroEGGS-like take: 75 joints with fingers, centimetres, 30 fps; returns its path."""
    return write_family(path, "zeroeggs", frames, fps, seed, turns=turns, degrees=degrees)[0]


def write_family_study(root, family="zeroeggs", n_items=3, frames=45, fps=30.0, top="", tables=""):
    """A study from folders at `root` of one family's BVH: real/ (the reference) and sys_a/ (the same skeleton,
    other motion), `n_items` items, no sound; `top` (top-level keys) and `tables` are added to the study file.
    Returns the study file's path."""
    from pathlib import Path

    root = Path(root)
    for k in range(n_items):
        for sub, seed in (("real", k), ("sys_a", 100 + k)):
            (root / sub).mkdir(parents=True, exist_ok=True)
            write_family(root / sub / f"item{k:02d}.bvh", family, frames, fps, seed)
    study = root / "study.toml"
    study.write_text(
        'reference = "real"\nseed = 1\nn_training = 1\n' + top + "\n"
        '[conditions]\nreal = "real"\nSYS_A = "sys_a"\n\n[catch]\nmake = ["jitter", "freeze"]\nn = 1\n' + tables
    )
    return study
