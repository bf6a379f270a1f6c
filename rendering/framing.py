"""Where the camera of a study of your own motion stands (the view) and how much of the body it frames.

A study file's `[render]` table (CONTRACTS §10) sets both. The view is an azimuth measured from the body's mean
facing over the item (all its clips' frames): "front" (0), "three-quarter" (40), "side" (90), or degrees. Without
a view the camera is the fixed set-up of the built-in study (40 degrees from +Z, the direction every clip faces
at its first frame). The framing is "full" (the whole body, `camera.framing_camera`), "upper" (the hips up, the
hands in every frame) or "auto" (upper when the feet barely move).

One camera per item frames all its clips, so that no clip's framing tells it from another's.
"""

from dataclasses import replace

import numpy as np

from moglow_eval.core import skeleton_names

from .camera import DEFAULT_CAMERA, HEAD_ROOM, NEAR, Projector, camera_targets, framing_camera
from .raster import head_joint

VIEWS = {"front": 0.0, "three-quarter": 40.0, "side": 90.0}  # degrees from the body's mean facing
FRAMINGS = ("full", "upper", "auto")
UPPER_ELEVATION = 5.0  # degrees: a nearly level camera, as a seated audience sees a speaker
UPPER_MARGIN = 0.005  # of the half-frame kept free around the framed body
BODY_PAD = 0.05  # metres around every framed joint: the solid body's limb capsules (raster.Style.limb_radius)
DETAIL_PAD = 0.012  # metres around a finger or face joint: the thin capsules (raster.Style.thin_radius)
HEAD_TOP = 0.18  # metres from the head joint along the neck to the drawn head's top (the solid's sphere; stick 0.16)
UPPER_FOV = 15.0  # degrees: a longer lens than the full body's, so that hands near the camera loom less
FEET_STILL = 0.4  # metres: "auto" frames the upper body when no foot strays further than this from its start
LEG_WORDS = {"leg", "upleg", "thigh", "knee", "shin", "calf", "foot", "ankle", "toe", "toes", "heel"}


def leg_joints(names, parents):
    """Indices of the leg joints (named like legs, feet or sided hips) and everything below them."""
    out = set()
    for j, name in enumerate(names):
        words = set(skeleton_names.tokens(name))
        sided_hip = "hip" in words and skeleton_names.side(name) is not None
        if words & LEG_WORDS or sided_hip or (parents[j] >= 0 and parents[j] in out):
            out.add(j)
    return sorted(out)


def hips_ancestors(parents, legs):
    """The joints above the hips in the hierarchy (the hips: the parents of the legs' top joints): a root joint on
    the floor, as Bandai-Namco's `joint_Root`, is no part of the upper body and would pull the frame down to it."""
    hips = {parents[j] for j in legs if parents[j] >= 0 and parents[j] not in legs}
    out = set()
    for j in hips:
        while parents[j] >= 0:
            j = parents[j]
            out.add(j)
    return out


def mean_facing(clips, names):
    """The body's mean facing over `clips` (joints [T, J, 3], Y up) as an azimuth in degrees (from +Z towards
    +X), from the left joints' mean minus the right's in every frame; 0 where the names tell no sides."""
    left = [j for j, n in enumerate(names) if skeleton_names.side(n) == "left"]
    right = [j for j, n in enumerate(names) if skeleton_names.side(n) == "right"]
    if not left or not right:
        return 0.0
    total = np.zeros(2)
    for joints in clips:
        across = np.asarray(joints)[:, left].mean(1) - np.asarray(joints)[:, right].mean(1)
        facing = np.stack([-across[:, 2], across[:, 0]], 1)  # (x, z) of across x up
        facing /= np.maximum(np.linalg.norm(facing, axis=1, keepdims=True), 1e-9)
        total += facing.sum(0)
    return float(np.degrees(np.arctan2(total[0], total[1]))) if np.linalg.norm(total) > 1e-9 else 0.0


def feet_still(clips, names, parents):
    """True when no leg joint moves further than FEET_STILL on the floor from where it starts, in any clip."""
    legs = leg_joints(names, parents) or [0]
    for joints in clips:
        xz = np.asarray(joints)[:, legs][..., [0, 2]]
        if np.linalg.norm(xz - xz[:1], axis=-1).max() > FEET_STILL:
            return False
    return True


