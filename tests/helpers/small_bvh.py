"""A small BVH file written by the tests: five joints of mixed channel counts and rotation orders, its hierarchy
written out apart from the reader, and random motion for it (the BVH reader's tests and the features' unknown
skeleton)."""

import numpy as np

# Mixed channel counts and rotation orders, interleaved position/rotation channels, a proper-Euler
# order (X Z X), End Sites, tabs; written with CRLF line ends below.
HIERARCHY = """HIERARCHY
ROOT Hips
{
\tOFFSET 1 2 3
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Spine
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\tJOINT Head
\t\t{
\t\t\tOFFSET 0 5 1
\t\t\tCHANNELS 3 Yrotation Zrotation Xrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0 3 0
\t\t\t}
\t\t}
\t\tJOINT Arm
\t\t{
\t\t\tOFFSET 4 8 0
\t\t\tCHANNELS 6 Zrotation Yposition Xrotation Xposition Zposition Yrotation
\t\t\tJOINT Hand
\t\t\t{
\t\t\t\tOFFSET 6 0 0
\t\t\t\tCHANNELS 3 Xrotation Zrotation Xrotation
\t\t\t\tEnd Site
\t\t\t\t{
\t\t\t\t\tOFFSET 2 0 0
\t\t\t\t}
\t\t\t}
\t\t}
\t}
\tJOINT Leg
\t{
\t\tOFFSET -2 -9 0.5
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -8 0
\t\t}
\t}
}
"""
# (name, parent, offset, channels) of the hierarchy above, written out independently of the reader.
JOINTS = [
    ("Hips", -1, [1, 2, 3], "Xposition Yposition Zposition Zrotation Xrotation Yrotation"),
    ("Spine", 0, [0, 10, 0], "Xrotation Yrotation Zrotation"),
    ("Head", 1, [0, 5, 1], "Yrotation Zrotation Xrotation"),
    ("Arm", 1, [4, 8, 0], "Zrotation Yposition Xrotation Xposition Zposition Yrotation"),
    ("Hand", 3, [6, 0, 0], "Xrotation Zrotation Xrotation"),
    ("Leg", 0, [-2, -9, 0.5], "Zrotation Yrotation Xrotation"),
]
END_SITES = [(2, [0, 3, 0]), (4, [2, 0, 0]), (5, [0, -8, 0])]
N_CHANNELS = sum(len(j[3].split()) for j in JOINTS)
N_FRAMES = 7


def motion_values(seed=0):
    rng = np.random.default_rng(seed)
    m = rng.uniform(-180, 180, size=(N_FRAMES, N_CHANNELS))
    return np.round(m, 4)


def bvh_text(motion, frames=None, crlf=True):
    lines = HIERARCHY.split("\n")[:-1] + [
        "MOTION",
        f"Frames: {len(motion) if frames is None else frames}",
        "Frame Time: 0.04",
    ]
    lines += ["\t".join(f"{v:.4f}" for v in row) + " " for row in motion]
    return ("\r\n" if crlf else "\n").join(lines) + ("\r\n" if crlf else "\n")
