"""Objective motion metrics per clip (21-joint order of generation.motion.skeleton), for metrics.csv.

- foot_skating (m/s): mean horizontal speed of a foot (ankle and toe joints) over the frame pairs in
  which it is in contact. Contact: in both frames the foot's ankle and toe are each less than
  CONTACT_HEIGHT = 1 cm above the lowest height that joint reaches in the clip (the floor as that
  foot sees it, so a clip floating a little above y = 0 is judged the same way). Real Bandai-Namco
  walks score about 0.06 m/s (runs 0.05, backward walks 0.10), against walking speeds of 1.3 m/s.
  A foot that meets this in fewer than 10% of frame pairs (jittery generated motion that never rests)
  counts as in contact in its lowest 10%, so the metric is defined for every clip.
- bone_length_std (m): standard deviation over time of each bone's length, averaged over bones
  (0 for any rigid skeleton; generators that output joint positions need not keep bones rigid).
- jerk (m/s^3): mean norm of the third time derivative of joint positions (finite differences).
- acceleration (m/s^2): mean norm of the second time derivative of joint positions.
- control_error (m): how far the root path implied by the body (the hips projected on the floor)
  strays from the path that the requested control integrates to. The two paths are first aligned by
  the rigid 2-D motion (rotation + translation on the floor) that fits them best, so a clip placed or
  turned differently in the world (an imported system) is not penalised for that alone. NAT, MG and FL
  clips are built by integrating the requested control (features.to_world) with the hips as the root,
  so for them it is ~0 by construction; it measures imported systems, which move the body themselves.
- control_following (m): how far the path that the body itself implies strays from the requested path.
  The body implies its own travel through its feet: while a foot is in contact (as for foot_skating), the
  body moves by the hips' displacement minus that foot's; in flight, by the hips' displacement. That path,
  integrated over the clip and rigidly aligned as for control_error, is compared with the requested one
  (mean distance). Real motion follows its control to a few centimetres. A generator that moves its feet
  as if it walked elsewhere (ignoring a side-step, walking on the spot) drifts by metres, while zero-mean
  jitter, which foot_skating and jerk measure, largely cancels along the path.

Not in metrics.csv, for the models' own output (root-frame poses, generation.motion.features):
- late_stepping (m): how far the feet swing about each other over a clip's last 2 s, the standard deviation of
  the horizontal vector from the right foot to the left (forward and sideways, so side-steps count too). Stepping
  swings it by tens of centimetres; a gait that dies out into a standing pose gives about 0.
"""

import numpy as np

from moglow_eval.core.skeleton_names import body_skeleton, side
from moglow_eval.core.study import METRIC_NAMES

from ..motion import skeleton

CONTACT_HEIGHT = 0.01  # m above each foot joint's lowest point in the clip
CONTACT_FALLBACK = 0.1  # a foot is in contact in at least its lowest 10% of frame pairs


def foot_contacts(joints, feet=tuple(skeleton.FEET), contact_height=CONTACT_HEIGHT, fallback=CONTACT_FALLBACK):
    """Per foot, whether it is in contact in each frame pair: bool [n_feet, T-1] (see foot_skating)."""
    contacts = []
    for pair in np.asarray(feet).reshape(-1, 2):
        height = joints[:, pair, 1]  # [T, 2]
        rel = (height - height.min(axis=0)).max(axis=1)  # [T] the higher joint
        score = np.maximum(rel[1:], rel[:-1])  # [T-1] per frame pair
        contacts.append(score <= max(contact_height, np.quantile(score, fallback)))
    return np.array(contacts)


def foot_steps(joints, feet=tuple(skeleton.FEET)):
    """Horizontal displacement of each foot (mean of its two joints) per frame pair: [n_feet, T-1, 2] (m)."""
    pairs = np.asarray(feet).reshape(-1, 2)
    return np.stack([np.diff(joints[:, pair][..., [0, 2]], axis=0).mean(axis=1) for pair in pairs])


