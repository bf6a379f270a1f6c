"""Catch clips made by the tool: clearly broken versions of a real clip, for any skeleton (CONTRACTS §10).

A catch trial only works if every attentive rater sees that the clip is broken, and (CONTRACTS §4) if nothing but
its pixels tells it from a test clip. The kinds break motion in different ways, so a mix of them spreads the catch
clips' look and their encoded size on both sides of the test clips':

- `jitter`: every joint shakes by independent noise of JITTER_SIGMA times the body's height, every frame;
- `freeze`: the body stops dead a quarter of the way in and holds that pose to the end, its root still moving;
- `swap`: the upper body plays half a clip out of step with the legs (and jumps where it wraps round), turning
  round about the vertical through the root twice over the clip: a twist no spine makes, seen from every view.
  Out of step alone, a calm take's upper body (a wave, a bow, over legs that hardly move) was the take played
  later, which a rater could take for real motion.

A kind can fail on a take: a freeze of one that hardly moves after its freeze point is the take itself to a rater,
who would then be excluded for rating it as real. `make_visible_catch` makes the next kind of a study's mix where
the first would not stray VISIBLE from the take.

How bad each is, on the metrics of metrics.csv, is in bench/notes/2026-11-25-history.md ("Catch clips made by the
tool") and, for today's kinds, bench/notes/2026-12-02-results-details.md ("c2st").
"""

import numpy as np

from ..data.motion_files import body_height
from ..motion.features import rotate_y

JITTER_SIGMA = 0.03  # of the body's height per joint and frame: about 5 cm for an adult
FREEZE_AT = 0.25  # of the clip's length
SWAP_TURNS = 2  # full turns of the swapped upper body over the clip
# How far a catch clip's most-moved joint must stray from the take's (about the root; the 90th percentile over frames)
# for its break to be seen: a judgement, not measured with raters. A freeze of a take still after its first quarter
# (a short goodbye) strays less; bench/catch_kinds.py counts the takes each kind leaves unseen.
VISIBLE = 0.05  # m


def jitter(joints, rng, root=0):
    return joints + rng.normal(0.0, JITTER_SIGMA * body_height(joints), joints.shape)


def freeze(joints, rng, root=0):
    out = joints.copy()
    t0 = max(1, int(round(FREEZE_AT * len(joints))))
    path = joints[:, root : root + 1]
    out[t0:] = joints[t0 - 1] - path[t0 - 1] + path[t0:]  # the pose at t0-1, carried along by the root
    return out


def upper_body(joints):
    """Joints whose mean height lies above the midpoint of all joints' mean heights: the trunk, arms and head."""
    height = joints[..., 1].mean(axis=0)
    return height > 0.5 * (height.min() + height.max())


def swap(joints, rng, root=0):
    out = joints.copy()
    up = upper_body(joints)
    path = joints[:, root : root + 1]
    shifted = np.roll(joints - path, len(joints) // 2, axis=0)  # half a clip away, wrapping round
    # Turned round about the vertical through the root, SWAP_TURNS times over the clip: a spine cannot, whatever the
    # motion and from every view.
    angle = 2.0 * np.pi * SWAP_TURNS * np.arange(len(joints)) / len(joints)
    out[:, up] = rotate_y(shifted, angle[:, None])[:, up] + path
    return out


KINDS = {"jitter": jitter, "freeze": freeze, "swap": swap}


def _about_root(clip, root):
    clip = np.asarray(clip, dtype=np.float64)
    return clip - clip[:, root : root + 1]


def unlike_any_pose(clip, real, root=0):
    """Per frame of `clip` [T, J, 3], how far its pose about the root is from the nearest pose of `real` [T', J, 3]
    (m, the mean over joints): 0 for a pose the real clip holds itself, as a calm take's time-shifted upper body
    does. What tells a broken body from the take it was made from, whatever the camera (bench/catch_kinds.py)."""
    a, b = _about_root(clip, root), _about_root(real, root)
    return np.array([np.linalg.norm(frame - b, axis=-1).mean(-1).min() for frame in a])


def strays(broken, real, root=0):
    """How far the most-moved joint of `broken` [T, J, 3] is from `real`'s, each about its root, at the 90th
    percentile over frames (m): whether a rater can see what was broken (VISIBLE), whatever the camera."""
    a, b = _about_root(broken, root), _about_root(real, root)
    return float(np.percentile(np.linalg.norm(a - b, axis=-1).max(-1), 90))


def make_visible_catch(joints, kinds, seed, root=0):
    """(broken copy, kind) of `joints` by the first of `kinds` whose clip strays at least VISIBLE from them
    (make_catch, `seed`, `root`); None where no kind of `kinds` does."""
    for kind in kinds:
        broken = make_catch(joints, kind, seed, root)
        if strays(broken, joints, root) >= VISIBLE:
            return broken, kind
    return None


def make_catch(joints, kind, seed, root=0):
    """A broken copy of joints [T, J, 3] (metres, Y up) of catch kind `kind`, seeded; `root` is the body's root
    joint (core.skeleton_names.body_root), which carries a frozen pose and the swapped upper body along: not a
    root marker left at the scene's origin, from which a walk's torso would be swapped in metres away."""
    rng = np.random.default_rng(seed)
    return KINDS[kind](np.asarray(joints, dtype=np.float64), rng, root).astype(np.float32)