def upper_camera(clips, names, parents, fps, base):
    """A camera that frames the body from the hips up: every joint but the legs' and the drawn head's top inside
    the frame in every frame of every clip, as large as that allows, through a nearly level camera at `base`'s
    azimuth that follows the root as `camera_targets` does. Each joint is padded by what is drawn around it
    (BODY_PAD, DETAIL_PAD for fingers and face), the head's top (HEAD_TOP along the neck) by nothing, so that
    the frame ends at the head's top above and at the lowest fingertip below: hands hanging below the hips
    extend the frame downwards, and the hips-to-head share of the frame is what is left above them."""
    base = replace(base, elevation=UPPER_ELEVATION, fov=UPPER_FOV)
    legs = set(leg_joints(names, parents))
    below = legs | hips_ancestors(parents, legs)
    keep = [j for j in range(len(names)) if j not in below] or list(range(len(names)))
    head = head_joint(names)
    rot = Projector(replace(base, distance=1.0), 2, 2).rot
    points, pads = [], []
    for joints in clips:
        joints = np.asarray(joints, dtype=np.float64)
        floor = camera_targets(joints, fps, base) * np.array([1.0, 0.0, 1.0])
        rel = joints - floor[:, None]
        if head is not None and parents[head] >= 0:
            neck = rel[:, head] - rel[:, parents[head]]
            top = rel[:, head] + HEAD_TOP * neck / np.maximum(np.linalg.norm(neck, axis=1, keepdims=True), 1e-6)
        else:
            top = rel[np.arange(len(rel)), rel[:, keep, 1].argmax(1)] + np.array([0.0, HEAD_ROOM, 0.0])
        points += [rel[:, keep].reshape(-1, 3), top]
        pad = [DETAIL_PAD if skeleton_names.is_detail(names[j]) else BODY_PAD for j in keep]
        pads += [np.tile(pad, len(rel)), np.zeros(len(rel))]
    points, pad = np.concatenate(points), np.concatenate(pads)
    q = points @ rot.T  # camera axes, relative to the target on the floor
    up = rot[:, 1]  # the camera-axis components of world up
    lim = (1 - UPPER_MARGIN) * np.tan(np.radians(base.fov) / 2)
    height = float(points[:, 1].mean())
    for _ in range(4):  # fit the distance, then centre the look-at height on the framed span, and again
        p = q - height * up
        distance = _distance(p, lim, pad)
        z = p[:, 2] + distance
        y_hi, y_lo = ((p[:, 1] + pad) / z).max(), ((p[:, 1] - pad) / z).min()
        height += float((y_hi + y_lo) / 2 * np.median(z)) / max(up[1], 1e-6)
    distance = _distance(q - height * up, lim, pad)
    return replace(base, distance=distance, height=height)


def _distance(p, lim, pad):
    """The least camera distance at which every point p (camera axes, relative to the look-at point), padded by
    `pad` metres (one a point), is inside the frame of half-width lim (the tangent of half the field of view)."""
    return float(max(((np.abs(p[:, :2]).max(1) + pad) / lim - p[:, 2]).max(), NEAR + BODY_PAD - p[:, 2].min()))


def item_camera(clips, names, parents, fps, view=None, framing="full"):
    """The camera of one item's clips (joints [T, J, 3], metres, Y up, placed).

    Parameters
    ----------
    clips : sequence of ndarray
        Every clip of the item.
    names, parents : sequence
        The skeleton.
    fps : float
        The clips' frame rate (the camera follows the root's smoothed path).
    view : str or float or None
        A key of VIEWS or degrees from the body's mean facing; None: the built-in study's fixed azimuth.
    framing : str
        "full", "upper" or "auto" (upper when the feet barely move: `feet_still`).

    Returns
    -------
    Camera
    """
    base = DEFAULT_CAMERA
    if view is not None:
        offset = VIEWS[view] if isinstance(view, str) else float(view)
        base = replace(base, azimuth=(mean_facing(clips, names) + offset) % 360.0)
    if framing == "auto":
        framing = "upper" if feet_still(clips, names, parents) else "full"
    if framing == "upper":
        return upper_camera(clips, names, parents, fps, base)
    return framing_camera(clips, base)
