"""Synthetic SMPL-family body models and parameter files, written by the tests (the real models are licensed).

A model file has the layout smplx's loaders read (v_template, shapedirs, posedirs, J_regressor, weights,
kintree_table, f) and the real models' joint trees (SMPL 24 joints, SMPL-H 52, SMPL-X 55), on a made-up body:
one vertex at each rest joint (the regressor picks it) and a few more, so its joints stand 1.5 m tall as real
SMPL joints do (head joint to feet). A parameter file has poses, trans, betas and mocap_frame_rate, as BEAT2 and
AMASS ship them.
"""

import numpy as np

SMPL_PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
# Rest joints of the 22 body joints, metres, Y up, facing +Z, left +X (T-pose), the pelvis at the origin.
BODY_REST = [
    (0, 0, 0), (0.06, -0.09, 0), (-0.06, -0.09, 0), (0, 0.11, 0), (0.10, -0.47, 0), (-0.10, -0.47, 0),
    (0, 0.25, 0), (0.09, -0.87, -0.04), (-0.09, -0.87, -0.04), (0, 0.31, 0), (0.12, -0.93, 0.10),
    (-0.12, -0.93, 0.10), (0, 0.52, 0), (0.08, 0.45, 0), (-0.08, 0.45, 0), (0, 0.60, 0.05), (0.17, 0.45, 0),
    (-0.17, 0.45, 0), (0.43, 0.45, 0), (-0.43, 0.45, 0), (0.68, 0.45, 0), (-0.68, 0.45, 0),
]  # fmt: skip


def tree(kind):
    """(parents, rest joints [J, 3]) of a model kind: smpl, smplh or smplx."""
    parents, rest = list(SMPL_PARENTS[:22]), [np.array(p, float) for p in BODY_REST]
    if kind == "smpl":
        return np.array(SMPL_PARENTS), np.array(rest + [rest[20] + (0.08, 0, 0), rest[21] - (0.08, 0, 0)])
    if kind == "smplx":  # jaw and eyes on the head, before the hands
        parents += [15, 15, 15]
        rest += [rest[15] + (0, -0.05, 0.08), rest[15] + (0.03, 0.03, 0.08), rest[15] + (-0.03, 0.03, 0.08)]
    for wrist, s in ((20, 1), (21, -1)):
        for f in range(5):
            parent = wrist
            for k in range(3):
                parents.append(parent)
                rest.append(rest[parent] + (s * (0.05 if k == 0 else 0.025), 0, (f - 2) * 0.015 if k == 0 else 0))
                parent = len(parents) - 1
    return np.array(parents), np.array(rest)


def model_arrays(kind, n_vertices=None, n_betas=10, seed=0):
    """The arrays of a synthetic model (float32, as the published files): vertex j is rest joint j for the first J
    vertices, which J_regressor picks; the rest of the vertices sit around the body."""
    rng = np.random.default_rng(seed)
    parents, rest = tree(kind)
    n = len(parents)
    v = max(n_vertices or 0, n + 8)
    template = np.concatenate([rest, rng.uniform(-0.3, 0.3, (v - n, 3))]).astype(np.float32)
    regressor = np.zeros((n, v), np.float32)
    regressor[np.arange(n), np.arange(n)] = 1.0
    weights = np.zeros((v, n), np.float32)
    weights[np.arange(v), np.minimum(np.arange(v), n - 1)] = 1.0
    kintree = np.stack([parents, np.arange(n)]).astype(np.int64)
    kintree[0, 0] = 2**32 - 1  # as the published files mark the root
    return dict(
        v_template=template,
        shapedirs=rng.normal(0, 0.01, (v, 3, n_betas)).astype(np.float32),
        posedirs=np.zeros((v, 3, (n - 1) * 9), np.float32),
        J_regressor=regressor,
        weights=weights,
        kintree_table=kintree,
        f=np.stack([np.arange(v - 2), np.arange(1, v - 1), np.arange(2, v)], 1).astype(np.int64),
    )


def write_model(path, kind, **kw):
    np.savez(path, **model_arrays(kind, **kw))
    return path


def motion_arrays(kind, frames=60, fps=30.0, seed=0):
    """poses [T, 3J] (the root turning slowly, the arms waving), trans [T, 3] (walking forward), betas [10]."""
    rng = np.random.default_rng(seed)
    n = len(tree(kind)[0])
    t = np.arange(frames) / fps
    poses = np.zeros((frames, n, 3))
    poses[:, 0, 1] = 0.3 * t  # yaw about Y
    poses[:, 16, 2] = -1.0 + 0.3 * np.sin(2 * np.pi * t)  # left shoulder down from the T-pose, waving
    poses[:, 17, 2] = 1.0
    trans = np.stack([0.1 * np.sin(t), 0.93 + 0 * t, 0.5 * t], 1)
    return dict(
        poses=poses.reshape(frames, -1), trans=trans, betas=rng.normal(0, 1, 10), mocap_frame_rate=np.float64(fps)
    )


def write_motion(path, kind, **kw):
    np.savez(path, **motion_arrays(kind, **kw))
    return path
