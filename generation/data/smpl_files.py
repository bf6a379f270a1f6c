"""SMPL-family parameter files as joint positions, through the smplx library and the user's own body model.

BEAT2, the GENEA leaderboard and Seamless Interaction ship motion as `.npz` files of body-model parameters:
`poses` [T, 3J] (axis-angle per joint, the root first), `trans` [T, 3] (metres), `betas` (the body shape) and a
frame rate (`mocap_frame_rate` or `mocap_framerate`). Joint positions need the body model (SMPL, SMPL-H or SMPL-X),
whose files are licensed and not shipped: the study file names the user's (`[skeleton] smpl_model`).

The joints are what smplx's forward pass gives as its first J joints, computed with smplx's own kinematics
(`smplx.lbs`: the rest joints regressed from the shaped template, then the rigid transform of the kinematic
tree); the mesh, which the joints do not depend on, is skinned elsewhere (generation.data.skinning, the mesh
style), from the same poses. The model's arrays are read without pickles: the seven of smplx's layout
(`MODEL_KEYS`) are loaded and checked, so a file smplx's loaders would refuse is refused here, though the joints
use four of them (v_template, shapedirs, J_regressor, kintree_table); the skinning uses the other three; and the
hand means (`hands_meanl`, `hands_meanr`) where they are added. The hands' rest pose follows each layout's own
loader (`apply_hand_mean`, `HAND_MEAN_LAYOUTS`): BEAT2's loaders add the model's mean hand pose to the stored
rotations, AMASS and Seamless Interaction store full rotations; `[skeleton] hand_mean` overrides it, for the joints
and the mesh alike. SMPL-X expression coefficients shape the head's rest joints. torch and smplx are imported only
when such a file is read.
"""

from pathlib import Path

import numpy as np

from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import (
    MAX_FRAMES,
    NPZ_READ_ERRORS,
    ClipError,
    check_skeleton,
    first_line,
    npz_headers,
)

MOTION_KEYS = ("poses", "trans", "betas")
FPS_KEYS = ("mocap_frame_rate", "mocap_framerate")
EXPRESSION_KEYS = ("expressions", "expression")  # SMPL-X's expression coefficients per frame (BEAT2: expressions)
HAND_MEAN_KEYS = ("hands_meanl", "hands_meanr")  # a SMPL-H or SMPL-X model's mean hand pose (MANO's), 45 values each
# The hands' rest pose, per layout (docs/own-study.md#smpl-family-files): BEAT2's files name their rate
# mocap_frame_rate, and its loaders call smplx with flat_hand_mean=False (smplx's default), which adds the model's mean
# hand pose to the stored rotations; AMASS's (mocap_framerate) store full rotations, as does anything else read here.
HAND_MEAN_LAYOUTS = {"mocap_frame_rate": True, "mocap_framerate": False}
HAND_FIRST = {"smplh": 22, "smplx": 25}  # the first hand joint in the poses (SMPL-X's jaw and eyes come before)
MODEL_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")
BATCH = 2048  # frames per pass through the kinematics: bounds the rotation matrices held at once

_BODY = [
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
]  # fmt: skip
_FINGERS = [f"{finger}{k}" for finger in ("index", "middle", "pinky", "ring", "thumb") for k in (1, 2, 3)]
_HANDS = [f"{side}_{f}" for side in ("left", "right") for f in _FINGERS]
# The models' joints in kinematic-tree order (the order of `poses`); SMPL-X puts the jaw and eyes before the hands.
JOINT_NAMES = {
    "smpl": [*_BODY, "left_hand", "right_hand"],
    "smplh": [*_BODY, *_HANDS],
    "smplx": [*_BODY, "jaw", "left_eye", "right_eye", *_HANDS],
}
TYPES = tuple(JOINT_NAMES)
WHERE_TO_GET = (
    "body models are licensed and not shipped: get one from https://smpl-x.is.tue.mpg.de (SMPL-X, SMPL-H) "
    'or https://smpl.is.tue.mpg.de (SMPL), as .npz, and set [skeleton] smpl_model = "PATH" in the study file'
)


