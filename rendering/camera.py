"""The camera every clip is seen through: one fixed set-up whose look-at point follows the clip's root.

Every clip is seen through the same camera set-up (`Camera`: elevation, azimuth, distance, field of view,
look-at height) whose look-at point follows the clip's smoothed root path on the floor, so the figure never
leaves the frame and nothing on screen depends on where a clip came from. The camera only translates, so a
`Projector` (a pinhole projection in numpy) is built once per clip.
"""

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import gaussian_filter1d


@dataclass(frozen=True)
class Camera:
    elevation: float = 12.0  # degrees above the horizon
    azimuth: float = 40.0  # degrees about +Y, from +Z towards +X (where the camera stands)
    distance: float = 4.5  # metres from the look-at point
    fov: float = 35.0  # vertical field of view, degrees
    height: float = 0.9  # look-at height above the floor, metres
    follow_sigma: float = 0.5  # seconds; Gaussian smoothing of the root path the camera follows
    max_lag: float = 0.5  # metres; the look-at point stays this close to the root on the floor


DEFAULT_CAMERA = Camera()
HEAD_ROOM = 0.1  # metres above the highest joint: the head disc the renderer draws beyond the head joint
FILL = 0.7  # of the frame height that the tallest extent of a framed body takes (framing_camera)


def framing_camera(clips, base=DEFAULT_CAMERA, fill=FILL, root=0):
    """One camera set-up that frames every clip in `clips` (joints [T, J, 3], metres, Y up) whole; `root` is the
    body's root joint (core.skeleton_names.body_root), which the camera follows.

    The built-in study's camera is set for a walker of 1.7 m; a study of your own motion may show a child, a
    giant or a dancer with arms spread. Here the look-at height is the middle of the bodies' vertical span and
    the distance makes the largest extent (height, or width around the root) `fill` of the frame height, with
    the look-at point's lag behind the root scaled alike. Every clip of an item is rendered through the same
    set-up, so no clip's framing tells it from another's."""
    top = bottom = reach = 0.0
    for joints in clips:
        joints = np.asarray(joints, dtype=np.float64)
        top = max(top, float(joints[..., 1].max()) + HEAD_ROOM)
        bottom = min(bottom, float(joints[..., 1].min()))
        around = joints[..., [0, 2]] - joints[:, root : root + 1, [0, 2]]
        reach = max(reach, float(np.linalg.norm(around, axis=-1).max()))
    span = max(top - bottom, 2 * reach, 0.1)
    distance = span / (2 * np.tan(np.radians(base.fov) / 2) * fill)
    return replace(base, distance=float(distance), height=float((top + bottom) / 2), max_lag=base.max_lag * span / 1.8)


NEAR = 0.2  # metres; floor lines are clipped to this depth in front of the camera


def frame_size(size):
    """(width, height) in pixels of a frame given as one side (square) or as (width, height)."""
    if isinstance(size, (tuple, list)):
        return int(size[0]), int(size[1])
    return int(size), int(size)


def camera_targets(joints, fps, camera=DEFAULT_CAMERA, root=0):
    """Look-at point per frame [T, 3]: the smoothed floor projection of the body's root joint `root`
    (core.skeleton_names.body_root), held within max_lag of it."""
    path = joints[:, root, [0, 2]].astype(np.float64)
    smooth = gaussian_filter1d(path, camera.follow_sigma * fps, axis=0, mode="nearest") if len(path) > 1 else path
    lag = smooth - path
    norm = np.linalg.norm(lag, axis=1, keepdims=True)
    lag *= np.minimum(1.0, camera.max_lag / np.maximum(norm, 1e-9))
    xz = path + lag
    return np.stack([xz[:, 0], np.full(len(xz), camera.height), xz[:, 1]], axis=1)


class Projector:
    """Pinhole projection for a camera at a fixed orientation, translated to each frame's target."""

    def __init__(self, camera, width, height):
        el, az = np.radians(camera.elevation), np.radians(camera.azimuth)
        self.offset = camera.distance * np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
        fwd = -self.offset / camera.distance
        right = np.cross(fwd, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        self.rot = np.stack([right, up, fwd])  # rows: camera x, y, depth
        self.focal = 0.5 * height / np.tan(np.radians(camera.fov) / 2)
        self.centre = np.array([width / 2, height / 2])

    def to_camera(self, points, eye):
        """World points [..., 3] -> camera coordinates [..., 3] (x right, y up, z depth) for eye [3]."""
        return (points - eye) @ self.rot.T

    def to_screen(self, cam):
        """Camera coordinates [..., 3] -> Agg display pixels [..., 2] (origin bottom left)."""
        return self.centre + self.focal * cam[..., :2] / np.maximum(cam[..., 2:3], 1e-6)


def clip_to_frustum(a, b, planes):
    """Liang-Barsky clipping of camera-space segments a->b [N, 3] to the half-spaces planes[:, :3] . p +
    planes[:, 3] >= 0 (the view frustum); returns the kept (a, b)."""
    da = a @ planes[:, :3].T + planes[:, 3]
    db = b @ planes[:, :3].T + planes[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = da / (da - db)  # where each segment crosses each plane
    t0 = np.where(da < 0, t, 0.0).max(1)  # entering
    t1 = np.where(db < 0, t, 1.0).min(1)  # leaving
    keep = (t0 < t1) & ~((da < 0) & (db < 0)).any(1)
    a, d, t0, t1 = a[keep], b[keep] - a[keep], t0[keep, None], t1[keep, None]
    return a + t0 * d, a + t1 * d