def foot_skating(joints, fps, feet=tuple(skeleton.FEET), contact_height=CONTACT_HEIGHT, fallback=CONTACT_FALLBACK):
    """Mean horizontal speed (m/s) of the feet while in contact (NaN for clips under 2 frames, or whose feet are
    not finite, as a diverged model's).

    `feet` lists (ankle, toe) joint pairs flattened, as skeleton.FEET. A foot is in contact between two
    frames when its ankle and its toe are, in both frames, within `contact_height` of the lowest height
    that joint reaches in the clip; its speed is then the mean horizontal speed of the two joints. (A
    height test on the toe alone is not enough at 20 fps: a swinging toe passes 1-2 cm above the
    floor at 2 m/s.) A foot that never meets this in more than a `fallback` fraction of its frame
    pairs (jittery generated motion) is taken to be in contact in its lowest `fallback` fraction.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if len(joints) < 2:
        return float("nan")
    contact = foot_contacts(joints, feet, contact_height, fallback)
    pairs = np.asarray(feet).reshape(-1, 2)
    speed = (
        np.stack(
            [np.linalg.norm(np.diff(joints[:, pair][..., [0, 2]], axis=0), axis=-1).mean(axis=1) for pair in pairs]
        )
        * fps
    )  # [n_feet, T-1]
    return float(speed[contact].mean()) if contact.any() else float("nan")  # none: non-finite feet


def late_stepping(poses, fps, seconds=2.0):
    """Root-frame poses [T, 63] or [T, 21, 3] (metres) -> std (m) of the horizontal left-minus-right foot vector
    over the last `seconds` (see the module doc)."""
    joints = np.asarray(poses, dtype=np.float64).reshape(len(poses), skeleton.N_JOINTS, 3)[-int(seconds * fps) :]
    sep = joints[:, skeleton.INDEX["Foot_L"], ::2] - joints[:, skeleton.INDEX["Foot_R"], ::2]  # (x, z)
    return float(np.sqrt(np.var(sep, axis=0).sum()))


def bone_length_std(joints, parents=skeleton.PARENTS):
    """Std over time of every bone's length, averaged over bones (m)."""
    joints = np.asarray(joints, dtype=np.float64)
    child = np.nonzero(np.asarray(parents) >= 0)[0]
    length = np.linalg.norm(joints[:, child] - joints[:, np.asarray(parents)[child]], axis=-1)
    return float(length.std(axis=0).mean())


def jerk(joints, fps):
    """Mean norm of the third derivative of joint positions (m/s^3); NaN for clips under 4 frames."""
    joints = np.asarray(joints, dtype=np.float64)
    if len(joints) < 4:
        return float("nan")
    return float(np.linalg.norm(np.diff(joints, n=3, axis=0), axis=-1).mean() * fps**3)


def joint_jerk(joints, fps):
    """Each joint's mean jerk (m/s^3): the mean norm of the third derivative of its position over the frames of
    joints [..., T, J, 3] -> [..., J]."""
    joints = np.asarray(joints, dtype=np.float64)
    return np.linalg.norm(np.diff(joints, n=3, axis=-3), axis=-1).mean(axis=-2) * fps**3


def acceleration(joints, fps):
    """Mean norm of the second derivative of joint positions (m/s^2); NaN for clips under 3 frames."""
    joints = np.asarray(joints, dtype=np.float64)
    if len(joints) < 3:
        return float("nan")
    return float(np.linalg.norm(np.diff(joints, n=2, axis=0), axis=-1).mean() * fps**2)


def _rigid_align_error(a, b):
    """Mean distance between 2-D paths a and b [T, 2] after the best rotation + translation of b onto a; NaN
    where a path is not finite (a diverged model's clip), since SVD cannot align it."""
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return float("nan")
    ca, cb = a - a.mean(0), b - b.mean(0)
    u, _, vt = np.linalg.svd(cb.T @ ca)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, d]) @ vt  # proper rotation, no reflection
    return float(np.linalg.norm(cb @ rot - ca, axis=1).mean())


def control_path(control):
    """Root path on the floor [T, 2] (x, z) that control [T, 3] integrates to, from the origin, heading +Z."""
    from ..motion.features import to_world

    control = np.asarray(control, dtype=np.float64)
    zero = np.zeros((len(control), skeleton.POSE_DIM))
    return to_world(zero, control)[:, 0][:, [0, 2]].astype(np.float64)


def control_error(joints, control):
    """Mean floor distance (m) between the hips' path and the path of the requested control, rigidly aligned."""
    hips = np.asarray(joints, dtype=np.float64)[:, skeleton.INDEX["Hips"]][:, [0, 2]]
    return _rigid_align_error(hips, control_path(control))


def control_following(joints, control):
    """Mean floor distance (m) between the path the body implies through its feet and the requested path."""
    joints = np.asarray(joints, dtype=np.float64)
    hips = joints[:, skeleton.INDEX["Hips"]][:, [0, 2]]
    contact = foot_contacts(joints)  # [n_feet, T-1]
    slide = (foot_steps(joints) * contact[..., None]).sum(0) / np.maximum(contact.sum(0), 1)[:, None]
    step = np.diff(hips, axis=0) - slide  # the body's own travel per frame
    implied = np.concatenate([hips[:1], hips[:1] + np.cumsum(step, axis=0)])
    return _rigid_align_error(implied, control_path(control))