class SmplError(UserError):
    """An SMPL-family file or body model that cannot be used; the message names the file."""


def is_smpl_file(path):
    """Whether an .npz holds SMPL-family parameters (poses and trans) rather than a clip (joints)."""
    try:
        names = set(npz_headers(path, limit=None))
    except ClipError:
        return False
    return {"poses", "trans"} <= names and "joints" not in names


def smpl_positions(path, model, smpl_type=None, source_fps=None, hand_mean="auto"):
    """(joints [T, J, 3] float64 in metres, in the model's axes; names; parents; frame rate) of an SMPL-family
    parameter file, through the body model file `model` (.npz). `hand_mean`: add the model's mean hand pose to the
    stored hand rotations (True), not (False), or as the file's layout does ("auto": HAND_MEAN_LAYOUTS). SMPL-X
    expression coefficients, where the file has them, shape the head's rest joints as in smplx's forward pass.
    SmplError naming the file otherwise."""
    if model is None:
        raise SmplError(f"{path}: an SMPL-family parameter file (poses, trans, betas); {WHERE_TO_GET}")
    poses, trans, betas, fps = read_parameters(path, source_fps)
    poses = apply_hand_mean(poses, model, smpl_type, path, hand_mean)
    expression = read_expression(path, len(poses))
    joints, names, parents = pose_joints(poses, trans, betas, model, smpl_type, path, expression)
    return joints, names, parents, fps


def apply_hand_mean(poses, model, smpl_type, path, hand_mean):
    """The one hand rule, for the joints and the mesh alike (so that they agree), for any file read through a body
    model: `poses` of the file at `path` with the model's mean hand pose added where `hand_mean` is True, or, for
    "auto", where the file's layout adds it (HAND_MEAN_LAYOUTS: BEAT2's; AMASS's and Seamless Interaction's,
    which name no such rate, store full rotations)."""
    return with_hand_mean(poses, model, smpl_type, hand_mean_of(path, hand_mean), path)


def hand_mean_of(path, hand_mean):
    """Whether the hand mean is added for the file at `path`: `hand_mean` if a bool, else its layout's."""
    if isinstance(hand_mean, bool):
        return hand_mean
    headers = npz_headers(path, limit=None)  # the names alone: the readers bound what they load
    return next((HAND_MEAN_LAYOUTS[k] for k in FPS_KEYS if k in headers), False)


def with_hand_mean(poses, model, smpl_type, add, where):
    """`poses` with the model's mean hand pose added to both hands' rotations where `add` (and the model has hands);
    SmplError naming the model when it was asked for and the model has no hand mean."""
    if not add:
        return poses
    kind = smpl_type or next((k for k, n in JOINT_NAMES.items() if 3 * len(n) == poses.shape[1]), None)
    if kind not in HAND_FIRST:
        return poses  # SMPL: no finger joints
    headers = npz_headers(model)
    if any(k not in headers for k in HAND_MEAN_KEYS):
        raise SmplError(f"{model}: no hands_meanl / hands_meanr, which hand_mean for {where} needs (set it false)")
    d = load_arrays(model, HAND_MEAN_KEYS, "a body model")
    mean = np.concatenate([np.asarray(d[k], np.float64).reshape(-1) for k in HAND_MEAN_KEYS])
    if mean.shape != (90,):
        raise SmplError(f"{model}: hands_meanl and hands_meanr must hold 45 values each, got {mean.shape[0]} in all")
    out = poses.copy()
    first = 3 * HAND_FIRST[kind]
    out[:, first : first + 90] += mean
    return out


def read_expression(path, frames):
    """SMPL-X expression coefficients [T, E] of an SMPL-family file, or None where it has none."""
    headers = npz_headers(path)
    key = next((k for k in EXPRESSION_KEYS if k in headers), None)
    if key is None:
        return None
    e = np.asarray(load_arrays(path, (key,), "an SMPL-family file")[key], np.float64)
    if e.ndim != 2 or len(e) != frames or not np.isfinite(e).all():
        raise SmplError(f"{path}: '{key}' must be finite [{frames}, E], one row per frame, got {e.shape}")
    return e


