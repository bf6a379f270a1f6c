"""Seamless Interaction's participant files: SMPL-H parameters under `smplh:*` keys, one file per participant.

Meta's Seamless Interaction data set (the GENEA Challenge 2026's data) ships, per participant of an interaction,
`V<vendor>_S<session>_I<interaction>_P<participant>.npz` beside a `.wav` (48 kHz, that person's denoised voice)
and a `.json` (word-timed transcript and voice activity: generation.data.transcripts). Participant ids may end in a
letter (`P0299A`); the two participants of one interaction share the `V*_S*_I*` prefix, and nothing in the files
says which of them is the agent of a study: the cutter (generation.own_study.conversations) decides that by who
speaks, never by file order.

The motion: `smplh:global_orient` [T, 3], `smplh:body_pose` [T, 63] or [T, 21, 3], `smplh:left_hand_pose` and
`smplh:right_hand_pose` [T, 45] or [T, 15, 3] (axis-angle), `smplh:translation` [T, 3] (metres) and
`smplh:is_valid` [T], at 30 Hz. There are no `betas`: the body model's mean shape is used. Every other key
(`movement:*`, `boxes_and_keypoints:*`) is ignored and never read. A frame is valid where `is_valid` says so and
its numbers are finite; an invalid frame's parameters are replaced by the last valid frame's (held, never
interpolated) so that the kinematics can run, and the mask goes along for the builder to refuse any item that
shows one (generation.own_study.inputs).

Only the members named here are read, within the bounds their `.npy` headers set (at most MAX_FRAMES frames and
MAX_NPZ_BYTES in all), before anything is allocated.
"""

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from moglow_eval.core.clip import MAX_FRAMES, MAX_NPZ_BYTES, NPZ_READ_ERRORS, ClipError, first_line, npz_headers

from .smpl_files import SmplError

# (key, joints): the SMPL-H pose in kinematic-tree order, the root's orientation first (52 joints in all).
POSE_KEYS = (
    ("smplh:global_orient", 1),
    ("smplh:body_pose", 21),
    ("smplh:left_hand_pose", 15),
    ("smplh:right_hand_pose", 15),
)
TRANS_KEY = "smplh:translation"
VALID_KEY = "smplh:is_valid"
KEYS = (*(k for k, _ in POSE_KEYS), TRANS_KEY, VALID_KEY)
FPS = 30.0  # the data set's motion rate; its files store none
NAME = re.compile(r"(?P<interaction>V\d+_S\d+_I\d+)_(?P<participant>P[0-9]+[A-Za-z]*)")


@dataclass
class SeamlessMotion:
    poses: np.ndarray  # [T, 156] float64 axis-angle, invalid frames held from the last valid one
    trans: np.ndarray  # [T, 3] float64 metres
    valid: np.ndarray  # [T] bool
    fps: float


def parse_name(path):
    """(interaction, participant) of a Seamless Interaction file name (`V00_S0809_I00000582_P0947A.npz` ->
    (`V00_S0809_I00000582`, `P0947A`)), or None for any other name."""
    stem = Path(path).name.split(".")[0]
    m = NAME.fullmatch(stem)
    return (m["interaction"], m["participant"]) if m else None


def is_seamless_file(path):
    """Whether an .npz holds Seamless Interaction's SMPL-H parameters (an `smplh:body_pose` member)."""
    try:
        return "smplh:body_pose" in npz_headers(path, limit=None)
    except ClipError:
        return False


def _shape_of(path, headers, key, joints):
    """T of a member of shape [T, 3 joints] or [T, joints, 3] ([T] or [T, 1] for the mask); SmplError otherwise."""
    if key not in headers:
        raise SmplError(f"{path}: a Seamless Interaction file without '{key}' (it needs {', '.join(KEYS)})")
    shape, dtype = headers[key]
    if key == VALID_KEY:
        ok = len(shape) == 1 or (len(shape) == 2 and shape[1] == 1)
        want = "[T]"
    else:
        ok = (len(shape) == 2 and shape[1] == 3 * joints) or (len(shape) == 3 and shape[1:] == (joints, 3))
        want = f"[T, {3 * joints}] or [T, {joints}, 3]"
    if not ok or dtype.kind not in "fiub":
        raise SmplError(f"{path}: '{key}' must be numbers of shape {want}, got {shape} {dtype}")
    return shape[0]


