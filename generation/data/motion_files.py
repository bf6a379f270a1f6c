"""Any motion file as a clip of any skeleton: BVH of any hierarchy, joint-position arrays, or the project's clips.

A study of your own motion (generation.own_study.builder) reads every condition's files through `read_motion`, which
returns a `Motion`: world joint positions [T, J, 3] in metres with Y up, the skeleton (names, parents) and the
frame rate, resampled to the study's rate. Four formats:

- `ITEM.bvh` / `ITEM.bvh.gz`: every joint of the hierarchy by forward kinematics (rotations slerped when
  resampled, so bones stay rigid), plus each End Site that sits away from its joint (a head top, a finger tip),
  named `PARENT_end`. Fingers and face joints come along.
- `ITEM.npy`: joint positions [T, J, 3], as GENEA 2022 and HumanML3D exchange them, with the skeleton given once
  in a small JSON (`Skeleton.load`: names, and parents by index or by name); positions are resampled linearly.
- `ITEM.npz`: a clip file (CONTRACTS §1), or an SMPL-family parameter file (poses, trans, betas), whose joints
  come from the user's body model through smplx (generation.data.smpl_files), resampled linearly; or a Seamless
  Interaction participant file (`smplh:*` keys, generation.data.seamless_files), the same way, with its mask of
  valid frames (`Motion.valid`).

The up axis is read from the study file or detected (`detect_up`). Units are the study file's, or with "auto"
the first that makes the standing body a person's height, the skeleton family's own unit tried first
(generation.data.skeleton_families); both measure the body without its root markers (`body_joints`: a
Bandai-Namco `joint_Root` left at the scene's origin is none of the body). Every file is read within bounds set
by its header (frames, channels, array shapes) before anything is allocated. Every problem is a MotionError
naming the file.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from moglow_eval.core import skeleton_names, user_files
from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import (
    MAX_FRAMES,
    MAX_JOINTS,
    MAX_NPZ_BYTES,
    ClipError,
    check_fps,
    check_skeleton,
    first_line,
    load_clip,
    npz_headers,
)

from ..motion.bvh import BvhError, forward_kinematics, header_fps, header_timing, read_bvh
from ..motion.resample import clean_fps, lerp_indices, local_quaternions_at, quat_to_matrix, resample_times
from . import seamless_files
from .skeleton_families import UnitError, choose_unit
from .smpl_files import FPS_KEYS, WHERE_TO_GET, SmplError, apply_hand_mean, is_smpl_file, pose_joints, smpl_positions
from .systems import resample_positions

EXTENSIONS = (".bvh.gz", ".bvh", ".npy", ".npz")
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}  # metres per unit
UPS = ("y", "z")
SKELETON_BYTES = 4 << 20  # a skeleton file names a few hundred joints at most (MAX_JOINTS)
BODY_HEIGHT_M = (0.5, 3.0)  # what a body's extent along the up axis may be, in metres (a child sitting .. a giant)
END_SITE_MIN = 1e-6  # End Sites closer than this to their joint (in file units) are not joints of their own


class MotionError(UserError):
    """An unreadable or implausible motion file; the message names the file."""


@dataclass
class Motion:
    joints: np.ndarray  # [T, J, 3] float32, metres, Y up
    names: list  # [J]
    parents: np.ndarray  # [J] int64, -1 for roots
    fps: float
    path: str = ""
    valid: np.ndarray | None = None  # [T] bool where the file marks frames invalid (Seamless Interaction); else None

    @property
    def seconds(self):
        return len(self.joints) / self.fps


@dataclass
class Skeleton:
    """Joint names and parents for joint-position arrays (.npy), read once from the study's skeleton JSON."""

    names: list
    parents: np.ndarray

    @classmethod
    def load(cls, path):
        """{"names": [...], "parents": [...]} with parents as indices (-1 for the root) or names (null for the
        root); MotionError naming the file and key otherwise."""
        path = Path(path)
        spec = user_files.read_json(path, SKELETON_BYTES, MotionError, "skeleton file")
        if not isinstance(spec, dict) or not isinstance(spec.get("names"), list) or "parents" not in spec:
            raise MotionError(f'{path}: expected {{"names": [...], "parents": [...]}}')
        names = spec["names"]
        if not names or not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
            raise MotionError(f"{path}: 'names' must be distinct, non-empty strings")
        if len(names) > MAX_JOINTS:
            raise MotionError(f"{path}: {len(names)} joints is more than the limit of {MAX_JOINTS}")
        raw = spec["parents"]
        if not isinstance(raw, list) or len(raw) != len(names):
            raise MotionError(f"{path}: 'parents' must be a list of {len(names)} entries, one per name")
        index = {n: i for i, n in enumerate(names)}
        parents = []
        for name, p in zip(names, raw):
            if p is None or (isinstance(p, int) and not isinstance(p, bool)):
                parents.append(-1 if p is None else p)
            elif isinstance(p, str) and p in index:
                parents.append(index[p])
            else:
                raise MotionError(f"{path}: parent of {name!r} is {p!r}, not a joint name, an index or null")
        try:
            parents = check_skeleton(np.array(parents, dtype=np.int64), len(names), path, names)
        except ClipError as e:
            raise MotionError(str(e)) from None
        return cls(list(names), parents)


