"""Exact invariants of the features, and generated poses put back onto them.

In the feature space (CONTRACTS §2) the root is the hips' floor projection, so the hips' x and z in the root frame
are 0 in every real frame, by construction. MG and FL model all 63 values freely, so their samples leave the hips a
little off the root, and a classifier that reads those two values tells every generated window from a real one,
though no rater can see it (bench/RESULTS.md#c2st). `root_hips` sets them back to 0 (the point of the invariant
nearest to the sample: the other 61 values stay), before the pose is fitted to the actor's rigid skeleton
(`rigid.fit_skeleton` keeps the hips where they are). `make_stimuli` records both steps in the manifest's
`postprocess` column as `root_hips+rigid_skeleton` (CONTRACTS §4); `fit_to_actor` is the one function that applies
them, there and in the quality guard.

`constant_dims` is the check over the training set that finds such invariants: the feature dimensions that hold
one value (to float tolerance) in every frame of every window (`python -m generation.motion.invariants
runs/dataset.npz`). On the Bandai-Namco training windows it finds the
hips' x and z and nothing else. The models keep spending likelihood on those two dimensions; dropping them from
the model, or conditioning on them, would need retraining (bench/RESULTS.md#model-realism).

Real data holds invariants that are not one feature's value too. The hips' three children (the spine and both
thighs) turn with the hips as one rigid body, and the chest's (the neck and both shoulders) with the chest, so the
hip and shoulder widths never change (exact to float rounding in the training windows; the models' samples move
them): `rigid.fit_skeleton` holds these, with the bone lengths. Not treated: the heading of the root is the pose's
own heading smoothed over the whole take (features.root_trajectory), so it is not a function of the window alone and
has no nearest point within it.
"""

import sys

import numpy as np

from moglow_eval.core import cli
from moglow_eval.core.clip import NPZ_READ_ERRORS, first_line, npz_headers

from . import rigid, skeleton

ROOT_HIPS = "root_hips"  # the manifest's postprocess step that puts the hips back on the root
HIPS_XZ = (0, 2)  # feature dimensions of the hips' x and z in the root frame (joint 0 is the hips)
POSTPROCESS = f"{ROOT_HIPS}+{rigid.RIGID}"  # what make_stimuli records for MG and FL: both steps, in this order
TOLERANCE = 1e-6  # metres: float32 rounding of coordinates of a metre or two is about 1e-7


def constant_dims(x, tolerance=TOLERANCE):
    """{dimension: value} of the features x [..., D] that hold one value, to within `tolerance`, over every frame
    of every window: the exact invariants of a training set."""
    flat = np.asarray(x, dtype=np.float64).reshape(-1, np.shape(x)[-1])
    if not len(flat):
        raise ValueError("constant_dims: no frames")
    lo, hi = flat.min(0), flat.max(0)
    return {int(d): float((lo[d] + hi[d]) / 2) + 0.0 for d in np.flatnonzero(hi - lo <= tolerance)}  # no -0


def hold(x, constants):
    """Features x [..., D] with every dimension of `constants` ({dimension: value}) set to its value; the same
    shape and dtype back. The nearest point of the invariant: no other value changes."""
    out = np.array(x, copy=True)
    for d, value in constants.items():
        out[..., d] = value
    return out


def root_hips(x):
    """Poses x [..., T, 63] with the hips on the root: their x and z in the root frame set to 0, as in real data."""
    return hold(x, dict.fromkeys(HIPS_XZ, 0.0))


def fit_to_actor(x, history):
    """Generated windows x [B, T, 63] with the hips on the root and every bone at the length of the window's actor,
    read from its real history [B, tau, 63]: what make_stimuli ships for MG and FL (POSTPROCESS), and what the
    quality guard measures."""
    return rigid.fit_to_history(root_hips(x), history)


def build_parser():
    """The command's argument parser: python -m generation.motion.invariants [DATASET.npz]."""
    ap = cli.ArgumentParser(prog="python -m generation.motion.invariants", description=__doc__.split("\n")[0])
    ap.add_argument("dataset", nargs="?", default="runs/dataset.npz", help="prepared data (default runs/dataset.npz)")
    return ap


def _main(argv):
    path = build_parser().parse_args(argv).dataset
    # This floor room may not import the dataset reader (generation.data.dataset): the archive's headers are read
    # first, so a file that is no .npz, or holds no training windows of the features, is one line before any load.
    shape = npz_headers(path, limit=None).get("train_x", (None,))[0]
    if shape is None:
        raise cli.UserError(f"{path}: missing key 'train_x' (a dataset of generation.data.prepare, CONTRACTS §2)")
    if len(shape) != 3 or shape[2] != skeleton.POSE_DIM:
        raise cli.UserError(f"{path}: 'train_x' {tuple(shape)} is not [N, T, {skeleton.POSE_DIM}] (CONTRACTS §2)")
    try:
        with np.load(path, allow_pickle=False) as d:
            x = d["train_x"]
    except NPZ_READ_ERRORS as e:
        raise cli.UserError(f"{path}: 'train_x' cannot be read ({first_line(e)})") from None
    print(f"{path}: {len(x)} training windows; the features held at one value (to {TOLERANCE:g} m):")
    for dim, value in constant_dims(x).items():
        print(f"  {dim}: {skeleton.JOINT_NAMES[dim // 3]} {'xyz'[dim % 3]} = {value:g}")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