def clip_metrics(joints, fps, control=None):
    """All metrics of one clip (joints [T, 21, 3] in metres, Y up) as a dict; control_error NaN without control."""
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (skeleton.N_JOINTS, 3):
        raise ValueError(f"clip_metrics: joints must be [T, {skeleton.N_JOINTS}, 3], got {joints.shape}")
    no_control = float("nan")
    values = dict(
        foot_skating=foot_skating(joints, fps),
        bone_length_std=bone_length_std(joints),
        jerk=jerk(joints, fps),
        control_error=control_error(joints, control) if control is not None else no_control,
        control_following=control_following(joints, control) if control is not None and len(joints) > 1 else no_control,
        acceleration=acceleration(joints, fps),
    )
    return {name: values[name] for name in METRIC_NAMES}  # metrics.csv's column order; a missing one is a KeyError


# ---------------------------------------------------------------- any skeleton
_ANKLE = ("ankle", "foot")
_TOE = ("toe",)


def find_feet(names):
    """(ankle, toe) joint indices per side, [l_ankle, l_toe, r_ankle, r_toe], found from the joint names (a side
    as moglow_eval.core.skeleton_names.side tells it, and 'foot'/'ankle', 'toe' in the name); None when either foot is
    missing. A foot with only an ankle or only a toe joint uses that joint twice."""
    feet = []
    for want in ("left", "right"):
        found = {}
        for j, name in enumerate(names):
            low = name.lower()
            if side(name) != want or low.endswith("_end"):
                continue
            for part, keys in (("ankle", _ANKLE), ("toe", _TOE)):
                if part not in found and any(k in low for k in keys) and not (part == "ankle" and "toe" in low):
                    found[part] = j
        if not found:
            return None
        feet += [found.get("ankle", found.get("toe")), found.get("toe", found.get("ankle"))]
    return feet


def any_clip_metrics(joints, fps, names, parents, feet=None):
    """metrics.csv's metrics of a clip of any skeleton (joints [T, J, 3], metres, Y up): jerk, acceleration and
    bone-length variation always, foot skating where `feet` ([l_ankle, l_toe, r_ankle, r_toe], indices into `names`)
    are known, the control metrics NaN (a study of your own motion has no control signal).

    Jerk, acceleration and bone-length variation are taken on the body without its root markers
    (moglow_eval.core.skeleton_names.body_skeleton): a marker left at the scene's origin while the body walks is
    no joint of the body, and its "bone" to the hips would stretch by metres."""
    joints = np.asarray(joints, dtype=np.float64)
    keep, _, body_parents = body_skeleton(names, parents)
    body = joints[:, keep]
    values = dict(
        foot_skating=foot_skating(joints, fps, feet=tuple(feet)) if feet is not None and len(joints) > 1 else np.nan,
        bone_length_std=bone_length_std(body, body_parents),
        jerk=jerk(body, fps),
        control_error=np.nan,
        control_following=np.nan,
        acceleration=acceleration(body, fps),
    )
    return {name: float(values[name]) for name in METRIC_NAMES}


def style_retention(samples, own, takes, categories, start=0, reference=None):
    """How much of its history's style a generated window keeps, over many held-out windows.

    samples, own: root-frame poses [B, T, 63] of the generated windows and of the real windows they continue
    (NAT, the same control and history); takes, categories: each window's take name and locomotion category [B].
    A window's style is its mean pose (posture: a hanging head, raised shoulders, a stoop) from frame `start` on.
    Each generated window is compared with its own NAT and with the average NAT window of its category, taken over
    the other takes (its own take left out) of `reference` (real windows [R, T', 63], their takes and categories;
    default: `own`, `takes` and `categories`). Returns (share, ratio): the share of windows whose style is closer
    to its own NAT's than to the category's average (0.5 or below: the style is lost to an average walker; real
    motion of another window of the same take scores near 1), and the median over windows of the distance to its
    own NAT over the distance to the category's average (below 1: closer to its own)."""
    s, o = (np.asarray(a, dtype=np.float64)[:, start:].mean(axis=1) for a in (samples, own))
    takes, categories = np.asarray(takes), np.asarray(categories)
    if reference is None:
        ref, ref_takes, ref_categories = o, takes, categories
    else:
        ref = np.asarray(reference[0], dtype=np.float64)[:, start:].mean(axis=1)
        ref_takes, ref_categories = np.asarray(reference[1]), np.asarray(reference[2])
    closer, ratios = [], []
    for i in range(len(s)):
        others = (ref_categories == categories[i]) & (ref_takes != takes[i])
        if not others.any():
            continue
        d_own = np.linalg.norm(s[i] - o[i])
        d_avg = np.linalg.norm(s[i] - ref[others].mean(axis=0))
        closer.append(d_own < d_avg)
        ratios.append(d_own / max(d_avg, 1e-12))
    return float(np.mean(closer)), float(np.median(ratios))