def motion_stem(path):
    """The item a file stands for (its name without a motion extension), or None for other files."""
    name = Path(path).name
    for ext in EXTENSIONS:
        if name.endswith(ext) and len(name) > len(ext):
            return name[: -len(ext)]
    return None


# ---------------------------------------------------------------- units and axes
def body_joints(joints, names, parents):
    """joints [T, J, 3] without the root markers (core.skeleton_names.root_markers), which the measures of the body
    below must not count: a marker left at the origin of a walk's scene would make the body metres deep and tall."""
    return joints[:, skeleton_names.body_skeleton(names, parents)[0]]


def median_extent(joints):
    """[3]: the body's extent along x, y and z in its median frame (joints [T, J, 3])."""
    return np.median(joints.max(axis=1) - joints.min(axis=1), axis=0)


def detect_up(joints):
    """'y' or 'z': the axis along which the body is tallest, in the median frame (a standing, walking or
    dancing body is taller than it is deep; arms spread wide tie at worst with a T-pose, decided by y)."""
    extent = median_extent(joints)
    return "z" if extent[2] > 1.2 * extent[1] else "y"


def to_y_up(joints, up):
    """Z-up (x right, y forward, z up; right-handed) -> Y-up (x, z, -y): a rotation, so nothing is mirrored."""
    if up == "y":
        return joints
    return np.stack([joints[..., 0], joints[..., 2], -joints[..., 1]], axis=-1)


def body_height(joints):
    """The body's height along Y in file units: the median over frames of its top minus its bottom."""
    return float(np.median(joints[..., 1].max(axis=1) - joints[..., 1].min(axis=1)))


def check_height(joints_m, where):
    """MotionError when a clip, in metres, is not the height of a body (absurd units)."""
    h = body_height(joints_m)
    lo, hi = BODY_HEIGHT_M
    if not lo <= h <= hi:
        raise MotionError(
            f"{where}: the body is {h:.3g} m tall after unit conversion (expected {lo:g}-{hi:g} m); "
            "check [skeleton] units"
        )


# ---------------------------------------------------------------- readers
def _bvh_positions(path, fps):
    """All joints (and End Sites away from their joint) of a BVH file [T, J, 3] in file units at `fps`."""
    bvh = read_bvh(path)
    if bvh.n_frames < 2:
        raise MotionError(f"{path}: {bvh.n_frames} frame(s); a clip needs at least 2")
    if len(bvh.names) + len(bvh.end_sites) > MAX_JOINTS:  # what a clip may hold, checked before the kinematics
        raise MotionError(
            f"{path}: {len(bvh.names)} joints and {len(bvh.end_sites)} End Sites, more than a clip's limit of "
            f"{MAX_JOINTS} joints"
        )
    names, parents, fps_in = list(bvh.names), list(bvh.parents), clean_fps(bvh.fps)
    ends = [(p, off) for p, off in bvh.end_sites if np.linalg.norm(off) > END_SITE_MIN]
    q, trans = local_quaternions_at(bvh, fps_in, fps)
    del bvh  # its channels' values, a copy of the take the steps below no longer need
    pos, rot = forward_kinematics(np.array(parents), quat_to_matrix(q), trans)
    if ends:
        tips = np.stack([pos[:, p] + np.einsum("tab,b->ta", rot[:, p], off) for p, off in ends], axis=1)
        pos = np.concatenate([pos, tips], axis=1)
        names += [f"{names[p]}_end" for p, _ in ends]
        parents += [p for p, _ in ends]
    return pos, names, np.array(parents, dtype=np.int64)


