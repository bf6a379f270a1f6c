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
# Of the half-frame kept free around the framed body: the drawing's antialiased edge and the 2x2 block of pixels
# that shares its colour (yuv420p) spill a pixel or two beyond what the pads cover: two pixels at 160 px high.
UPPER_MARGIN = 0.025
BODY_PAD = 0.05  # metres around every framed joint: the solid body's limb capsules (raster.Style.limb_radius)
DETAIL_PAD = 0.012  # metres around a finger or face joint: the thin capsules (raster.Style.thin_radius)
# The drawn head, framed as a ball (seen from any side, a head tipped towards the camera included): its centre this
# far from the head joint along the neck (the stick's disc, Style.head_radius; the solid's sphere, 0.8 of its
# radius), and this radius around it (the solid's sphere, Style.sphere_radius; the stick's disc and its outline).
HEAD_CENTRE = 0.08
HEAD_RADIUS = 0.1
HEAD_TOP = HEAD_CENTRE + HEAD_RADIUS  # metres from the head joint along the neck to the drawn head's top
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


def upper_camera(clips, names, parents, fps, base, room=0.0, aspect=1.0, reach=None):
    """A camera that frames the body from the hips up: every joint but the legs' and the drawn head inside the
    frame (`aspect`: its width over its height) in every frame of every clip, as large as that allows, through a
    nearly level camera at `base`'s azimuth that follows the root as `camera_targets` does. Each joint is padded
    by what is drawn around it (`framed_points`), so that the frame ends at the head's top above and at the lowest
    fingertip below: hands hanging below the hips extend the frame downwards, and the hips-to-head share of the
    frame is what is left above them."""
    base = replace(base, elevation=UPPER_ELEVATION, fov=UPPER_FOV)
    points, pads, root = [], [], skeleton_names.body_root(names, parents)
    for joints in clips:
        joints = np.asarray(joints, dtype=np.float64)
        floor = camera_targets(joints, fps, base, root) * np.array([1.0, 0.0, 1.0])
        framed_points(joints - floor[:, None], names, parents, True, points, pads, reach)
    distance, height = _fit(np.concatenate(points), np.concatenate(pads), base, room, aspect)
    return replace(base, distance=distance, height=height)


def framed_points(rel, names, parents, upper, points, pads, reach=None):
    """Append to `points` and `pads` what a camera must frame of one clip (joints [T, J, 3] relative to the
    look-at point on the floor): every joint (upper: but the legs' and the hips' ancestors), each padded by what
    is drawn around it (BODY_PAD, DETAIL_PAD for fingers and face; or `reach` [J], metres a joint, where more is
    drawn around it: a mesh's surface, its fingertips beyond the last finger joint), and the drawn head as a ball
    (HEAD_RADIUS around HEAD_CENTRE along the neck). A root marker (core.skeleton_names.root_markers) is not drawn,
    and not framed."""
    below = set(skeleton_names.root_markers(names, parents))  # not drawn (raster)
    if upper:
        legs = set(leg_joints(names, parents))
        below |= legs | hips_ancestors(parents, legs)
    keep = [j for j in range(len(names)) if j not in below] or list(range(len(names)))
    head = head_joint(names)
    if head is not None and parents[head] >= 0:
        neck = rel[:, head] - rel[:, parents[head]]
        ball = rel[:, head] + HEAD_CENTRE * neck / np.maximum(np.linalg.norm(neck, axis=1, keepdims=True), 1e-6)
        radius = HEAD_RADIUS
    else:
        ball = rel[np.arange(len(rel)), rel[:, keep, 1].argmax(1)] + np.array([0.0, HEAD_ROOM, 0.0])
        radius = 0.0
    points += [rel[:, keep].reshape(-1, 3), ball]
    pad = np.array([DETAIL_PAD if skeleton_names.is_detail(names[j]) else BODY_PAD for j in keep])
    if reach is not None and len(reach) == len(names):
        pad = np.maximum(pad, np.asarray(reach, np.float64)[keep])
    pads += [np.tile(pad, len(rel)), np.full(len(rel), radius)]