def shape_and_expression(kind, shapedirs, betas, expression):
    """(shape directions [V, 3, K], coefficients [T or 1, K]): the body shape's, then SMPL-X's expression's, as
    smplx's forward pass puts them together; the model's mean shape where `betas` is empty."""
    n_shape = min(len(betas), shape_components(kind, shapedirs.shape[2]))
    dirs, coef = shapedirs[:, :, :n_shape], np.asarray(betas[:n_shape], np.float64)[None]
    if expression is None or kind != "smplx":
        return dirs, coef
    first = shape_components(kind, shapedirs.shape[2])
    n_expr = min(expression.shape[1], shapedirs.shape[2] - first)
    if n_expr <= 0:
        return dirs, coef
    dirs = np.concatenate([dirs, shapedirs[:, :, first : first + n_expr]], 2)
    coef = np.concatenate([np.repeat(coef, len(expression), 0), expression[:, :n_expr]], 1)
    return dirs, coef


def pose_joints(poses, trans, betas, model, smpl_type, where, expression=None):
    """(joints [T, J, 3] float64, names, parents) of axis-angle poses [T, 3J] (the root first), translations
    [T, 3] and shape `betas` [B] (empty: the model's mean shape) through the body model file `model`, with smplx's
    kinematics. Every frame is posed from its own rotations: nothing is interpolated between frames here, so a
    rotation's axis-angle flipping near pi between two frames moves no joint. SmplError naming `where`."""
    template, shapedirs, regressor, parents, kind = read_model(model, smpl_type)
    n = len(parents)
    if poses.shape[1] != 3 * n:
        raise SmplError(
            f"{where}: 'poses' has {poses.shape[1]} values a frame, but the {kind} model {model} has {n} joints "
            f"({3 * n} values); give the model the file was made with"
        )
    try:
        import torch
        from smplx.lbs import batch_rigid_transform, batch_rodrigues, blend_shapes, vertices2joints
    except ImportError:
        raise SmplError(f"{where}: reading SMPL-family files needs smplx: pip install 'moglow-eval[smpl]'") from None
    dirs, coef = shape_and_expression(kind, shapedirs, betas, expression)
    with torch.no_grad():
        template, dirs, regressor = (torch.from_numpy(x) for x in (template, dirs, regressor))
        tree = torch.from_numpy(parents)
        out = np.empty((len(poses), n, 3))

        def rest_joints(c):  # the rest joints of the shape (and, for SMPL-X with expressions, of each frame's face)
            shaped = template[None] + (blend_shapes(torch.from_numpy(c), dirs) if dirs.shape[2] else 0)
            return vertices2joints(regressor, shaped)

        rest_all = rest_joints(coef) if len(coef) == 1 else None
        for a in range(0, len(poses), BATCH):
            pose = torch.from_numpy(np.ascontiguousarray(poses[a : a + BATCH], np.float64))
            rest = rest_all if rest_all is not None else rest_joints(coef[a : a + BATCH])
            rest = rest.expand(len(pose), -1, -1)
            rot = batch_rodrigues(pose.reshape(-1, 3)).reshape(len(pose), n, 3, 3)
            posed, _ = batch_rigid_transform(rot, rest, tree, dtype=torch.float64)
            out[a : a + BATCH] = posed.numpy()
    return out + trans[:, None], list(JOINT_NAMES[kind]), parents.astype(np.int64)


def shape_components(kind, k):
    """How many of a model's shapedirs are body shape, as smplx reads them: all for SMPL and SMPL-H; for SMPL-X
    300 of 400 (the rest are expressions), or 10 of a smaller set (10 shape, then 10 expression)."""
    if kind != "smplx":
        return k
    return 300 if k >= 400 else min(k, 10)


def load_arrays(path, keys, what):
    """{key: array} of the named members of an .npz, each checked to exist, read without pickles."""
    headers = npz_headers(path)  # refuses an archive whose headers ask for more than the limit, before reading
    missing = [k for k in keys if k not in headers]
    if missing:
        raise SmplError(f"{path}: {what} without '{missing[0]}'")
    try:
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in keys}
    except NPZ_READ_ERRORS as e:
        raise SmplError(f"{path}: unreadable {what} ({first_line(e)})") from None