def _npy_positions(path, skeleton, source_fps, fps):
    if skeleton is None:
        raise MotionError(f"{path}: a .npy file needs its skeleton: set [skeleton] file in the study file")
    try:
        arr = np.load(path, allow_pickle=False, mmap_mode="r")  # mapped: nothing is read before the checks below
    except (OSError, ValueError) as e:
        raise MotionError(f"{path}: not a readable .npy array ({first_line(e)})") from None
    if not isinstance(arr, np.ndarray) or arr.ndim != 3 or arr.shape[2] != 3:
        raise MotionError(f"{path}: expected joint positions [T, J, 3], got shape {getattr(arr, 'shape', '?')}")
    if arr.shape[1] != len(skeleton.names):
        raise MotionError(f"{path}: {arr.shape[1]} joints, but the skeleton file names {len(skeleton.names)}")
    if arr.dtype.kind not in "fiu":
        raise MotionError(f"{path}: positions must be numbers, got {arr.dtype}")
    if len(arr) < 2:
        raise MotionError(f"{path}: {len(arr)} frame(s); a clip needs at least 2")
    if len(arr) > MAX_FRAMES or arr.size * 8 > MAX_NPZ_BYTES:
        raise MotionError(
            f"{path}: {len(arr)} frames of {arr.shape[1]} joints is more than the limit "
            f"({MAX_FRAMES} frames, {MAX_NPZ_BYTES >> 20} MiB of positions)"
        )
    len(resample_times(len(arr), source_fps, fps))  # bounded before any allocation (MAX_FRAMES)
    joints = np.asarray(arr, dtype=np.float64)
    if not np.isfinite(joints).all():
        raise MotionError(f"{path}: positions contain NaN or infinite values")
    return resample_positions(joints, source_fps, fps), list(skeleton.names), skeleton.parents.copy()


def _npz_positions(path, fps):
    try:
        clip = load_clip(path)
    except ClipError as e:
        raise MotionError(str(e)) from None
    if len(clip["joints"]) < 2:
        raise MotionError(f"{path}: {len(clip['joints'])} frame(s); a clip needs at least 2")
    joints = resample_positions(np.asarray(clip["joints"], np.float64), float(clip["fps"]), fps)
    return joints, list(clip["joint_names"]), np.asarray(clip["parents"], np.int64)


def _smpl_positions(path, fps, smpl_model, smpl_type, hand_mean, source_fps):
    """An SMPL-family parameter file's joints (generation.data.smpl_files), resampled linearly to `fps`."""
    joints, names, parents, native = smpl_positions(path, smpl_model, smpl_type, source_fps, hand_mean)
    try:
        native = check_fps(native, path)
    except ClipError as e:
        raise MotionError(str(e)) from None
    len(resample_times(len(joints), native, fps))  # bounded before the resampled copy (MAX_FRAMES)
    return resample_positions(joints, native, fps), names, parents


def _seamless_positions(path, fps, smpl_model, smpl_type, hand_mean, source_fps, up):
    """A Seamless Interaction file's joints through the body model at the mean shape, turned upright, resampled
    linearly to `fps` (positions, so an axis-angle flip near pi between frames moves nothing), and its validity
    mask at `fps`: an output frame is valid where both frames it lies between are."""
    if smpl_model is None:
        raise MotionError(f"{path}: a Seamless Interaction file (smplh:* keys); {WHERE_TO_GET}")
    m = seamless_files.read_seamless(path, source_fps)
    poses = apply_hand_mean(m.poses, smpl_model, smpl_type, path, hand_mean)
    joints, names, parents = pose_joints(poses, m.trans, np.zeros(0), smpl_model, smpl_type, path)
    try:
        native = check_fps(m.fps, path)
    except ClipError as e:
        raise MotionError(str(e)) from None
    i0, i1, w = lerp_indices(len(joints), native, fps)  # bounded before the resampled copy (MAX_FRAMES)
    valid = m.valid[i0] & (m.valid[i1] | (w < 1e-9))
    joints = resample_positions(joints, native, fps)
    joints = upright(joints, names) if up == "auto" else to_y_up(joints, up)
    return joints, names, parents, valid