def _fit(points, pad, base, room=0.0, aspect=1.0):
    """(distance, look-at height) at which every point (relative to the look-at point on the floor [N, 3]), padded
    by `pad` metres (one a point), is inside the frame of `base`'s view and field of view (vertical; `aspect` times
    as wide), as large as that allows, with the lowest `room` of the frame's height kept free (for captions: the
    body is framed in the rest)."""
    rot = Projector(replace(base, distance=1.0), 2, 2).rot
    q = points @ rot.T  # camera axes, relative to the target on the floor
    up = rot[:, 1]  # the camera-axis components of world up
    lim = (1 - UPPER_MARGIN) * np.tan(np.radians(base.fov) / 2)
    lims = np.array([aspect * lim, (1 - room) * lim])
    height = float(points[:, 1].mean())
    for _ in range(4):  # fit the distance, then centre the look-at height on the framed span, and again
        p = q - height * up
        distance = _distance(p, lims, pad)
        z = p[:, 2] + distance
        y_hi, y_lo = ((p[:, 1] + pad) / z).max(), ((p[:, 1] - pad) / z).min()
        height += float((y_hi + y_lo) / 2 * np.median(z)) / max(up[1], 1e-6)
    p = q - height * up
    distance = _distance(p, lims, pad)
    # The body fills the frame less `room`, centred; lowering the look-at point raises it into the top of the frame.
    height -= float(room * lim * np.median(p[:, 2] + distance)) / max(up[1], 1e-6)
    return distance, height


def _distance(p, lim, pad):
    """The least camera distance at which every point p (camera axes, relative to the look-at point), padded by
    `pad` metres (one a point), is inside the frame of half-width lim (the tangent of half the field of view; or
    [across, up])."""
    reach = ((np.abs(p[:, :2]) + pad[:, None]) / np.broadcast_to(lim, (2,))).max(1)
    return float(max((reach - p[:, 2]).max(), NEAR + BODY_PAD - p[:, 2].min()))


