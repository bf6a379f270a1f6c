"""The 21-joint body skeleton every part of the project speaks (MoGlow §5.1: 21 joints x xyz = 63 values).

The joint order, names and parents here are the contract between features, models, rendering and
metrics. Names follow the Bandai-Namco skeleton (its 21 body joints, without `joint_Root`).
"""

import numpy as np

JOINT_NAMES = [
    "Hips",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "Shoulder_L",
    "UpperArm_L",
    "LowerArm_L",
    "Hand_L",
    "Shoulder_R",
    "UpperArm_R",
    "LowerArm_R",
    "Hand_R",
    "UpperLeg_L",
    "LowerLeg_L",
    "Foot_L",
    "Toes_L",
    "UpperLeg_R",
    "LowerLeg_R",
    "Foot_R",
    "Toes_R",
]
PARENTS = np.array(
    [
        -1,
        0,
        1,
        2,
        3,
        2,
        5,
        6,
        7,
        2,
        9,
        10,
        11,
        0,
        13,
        14,
        15,
        0,
        17,
        18,
        19,
    ],
    dtype=np.int64,
)
N_JOINTS = len(JOINT_NAMES)
POSE_DIM = 3 * N_JOINTS  # 63
CONTROL_DIM = 3  # forward (m), sideways (m), yaw (rad) per frame

INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}
# Left/right partner of every joint, for mirroring (a joint without a side maps to itself).
MIRROR = np.array(
    [
        INDEX[n[:-2] + ("_R" if n.endswith("_L") else "_L")] if n[-2:] in ("_L", "_R") else i
        for i, n in enumerate(JOINT_NAMES)
    ],
    dtype=np.int64,
)
FEET = [INDEX["Foot_L"], INDEX["Toes_L"], INDEX["Foot_R"], INDEX["Toes_R"]]