def upright(joints, names):
    """Joints turned so that the body's up (from the root to the head, the mean over frames) is +Y, by a rotation of
    a multiple of 90 degrees about one axis (never a mirror): a person filmed in a camera's frame, Y down or Z up,
    stands upright."""
    head = next((j for j, n in enumerate(names) if n == "head"), len(names) - 1)
    up = (joints[:, head] - joints[:, 0]).mean(0)
    axis = int(np.argmax(np.abs(up)))
    x, y, z = joints[..., 0], joints[..., 1], joints[..., 2]
    positive = up[axis] > 0
    turned = {
        (0, True): (-y, x, z),
        (0, False): (y, -x, z),
        (1, True): (x, y, z),
        (1, False): (x, -y, -z),
        (2, True): (x, z, -y),
        (2, False): (x, -z, y),
    }[(axis, positive)]
    return np.stack(turned, axis=-1)


def native_fps(path, source_fps=None):
    """A motion file's own frame rate, read from its header (BVH's Frame Time, a clip's or an SMPL-family file's
    fps key) without reading its frames; `source_fps` ([skeleton] fps) for .npy, and for SMPL-family files that
    store none. MotionError naming the file otherwise."""
    path = Path(path)
    try:
        if path.name.endswith(".npy"):
            fps = source_fps
        elif path.name.endswith(".npz"):
            fps = _npz_fps(path, source_fps)
        else:
            fps = clean_fps(header_fps(path))
    except (BvhError, ClipError) as e:
        raise MotionError(str(e)) from None
    if fps is None:
        raise MotionError(f"{path}: no frame rate in the file: set [skeleton] fps in the study file")
    return float(fps)


def header_frames(path):
    """How many frames a BVH file or a clip .npz holds, from its header alone (None for other formats and where the
    header cannot be read: the full reader then names what is wrong)."""
    path = Path(path)
    try:
        if path.name.endswith((".bvh", ".bvh.gz")):
            return header_timing(path)[1]
        if path.name.endswith(".npz"):  # a clip's joints (SMPL-family and Seamless files hold none)
            shape = npz_headers(path).get("joints", ((),))[0]
            return int(shape[0]) if len(shape) == 3 else None
    except (BvhError, ClipError):
        return None
    return None


def _npz_fps(path, source_fps):
    if seamless_files.is_seamless_file(path):
        return source_fps or seamless_files.FPS
    keys = ("fps",) if not is_smpl_file(path) else FPS_KEYS
    names = npz_headers(path)
    key = next((k for k in keys if k in names), None)
    if key is None:
        return source_fps
    with np.load(path, allow_pickle=False) as f:
        value = np.asarray(f[key]).reshape(-1)
    if value.size != 1 or value.dtype.kind not in "iuf":  # a complex fps would lose its imaginary part with a warning
        raise MotionError(f"{path}: {key} must be one real number, got {value.size} value(s) of type {value.dtype}")
    return check_fps(value[0], path)


def _positions(path, fps, up, skeleton, source_fps, smpl):
    """(joints [T, J, 3] Y up in file units, names, parents, metres per unit where the format fixes it, valid frames
    or None)."""
    if path.name.endswith(".npz"):
        if seamless_files.is_seamless_file(path):
            joints, names, parents, valid = _seamless_positions(path, fps, *smpl, source_fps, up)
            return joints, names, parents, 1.0, valid  # the body model's metres
        if is_smpl_file(path):
            joints, names, parents = _smpl_positions(path, fps, *smpl, source_fps)
            return _y_up(joints, names, parents, up), names, parents, None, None
        return (*_npz_positions(path, fps), 1.0, None)  # clips are in metres, Y up
    if path.name.endswith(".npy"):
        if source_fps is None:
            raise MotionError(f"{path}: a .npy file needs its frame rate: set [skeleton] fps in the study file")
        joints, names, parents = _npy_positions(path, skeleton, source_fps, fps)
    else:
        joints, names, parents = _bvh_positions(path, fps)
    return _y_up(joints, names, parents, up), names, parents, None, None