def item_camera(clips, names, parents, fps, view=None, framing="full", room=0.0, facing=None, aspect=1.0, reach=None):
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
    room : float
        The share of the frame's height kept free of the body at the bottom (captions); upper framing only.
    facing : sequence of ndarray or None
        The clips whose mean facing `view` is measured from (None: `clips`): a study's reference, so that the
        view does not turn when a system joins.
    aspect : float
        The frame's width over its height (upper framing).
    reach : ndarray or None
        Metres drawn around each joint [J] beyond what BODY_PAD and DETAIL_PAD allow (a mesh's surface); upper
        framing.

    Returns
    -------
    Camera
    """
    base = DEFAULT_CAMERA
    if view is not None:
        offset = VIEWS[view] if isinstance(view, str) else float(view)
        base = replace(base, azimuth=(mean_facing(clips if facing is None else facing, names) + offset) % 360.0)
    if framing == "auto":
        framing = "upper" if feet_still(clips, names, parents) else "full"
    if framing == "upper":
        return upper_camera(clips, names, parents, fps, base, room, aspect, reach)
    # Only what is drawn is framed: not a root marker left at the scene's origin (raster draws no bone from one).
    drawn = skeleton_names.body_skeleton(names, parents)[0]
    root = drawn.index(skeleton_names.body_root(names, parents))
    return framing_camera([np.asarray(c)[:, drawn] for c in clips], base, root=root)


# The steps a study's cameras are held to (steady): a system whose motion stays inside the frame leaves its item's
# camera, and so every other clip of the item, as it was.
DISTANCE_STEP = 0.03  # the distance, up to the next of a 3% ladder (with 1% to spare: room for the height's step)
HEIGHT_STEP = 0.01  # metres: the look-at height and lag, to the nearest centimetre


def steady(camera):
    """The camera held to steps: its distance up to the next step of a ladder (never nearer: what was framed stays
    framed, and a little more), its height and lag to the nearest HEIGHT_STEP. A study's build keys each video by
    its camera (generation.stimuli.build_index): a condition that joins without leaving the frame then re-renders
    nothing of the others."""
    rung = np.ceil(np.log(camera.distance * 1.01) / np.log1p(DISTANCE_STEP))
    return replace(
        camera,
        distance=float(np.exp(rung * np.log1p(DISTANCE_STEP))),
        height=float(np.round(camera.height / HEIGHT_STEP) * HEIGHT_STEP),
        max_lag=float(np.round(camera.max_lag / HEIGHT_STEP) * HEIGHT_STEP),
    )


# A two-person item's views, in degrees from the perpendicular of the two people's line towards the agent's front.
# "side" (the default) sees the two, each turned a little towards the camera (generation.own_study.placing), alike
# and at one distance, so that each is as large as one person in an upper frame; "three-quarter" sees the agent
# nearer three-quarter and the other person nearly in profile, the agent further away and smaller.
PAIR_VIEWS = {"side": 0.0, "three-quarter": 20.0, "front": 60.0}
PAIR_VIEW = "side"
PAIR_FOV = 20.0  # degrees: the full bodies of two people
PAIR_ELEVATION = 8.0  # degrees, full bodies (the upper framing takes the one-person UPPER_ELEVATION)
# Degrees: two people from the hips up. A longer lens than one person's (UPPER_FOV): a hand held towards the camera
# (or, seen at three-quarter, the nearer of the two) looms less, the further the camera.
PAIR_UPPER_FOV = 10.0
# Two people side by side in a frame three times as wide as high, as GENEA 2026's visualiser films them (1536x512):
# each person's upper body then fills the frame's height, as one person's does in a square upper frame.
PAIR_ASPECT = 3.0


def pair_azimuth(agent_root, partner_root, agent_facing, view=None):
    """The camera's azimuth (degrees, from +Z towards +X) for two people: on the side of the line between their
    roots (x, z) that the agent faces (its mean facing, degrees), turned `view` (a key of PAIR_VIEWS or degrees;
    None: PAIR_VIEW) from the perpendicular towards the agent's front."""
    offset = PAIR_VIEWS[view or PAIR_VIEW] if not isinstance(view, (int, float)) else float(view)
    line = np.asarray(partner_root, np.float64) - np.asarray(agent_root, np.float64)
    line /= max(np.linalg.norm(line), 1e-9)
    side = np.array([-line[1], line[0]])  # the line turned a quarter: one side's perpendicular (x, z)
    facing = np.array([np.sin(np.radians(agent_facing)), np.cos(np.radians(agent_facing))])
    if side @ facing < 0:
        side = -side
    a = np.radians(offset)
    direction = np.cos(a) * side + np.sin(a) * line
    return float(np.degrees(np.arctan2(direction[0], direction[1])) % 360.0)


def pair_camera(clips, people, view=None, framing="upper", room=0.0, aspect=1.0, facing=None, reach=(None, None)):
    """One fixed camera for a two-person item: (Camera, look-at point [3]).

    Parameters
    ----------
    clips : sequence of ndarray
        Every clip of the agent in the item (joints [T, J, 3], metres, Y up, placed beside the partner).
    people : sequence of (names, parents, partner joints or None)
        The agent's skeleton (partner None) and the partner's skeleton and joints [T, K, 3].
    view : str or float or None
        A key of PAIR_VIEWS or degrees from the perpendicular of their line towards the agent's front (the side
        the agent faces); None: PAIR_VIEW, side.
    framing : str
        "upper" (hips up: the usual for people talking), "full", or "auto" (upper).
    room : float
        The share of the frame's height kept free of the bodies at the bottom (captions).
    aspect : float
        The frame's width over its height (PAIR_ASPECT: the wide frame two people are filmed in).
    facing : sequence of ndarray or None
        The agent's clips the view and the look-at point are measured from (None: `clips`): the reference's, so
        that they stay put when a system joins.
    reach : (ndarray or None, ndarray or None)
        The agent's and the partner's metres drawn around each joint beyond BODY_PAD and DETAIL_PAD (a mesh's
        surface: framed_points).

    Returns
    -------
    (Camera, ndarray)
        The camera (as close as framing both in every frame of every clip allows, held to steps: `steady`) and the
        point it looks at in every frame: between the two, so that it never moves and the partner is the same
        pixels in every condition's video.
    """
    (names, parents, _), (p_names, p_parents, partner) = people
    measured = clips if facing is None else facing
    root, p_root = skeleton_names.body_root(names, parents), skeleton_names.body_root(p_names, p_parents)
    roots = np.mean([np.asarray(c)[:, root, [0, 2]].mean(0) for c in measured], 0)
    partner_root = np.asarray(partner)[:, p_root, [0, 2]].mean(0)
    azimuth = pair_azimuth(roots, partner_root, mean_facing(measured, names), view)
    upper = framing != "full"
    fov, elevation = (PAIR_UPPER_FOV, UPPER_ELEVATION) if upper else (PAIR_FOV, PAIR_ELEVATION)
    base = replace(DEFAULT_CAMERA, azimuth=azimuth, fov=fov, elevation=elevation)
    centre = (roots + partner_root) / 2
    floor = np.array([centre[0], 0.0, centre[1]])
    points, pads = [], []
    for joints in clips:
        framed_points(np.asarray(joints, np.float64) - floor, names, parents, upper, points, pads, reach[0])
    framed_points(np.asarray(partner, np.float64) - floor, p_names, p_parents, upper, points, pads, reach[1])
    distance, height = _fit(np.concatenate(points), np.concatenate(pads), base, room, aspect)
    camera = steady(replace(base, distance=distance, height=height))
    return camera, np.array([centre[0], camera.height, centre[1]])