def read_parameters(path, source_fps):
    headers = npz_headers(path)
    shape = headers.get("poses", ((),))[0]
    if len(shape) != 2 or shape[0] < 2 or shape[0] > MAX_FRAMES:
        raise SmplError(f"{path}: 'poses' must be [T, 3 x joints] with 2 to {MAX_FRAMES} frames, got {shape}")
    fps_key = next((k for k in FPS_KEYS if k in headers), None)
    d = load_arrays(path, (*MOTION_KEYS, *([fps_key] if fps_key else [])), "an SMPL-family file")
    poses, trans, betas = (np.asarray(d[k], np.float64) for k in MOTION_KEYS)
    if trans.shape != (len(poses), 3):
        raise SmplError(f"{path}: 'trans' must be [{len(poses)}, 3], one per frame of 'poses', got {trans.shape}")
    if betas.ndim == 2:  # some tools store one row of betas per frame, all alike
        betas = betas[0]
    if not (np.isfinite(poses).all() and np.isfinite(trans).all() and np.isfinite(betas).all()):
        raise SmplError(f"{path}: poses, trans or betas contain NaN or infinite values")
    if fps_key:
        fps = float(np.asarray(d[fps_key]).reshape(-1)[0])
    elif source_fps is not None:
        fps = float(source_fps)
    else:
        raise SmplError(f"{path}: no frame rate ({' or '.join(FPS_KEYS)}): set [skeleton] fps in the study file")
    return poses, trans, betas.reshape(-1), fps


def read_model(model, smpl_type):
    """(v_template [V, 3], shapedirs [V, 3, K], J_regressor [J, V], parents [J], model type) of a body model."""
    model = Path(model)
    if model.suffix != ".npz":
        raise SmplError(f"{model}: give the body model as .npz (the SMPL-X downloads include .npz files)")
    d = load_arrays(model, MODEL_KEYS, "a body model")
    template, shapedirs, regressor = (np.asarray(d[k], np.float64) for k in ("v_template", "shapedirs", "J_regressor"))
    kintree = np.asarray(d["kintree_table"])
    if kintree.ndim != 2 or kintree.shape[0] != 2 or kintree.dtype.kind not in "iu":
        raise SmplError(f"{model}: 'kintree_table' must be integers [2, J], got {kintree.shape} {kintree.dtype}")
    parents = kintree[0].astype(np.int64)
    parents[0] = -1  # the root's entry is any value (2**32 - 1 in the published files), as smplx reads it
    n, v = len(parents), len(template)
    if shapedirs.ndim == 2:
        shapedirs = shapedirs[:, :, None]
    if template.shape != (v, 3) or shapedirs.shape[:2] != (v, 3) or regressor.shape != (n, v):
        raise SmplError(
            f"{model}: the arrays do not fit one model: v_template {template.shape}, shapedirs {shapedirs.shape}, "
            f"J_regressor {regressor.shape}, kintree_table [2, {n}]"
        )
    if smpl_type and len(JOINT_NAMES[smpl_type]) != n:
        raise SmplError(
            f"{model}: {n} joints in 'kintree_table', but an {smpl_type} model has {len(JOINT_NAMES[smpl_type])}: "
            "check [skeleton] smpl_type"
        )
    kind = smpl_type or next((k for k, names in JOINT_NAMES.items() if len(names) == n), None)
    if kind is None:
        known = ", ".join(f"{k} {len(names)}" for k, names in JOINT_NAMES.items())
        raise SmplError(f"{model}: {n} joints in 'kintree_table', which is no SMPL-family model ({known})")
    try:
        check_skeleton(parents, n, model, JOINT_NAMES[kind])
    except ClipError as e:
        raise SmplError(str(e)) from None
    if np.any(parents[1:] >= np.arange(1, n)):
        raise SmplError(f"{model}: 'kintree_table' must list every joint after its parent, as smplx needs")
    return template, shapedirs, regressor, parents, kind
