"""Import another system's motion as an extra condition: `make_stimuli --system NAME=DIR`.

Convention: DIR holds one motion file per item, named by the item id and nothing else:
`ITEM.bvh`, `ITEM.bvh.gz` or `ITEM.npz` (a clip file, CONTRACTS.md §1), for every item listed in
the stimulus folder's `items.csv` with role `test` or `training` (`make_stimuli --export-items DIR`
writes that list, with each item's control and real history, before any model is trained). Other
files are ignored. Each file must hold at least the item's frame count (80 at 20 fps) after
resampling to 20 fps; longer files are cut to the first frames.

BVH files go through the same reader, skeleton detection and 21-joint mapping as the training data
(features.load_take: Bandai-Namco or CMU/PFNN skeletons). Clip files need either the 21 joint names
of generation.motion.skeleton or a skeleton that features knows (e.g. the output of
`python -m generation.data.import_motion`); their positions are taken as metres and linearly resampled.
"""

from pathlib import Path

import numpy as np

from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import ClipError, load_clip
from moglow_eval.core.study import CONDITION_NAME, RESERVED

from ..motion import skeleton
from ..motion.bvh import BvhError
from ..motion.features import detect_skeleton, load_take, map_joints, root_trajectory, rotate_y
from ..motion.resample import lerp_indices, same_rate

EXTENSIONS = (".bvh.gz", ".bvh", ".npz")


class SystemError_(UserError):
    """Bad --system input; the message names the spec, folder or file."""


def parse_system_spec(spec):
    """'NAME=DIR' -> (NAME, Path(DIR)); the folder must exist and the name be new and plain."""
    if "=" not in spec:
        raise SystemError_(f"--system {spec!r}: expected NAME=DIR, e.g. --system MYMODEL=out/bvh")
    name, folder = spec.split("=", 1)
    if not CONDITION_NAME.fullmatch(name):
        raise SystemError_(f"--system {spec!r}: NAME must be a letter then letters, digits, _ or - (at most 32)")
    if name.upper() in RESERVED:
        raise SystemError_(f"--system {spec!r}: NAME {name} is taken by a built-in condition ({', '.join(RESERVED)})")
    folder = Path(folder)
    if not folder.is_dir():
        raise SystemError_(f"--system {spec!r}: folder {folder} does not exist")
    return name, folder


def item_of(path):
    """The item id a file stands for: its name without .bvh, .bvh.gz or .npz (None for other files)."""
    name = Path(path).name
    for ext in EXTENSIONS:
        if name.endswith(ext):
            return name[: -len(ext)]
    return None


def find_system_files(folder, items):
    """{item: path} for every item in `items`; SystemError_ naming the missing ones."""
    found = {}
    for p in sorted(Path(folder).iterdir()):
        item = item_of(p)
        if item in items and p.is_file():
            if item in found:
                raise SystemError_(f"{folder}: two files for item {item}: {found[item].name} and {p.name}")
            found[item] = p
    missing = [i for i in items if i not in found]
    expected = "(expected ITEM.bvh, ITEM.bvh.gz or ITEM.npz; see items.csv)"
    if missing and not found:  # a wrong folder, or names unlike the items': naming each item would say less
        raise SystemError_(f"{folder}: no motion file for any of the {len(items)} items {expected}")
    if missing:
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise SystemError_(f"{folder}: no motion file for item(s) {', '.join(missing[:5])}{more} {expected}")
    return found


def resample_positions(joints, fps_in, fps_out):
    """Linear resampling of positions [T, J, 3] to fps_out over the same time span."""
    if same_rate(fps_in, fps_out):
        return joints
    i0, i1, w = lerp_indices(len(joints), fps_in, fps_out)
    w = w[:, None, None]
    return joints[i0] * (1 - w) + joints[i1] * w


def _clip_joints21(path):
    """A clip .npz as 21 joints [T, 21, 3] (metres) and its fps."""
    clip = load_clip(path)
    names = list(clip["joint_names"])
    pos = clip["joints"]
    if set(skeleton.JOINT_NAMES) <= set(names):
        return pos[:, [names.index(n) for n in skeleton.JOINT_NAMES]], clip["fps"]
    return map_joints(pos, names, detect_skeleton(names, path)), clip["fps"]


def load_system_motion(path, fps, n_frames):
    """One imported file as 21 joints [n_frames, 21, 3] float32 at `fps`; SystemError_ on any problem."""
    path = Path(path)
    try:
        if path.name.endswith(".npz"):
            joints, fps_in = _clip_joints21(path)
            span = int(np.ceil((n_frames - 1) * fps_in / fps)) + 2  # only what the item needs is resampled
            joints = resample_positions(np.asarray(joints[:span], np.float64), fps_in, fps)
        else:
            joints = load_take(path, fps)
    except (BvhError, ClipError) as e:
        raise SystemError_(str(e)) from None
    if len(joints) < n_frames:
        raise SystemError_(f"{path}: {len(joints)} frames at {fps:g} fps; the item needs {n_frames}")
    joints = np.asarray(joints[:n_frames], dtype=np.float32)
    if not np.isfinite(joints).all():
        raise SystemError_(f"{path}: motion contains NaN or infinite values")
    return joints


def canonical_placement(joints, fps, frame=0):
    """Move a clip so that its root at `frame` is at the origin facing +Z (features' yaw 0), floor unchanged.

    Every condition goes through this before rendering, so no clip's start position or heading can
    tell where it came from.
    """
    root, yaw = root_trajectory(joints, fps)
    out = np.asarray(joints, dtype=np.float64).copy()
    out[..., 0] -= root[frame, 0]
    out[..., 2] -= root[frame, 1]
    return rotate_y(out, -yaw[frame]).astype(np.float32)
