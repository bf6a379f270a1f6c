"""Turn any BVH file into a motion clip .npz (CONTRACTS.md §1).

    python -m generation.data.import_motion IN.bvh[.gz] OUT.npz [--scale 0.01] [--fps 20]

All joints of the file, world positions by forward kinematics, times `--scale` (file units -> metres;
default 0.01 for centimetre files), resampled to `--fps` when given (rotations are slerped, so bones
keep their lengths). When the skeleton is one the project knows (Bandai-Namco, CMU/PFNN), the clip
also gets the root `control` of its 21-joint body (features.to_features), in the clip's units.
"""

import logging
import sys

import numpy as np

from moglow_eval.core import cli
from moglow_eval.core.clip import MAX_FPS, MIN_FPS, clip_path, save_clip

from ..motion.bvh import BvhError, read_bvh
from ..motion.features import bvh_world_positions, detect_skeleton, map_joints, to_features
from ..motion.resample import clean_fps

log = logging.getLogger(__name__)


def import_motion(in_path, out_path, scale=0.01, fps=None):
    """Convert one BVH file to a clip .npz (CONTRACTS §1), as `python -m generation.data.import_motion` does.

    All joints of the file, world positions by forward kinematics, times `scale`. When the skeleton is one the
    project knows (Bandai-Namco, CMU/PFNN), the clip also gets the root control of its 21-joint body, in the
    clip's units; any other skeleton imports without it.

    Parameters
    ----------
    in_path : str or Path
        The BVH file (.bvh or .bvh.gz).
    out_path : str or Path
        The clip .npz to write.
    scale : float
        File units to metres (0.01 for centimetre files).
    fps : float or None
        The frame rate of the clip: the motion is resampled to it (rotations are slerped, so bones keep their
        lengths); None: the file's own rate.

    Returns
    -------
    ndarray
        The joint positions written, [T, J, 3] float32.

    Raises
    ------
    BvhError
        One line naming the file and line: an unreadable BVH, or one with no frames.
    """
    bvh = read_bvh(in_path)
    if bvh.n_frames < 1:
        raise BvhError(f"{in_path}:1: no frames")
    fps_out = clean_fps(bvh.fps) if fps is None else float(fps)
    pos = bvh_world_positions(bvh, fps_out if bvh.n_frames > 1 else None)
    joints = (pos * scale).astype(np.float32)
    extra = {}
    try:
        key = detect_skeleton(bvh.names, f"{in_path}:1")
    except BvhError as e:  # any skeleton imports; only the control needs a known one
        log.warning(f"note: no control written: {e}")
        key = None
    if key is not None and len(joints) > 1:
        # control in the clip's own units (so it integrates back onto its joints whatever --scale is)
        extra["control"] = to_features(map_joints(joints, bvh.names, key), fps_out)[1]
    save_clip(out_path, joints, bvh.parents, bvh.names, fps_out, **extra)
    return joints


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.data.import_motion", description=__doc__.split("\n")[0])
    ap.add_argument("input", help="BVH file (.bvh or .bvh.gz)")
    ap.add_argument("output", help="clip .npz to write")
    ap.add_argument(
        "--scale",
        type=cli.number(float, lo=0, hi=1e3, lo_open=True),
        default=0.01,
        help="metres per file unit (default 0.01: centimetres)",
    )
    ap.add_argument(
        "--fps",
        type=cli.number(float, MIN_FPS, MAX_FPS),
        default=None,
        help="resample to this frame rate (default: keep the file's)",
    )
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.log_to_stderr()
    joints = import_motion(args.input, clip_path(args.output), args.scale, args.fps)
    print(f"{args.output}: {joints.shape[0]} frames, {joints.shape[1]} joints")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