def _y_up(joints, names, parents, up):
    """The joints turned Y up: `up` as given, or with "auto" the axis along which the body is tallest."""
    return to_y_up(joints, detect_up(body_joints(joints, names, parents)) if up == "auto" else up)


def read_motion(
    path,
    fps,
    units="auto",
    up="auto",
    skeleton=None,
    source_fps=None,
    smpl_model=None,
    smpl_type=None,
    hand_mean="auto",
):
    """One motion file as a Motion at `fps`, in metres, Y up.

    Reads BVH of any skeleton (.bvh, .bvh.gz), joint-position arrays (.npy [T, J, 3]), clip .npz files,
    SMPL-family parameter files (.npz with poses, trans and betas, through the body model `smpl_model`) and
    Seamless Interaction participant files (.npz with `smplh:*` keys, through an SMPL-H model at its mean shape).

    Parameters
    ----------
    path : str or Path
        The motion file.
    fps : float
        The frame rate wanted; the motion is resampled to it.
    units : str or float
        "auto" (from the standing body's height: generation.data.skeleton_families.choose_unit), a key of UNITS
        ("m", "cm", "mm") or metres per unit (a number). A clip .npz is always metres and Y up.
    up : str
        "auto" (detected from the motion), "y" or "z".
    skeleton : Skeleton or None
        Joint names and parents; needed for .npy.
    source_fps : float or None
        The frame rate of .npy arrays (a .npy file stores none), and of SMPL-family files that store none.
    smpl_model : str or Path or None
        The SMPL, SMPL-H or SMPL-X body model (.npz) for SMPL-family files; they cannot be read without one.
    smpl_type : str or None
        "smpl", "smplh" or "smplx"; None to tell it from the model's joint count.
    hand_mean : bool or "auto"
        Whether the body model's mean hand pose is added to the stored hand rotations; "auto": as the file's layout
        does (BEAT2 adds it, AMASS and Seamless Interaction store full rotations; smpl_files.HAND_MEAN_LAYOUTS).

    Returns
    -------
    Motion
        joints [T, J, 3] float32 in metres, Y up; names [J]; parents [J] (-1 for the root, the first joint);
        fps; path; valid [T] (bool) for a file that marks frames invalid (Seamless Interaction), else None.

    Raises
    ------
    MotionError
        One line naming the file: unreadable or too large, a .npy without its frame rate, an SMPL-family file
        without its body model, a first joint that is not the root, NaN or infinite positions, or a body that is
        not a body's height after unit conversion (with units "auto": no unit tried gives a person's height).
    """
    path = Path(path)
    try:
        joints, names, parents, scale, valid = _positions(
            path, fps, up, skeleton, source_fps, (smpl_model, smpl_type, hand_mean)
        )
    except (BvhError, ClipError, SmplError) as e:
        raise MotionError(str(e)) from None
    odd = next((str(n) for n in names if not str(n).isprintable() or not str(n)), None)
    if odd is not None:  # names go into every message, table and page about the motion
        raise MotionError(f"{path}: a joint name must be printable text, got {ascii(odd)[:60]}")
    if parents[0] != -1:
        raise MotionError(f"{path}: the first joint ({names[0]}) must be the root (parent -1): the camera follows it")
    if not np.isfinite(joints).all():
        raise MotionError(f"{path}: positions contain NaN or infinite values")
    body = body_joints(joints, names, parents)
    if scale is None:
        scale = _unit(body, names, units, path)
    joints = joints * float(scale)
    check_height(body * float(scale), path)
    return Motion(joints.astype(np.float32), names, np.asarray(parents, np.int64), float(fps), str(path), valid)


def _unit(joints, names, units, path):
    """Metres per file unit: the study file's, or with "auto" the first candidate giving a person's height."""
    if units != "auto":
        return UNITS.get(units, units)
    try:
        return choose_unit(body_height(joints), names, path)[0]
    except UnitError as e:
        raise MotionError(str(e)) from None
