"""Motion clip files (CONTRACTS.md §1): world joint positions in metres, Y up, floor at y = 0.

The limits below are what any clip, and any motion file turned into one, must stay within. They are
far beyond real motion capture, and they exist so that a corrupt or hostile file fails with one line
instead of asking for gigabytes (a frame rate of 1e9 resampled to 20 fps, a 100000-pixel video) or
writing infinite coordinates.
"""

import struct
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from moglow_eval.core.cli import UserError

MIN_FPS, MAX_FPS = 1.0, 1000.0  # frames per second of any clip or motion file
MAX_FRAMES = 500_000  # about 7 hours at 20 fps
MAX_JOINTS = 1000
MAX_COORD_M = 1e5  # |coordinate| in metres
MAX_NPZ_BYTES = 1 << 30  # what the arrays of one .npz (or one .npy) may hold, 1 GiB, judged from their headers
MAX_NPZ_MEMBERS = 4096  # a clip has a handful, an SMPL-family or Seamless file a few dozen
# One person's mesh for the mesh style (SMPL-X has 10,475 vertices): its body model is refused beyond it when read
# (generation.data) and its mesh when drawn (rendering.mesh), one line each.
MAX_MESH_VERTICES = 200_000


# What numpy and zipfile raise on a damaged archive: its own types do not cover deflate and header errors.
# numpy parses an .npy header as Python: a corrupt one can end in tokenize.TokenError or SyntaxError, which are
# not ValueErrors, and zipfile raises NotImplementedError for a version or compression byte it does not know
# (each found by tests/generation/test_bad_input.py's fuzzing).
NPZ_READ_ERRORS = (
    OSError,
    ValueError,
    EOFError,
    zipfile.BadZipFile,
    zlib.error,
    struct.error,
    KeyError,
    tokenize.TokenError,
    SyntaxError,
    NotImplementedError,
)


class ClipError(UserError):
    """A clip file that does not follow CONTRACTS.md §1; the message names the file and key."""


def check_fps(fps, where):
    """`fps` as a float within [MIN_FPS, MAX_FPS]; ClipError naming `where` otherwise."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise ClipError(f"{where}: fps must be a number, got {fps!r}") from None
    if not MIN_FPS <= value <= MAX_FPS:  # also false for nan
        raise ClipError(f"{where}: fps must be between {MIN_FPS:g} and {MAX_FPS:g}, got {value:g}")
    return value


def check_frames(n_frames, where):
    if n_frames > MAX_FRAMES:
        raise ClipError(f"{where}: {n_frames} frames is more than the limit of {MAX_FRAMES}")


def check_joints(joints, where):
    """Finite coordinates within MAX_COORD_M metres."""
    if not np.isfinite(joints).all():
        raise ClipError(f"{where}: joints contain NaN or infinite values")
    if joints.size and np.abs(joints).max() > MAX_COORD_M:
        raise ClipError(f"{where}: a joint coordinate exceeds {MAX_COORD_M:g} m (wrong --scale?)")


def check_skeleton(parents, n_joints, where, names=None):
    """Integer parent indices, -1 for roots, each naming another joint of the clip, forming a tree (no cycle);
    `names`, where given, name the joints of a cycle in the error."""
    parents = np.asarray(parents)
    if parents.dtype.kind not in "iu":
        raise ClipError(f"{where}: 'parents' must be integers, got {parents.dtype}")
    if parents.shape != (n_joints,):
        raise ClipError(f"{where}: 'parents' must have J={n_joints} entries, got shape {parents.shape}")
    bad = np.flatnonzero((parents < -1) | (parents >= n_joints) | (parents == np.arange(n_joints)))
    if len(bad):
        raise ClipError(
            f"{where}: joint {bad[0]} has parent {parents[bad[0]]}, not -1 or another of the {n_joints} joints"
        )
    loop = _cycle(parents)
    if loop:
        text = " -> ".join(str(j) if names is None else str(names[j]) for j in loop)
        raise ClipError(f"{where}: the skeleton is not a tree: its parents form a cycle ({text})")
    return parents.astype(np.int64)


def _cycle(parents):
    """The joints of a cycle in `parents`, the first repeated at the end, or [] when every chain reaches a root.

    Each joint is walked up once: a walk that meets a joint it has already passed is in a cycle, and a joint whose
    root is known stops later walks, so the whole check is linear in the number of joints."""
    state = np.zeros(len(parents), np.int8)  # 0 not seen, 1 on the current walk, 2 reaches a root
    for start in range(len(parents)):
        walk, j = [], start
        while j >= 0 and state[j] == 0:
            state[j] = 1
            walk.append(j)
            j = int(parents[j])
        if j >= 0 and state[j] == 1:
            return [*walk[walk.index(j) :], j]
        state[walk] = 2
    return []


def clip_path(path):
    """An output path for a clip: must end in .npz (numpy would add it silently) and not be a folder."""
    path = Path(path)
    if path.is_dir():
        raise ClipError(f"{path}: is a folder; give the clip file to write, e.g. {path / 'clip.npz'}")
    if path.suffix != ".npz":
        raise ClipError(f"{path}: a clip file name must end in .npz")
    return path


def save_clip(path, joints, parents, joint_names, fps, control=None, **extra):
    """Write a clip .npz. `extra` keys are stored too (the contract allows added keys)."""
    path = clip_path(path)
    joints = np.asarray(joints, dtype=np.float32)
    if joints.ndim != 3 or joints.shape[2] != 3 or joints.shape[0] < 1 or joints.shape[1] < 1:
        raise ClipError(f"{path}: joints must be [T >= 1, J >= 1, 3], got {joints.shape}")
    check_joints(joints, path)
    fps = check_fps(fps, path)
    arrays = dict(
        joints=joints,
        parents=check_skeleton(parents, joints.shape[1], path),
        joint_names=np.asarray(joint_names, dtype=str),
        fps=np.float64(fps),
        **extra,
    )
    if control is not None:
        arrays["control"] = np.asarray(control, dtype=np.float32)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)


def first_line(exc):
    """The first line of an exception's message (its type's name where it has none), for one-line errors; of an
    OSError its words alone ("Permission denied"), not its errno and the path the message names already."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


_HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}


def npz_headers(path, limit=MAX_NPZ_BYTES):
    """{name: (shape, dtype)} of the arrays of an .npz, from each member's .npy header alone; ClipError naming the
    file when they would hold more than `limit` bytes in all (None: no limit, for a look at the names), a member
    that is not an array counting its inflated size, or when it has more than MAX_NPZ_MEMBERS members. numpy
    allocates an array whole from its header before it inflates the data, so a small archive with a hostile header
    would otherwise ask for any amount of memory."""
    out, total = {}, 0
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            if len(infos) > MAX_NPZ_MEMBERS:  # numpy lists every member: a hostile archive takes minutes to open
                raise ClipError(f"{path}: {len(infos)} members, more than the limit of {MAX_NPZ_MEMBERS}")
            for info in infos:
                with z.open(info) as f:
                    npy = info.filename.endswith(".npy")
                    # numpy reads a member not named .npy as an array too when it starts as one, else as bytes
                    if not npy and f.read(len(np.lib.format.MAGIC_PREFIX)) != np.lib.format.MAGIC_PREFIX:
                        total += info.file_size
                        continue
                    if not npy:
                        f.seek(0)
                    version = np.lib.format.read_magic(f)
                    if version not in _HEADER_READERS:
                        raise ClipError(f"{path}: member {info.filename} has .npy format version {version}")
                    shape, _, dtype = _HEADER_READERS[version](f)
                out[info.filename[:-4] if npy else info.filename] = (shape, dtype)
                total += int(np.prod(shape, dtype=object)) * dtype.itemsize
    except NPZ_READ_ERRORS as e:
        raise ClipError(f"{path}: not a readable .npz file ({first_line(e)})") from None
    if limit is not None and total > limit:
        raise ClipError(f"{path}: its arrays would take {total / 2**20:.0f} MiB, over the limit of {limit >> 20} MiB")
    return out


def _not_npz(path):
    """ClipError for a file that is neither a zip archive nor an .npy array, said as such: numpy's own message for
    it is about pickled data, which tells a user who gave a BVH or CSV file nothing."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(64)
    except OSError:
        return  # np.load names the error
    if head.startswith((b"\x93NUMPY", b"PK")):  # an .npy array, or a zip archive too broken to be found as one
        return
    if head.lstrip().upper().startswith(b"HIERARCHY") or str(path).lower().endswith((".bvh", ".bvh.gz")):
        raise ClipError(
            f"{path}: a BVH file, not an .npz clip (python -m generation.data.import_motion turns it into one)"
        )
    raise ClipError(f"{path}: not an .npz clip (a clip is a NumPy .npz archive: docs/CONTRACTS.md §1)")


def load_clip(path):
    """Read and check a clip .npz; returns a dict with at least joints, parents, joint_names, fps."""
    if zipfile.is_zipfile(path):
        npz_headers(path)
    else:
        _not_npz(path)
    try:
        f = np.load(path, allow_pickle=False)
    except NPZ_READ_ERRORS as e:
        raise ClipError(f"{path}: not a readable .npz clip ({first_line(e)})") from None
    if not isinstance(f, np.lib.npyio.NpzFile):
        raise ClipError(f"{path}: a single .npy array, not an .npz clip")
    try:
        with f:
            d = {k: f[k] for k in f.files}
    except NPZ_READ_ERRORS as e:
        raise ClipError(f"{path}: corrupt .npz member ({first_line(e)})") from None
    missing = [k for k in ("joints", "parents", "joint_names", "fps") if k not in d]
    if missing:
        raise ClipError(f"{path}: missing key '{missing[0]}'")
    j = d["joints"]
    if j.ndim != 3 or j.shape[2] != 3 or j.shape[0] < 1 or j.shape[1] < 1:
        raise ClipError(f"{path}: 'joints' must be [T >= 1, J >= 1, 3], got {j.shape}")
    if j.dtype.kind not in "fiu":
        raise ClipError(f"{path}: 'joints' must be numbers, got {j.dtype}")
    check_frames(j.shape[0], path)
    if j.shape[1] > MAX_JOINTS:
        raise ClipError(f"{path}: {j.shape[1]} joints is more than the limit of {MAX_JOINTS}")
    d["joints"] = j.astype(np.float32)
    check_joints(d["joints"], path)
    if d["joint_names"].shape != (j.shape[1],):
        raise ClipError(f"{path}: 'joint_names' must have J={j.shape[1]} entries")
    d["parents"] = check_skeleton(d["parents"], j.shape[1], path, d["joint_names"])
    if "control" in d and d["control"].shape != (j.shape[0], 3):
        raise ClipError(f"{path}: 'control' must be [T, 3], got {d['control'].shape}")
    if d["fps"].shape != ():
        raise ClipError(f"{path}: 'fps' must be a single number, got shape {d['fps'].shape}")
    d["fps"] = check_fps(d["fps"], path)
    d["joint_names"] = [str(n) for n in d["joint_names"]]
    return d