def check_headers(path):
    """T, the number of frames, from the members' headers alone; SmplError naming the file and key for a missing
    member, a wrong shape, frames that disagree or exceed MAX_FRAMES, or members over MAX_NPZ_BYTES."""
    try:
        headers = npz_headers(path, limit=None)  # the unknown members may be large: only ours are counted
    except ClipError as e:
        raise SmplError(str(e)) from None
    lengths = {key: _shape_of(path, headers, key, joints) for key, joints in (*POSE_KEYS, (TRANS_KEY, 1))}
    lengths[VALID_KEY] = _shape_of(path, headers, VALID_KEY, 0)
    frames = lengths[TRANS_KEY]
    other = next((k for k, n in lengths.items() if n != frames), None)
    if other is not None:
        raise SmplError(f"{path}: '{other}' has {lengths[other]} frames, '{TRANS_KEY}' {frames}")
    if not 2 <= frames <= MAX_FRAMES:
        raise SmplError(f"{path}: {frames} frames; a motion file holds 2 to {MAX_FRAMES}")
    total = sum(int(np.prod(headers[k][0], dtype=object)) * headers[k][1].itemsize for k in KEYS)
    if total > MAX_NPZ_BYTES:
        limit = MAX_NPZ_BYTES >> 20
        raise SmplError(f"{path}: its SMPL-H arrays would take {total >> 20} MiB, over the limit of {limit} MiB")
    return frames


def load_members(path):
    """{key: array} of the SMPL-H members of a Seamless Interaction file, as stored, checked by their headers
    first (check_headers); no other member is read."""
    frames = check_headers(path)
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: np.asarray(f[k]) for k in KEYS}
    except NPZ_READ_ERRORS as e:
        raise SmplError(f"{path}: unreadable Seamless Interaction file ({first_line(e)})") from None
    return arrays, frames


def read_seamless(path, source_fps=None):
    """A Seamless Interaction participant file as SMPL-H poses [T, 156], translations and its validity mask.

    Parameters
    ----------
    path : str or Path
        The participant's `.npz`.
    source_fps : float or None
        Its frame rate; None: the data set's FPS (30).

    Returns
    -------
    SeamlessMotion
        poses [T, 156] (global orientation, body, left hand, right hand), trans [T, 3], valid [T] (the file's
        `is_valid`, and finite numbers), fps. An invalid frame holds the last valid frame's parameters.

    Raises
    ------
    SmplError
        One line naming the file: a missing `smplh:*` member, a wrong shape, frames that disagree, too large, or
        no valid frame at all.
    """
    arrays, frames = load_members(path)
    poses = np.concatenate([np.asarray(arrays[k], np.float64).reshape(frames, 3 * j) for k, j in POSE_KEYS], 1)
    trans = np.asarray(arrays[TRANS_KEY], np.float64).reshape(frames, 3)
    valid = np.asarray(arrays[VALID_KEY]).reshape(frames).astype(bool)
    valid &= np.isfinite(poses).all(1) & np.isfinite(trans).all(1)
    if not valid.any():
        raise SmplError(f"{path}: no valid frame ('{VALID_KEY}' is false, or the numbers not finite, in all {frames})")
    held = hold_last_valid(valid)
    return SeamlessMotion(poses[held], trans[held], valid, float(source_fps or FPS))


def hold_last_valid(valid):
    """For each frame, the index of the last valid frame at or before it (the first valid frame before any)."""
    index = np.where(valid, np.arange(len(valid)), -1)
    index = np.maximum.accumulate(index)
    index[index < 0] = int(np.argmax(valid))
    return index


def invalid_spans(valid):
    """[(first, last)] frame ranges, inclusive, where `valid` is false."""
    bad = np.flatnonzero(~np.asarray(valid, bool))
    if not len(bad):
        return []
    breaks = np.flatnonzero(np.diff(bad) > 1)
    starts = np.concatenate([[bad[0]], bad[breaks + 1]])
    ends = np.concatenate([bad[breaks], [bad[-1]]])
    return [(int(a), int(b)) for a, b in zip(starts, ends)]


def spans_text(spans, most=3):
    """`12-40, 95` for [(12, 40), (95, 95)]; the first `most` spans and how many more."""
    shown = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in spans[:most])
    return shown + (f" and {len(spans) - most} more" if len(spans) > most else "")


def write_cut(src, dst, start, stop):
    """Write frames [start, stop) of a Seamless Interaction file's SMPL-H members to `dst` in the same layout (the
    cutter's item files; the other members are left out)."""
    arrays, _ = load_members(src)
    np.savez(dst, **{k: a[start:stop] for k, a in arrays.items()})
