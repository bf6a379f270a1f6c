"""Stick-figure videos of motion clips: one fixed camera, bones as lines, a floor grid, H.264 MP4.

Every clip is seen through the same camera set-up (`Camera`: elevation, azimuth, distance, field of
view, look-at height) whose look-at point follows the clip's smoothed root path on the floor, so the
figure never leaves the frame and nothing on screen depends on where a clip came from.

Speed: we project the joints ourselves (one vectorised pinhole projection for the whole clip), keep the
grey background and floor grid in the luma plane (numpy), draw only the figure with a bare matplotlib Agg
renderer (no figure, axes or artists) and hand ffmpeg (libx264) ready yuv420p frames through a pipe.
bench/bench_render.py compares this with a matplotlib FuncAnimation + ffmpeg writer.
"""
import subprocess
from dataclasses import dataclass

import imageio_ffmpeg
import numpy as np
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.path import Path
from matplotlib.transforms import IdentityTransform
from scipy.ndimage import gaussian_filter1d

from generation.clip import load_clip


class RenderError(ValueError):
    """A clip that cannot be rendered, or ffmpeg failing; the message names the file."""


@dataclass(frozen=True)
class Camera:
    elevation: float = 12.0     # degrees above the horizon
    azimuth: float = 40.0       # degrees about +Y, from +Z towards +X (where the camera stands)
    distance: float = 4.5       # metres from the look-at point
    fov: float = 35.0           # vertical field of view, degrees
    height: float = 0.9         # look-at height above the floor, metres
    follow_sigma: float = 0.5   # seconds; Gaussian smoothing of the root path the camera follows
    max_lag: float = 0.5        # metres; the look-at point stays this close to the root on the floor


@dataclass(frozen=True)
class Style:
    # Background, floor, grid and shadow are grey levels (FrameDrawer keeps them in the luma plane).
    background: float = 0.97
    floor: float = 0.88
    grid: float = 0.55
    shadow: float = 0.74
    centre: tuple = (0.15, 0.15, 0.15)
    left: tuple = (0.15, 0.35, 0.75)
    right: tuple = (0.75, 0.25, 0.15)
    grid_spacing: float = 1.0   # metres between grid lines
    grid_radius: float = 8.0    # metres of floor drawn around the look-at point (fading out)
    bone_width: float = 1 / 150  # line width as a fraction of the frame height
    head_radius: float = 0.08   # metres


DEFAULT_CAMERA = Camera()
DEFAULT_STYLE = Style()
_NEAR = 0.2  # metres; floor lines are clipped to this depth in front of the camera


def camera_targets(joints, fps, camera=DEFAULT_CAMERA):
    """Look-at point per frame [T, 3]: the smoothed floor projection of the root, held within max_lag of it."""
    root = joints[:, 0, [0, 2]].astype(np.float64)
    smooth = gaussian_filter1d(root, camera.follow_sigma * fps, axis=0, mode="nearest") if len(root) > 1 else root
    lag = smooth - root
    norm = np.linalg.norm(lag, axis=1, keepdims=True)
    lag *= np.minimum(1.0, camera.max_lag / np.maximum(norm, 1e-9))
    xz = root + lag
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


def _segments_path(points):
    """[N, 2, 2] segment end points -> one Path of N separate lines."""
    n = len(points)
    codes = np.tile(np.array([Path.MOVETO, Path.LINETO], dtype=Path.code_type), n)
    return Path(points.reshape(2 * n, 2), codes)


def _clip_near(a, b):
    """Clip camera-space segments a->b [N, 3] to depth >= _NEAR; returns the kept (a, b)."""
    keep = (a[:, 2] >= _NEAR) | (b[:, 2] >= _NEAR)
    a, b = a[keep].copy(), b[keep].copy()
    for p, q in ((a, b), (b, a)):
        behind = p[:, 2] < _NEAR
        t = (_NEAR - p[behind, 2]) / (q[behind, 2] - p[behind, 2])
        p[behind] = p[behind] + t[:, None] * (q[behind] - p[behind])
    return a, b


def _clip_rect(a, b, width, height):
    """Liang-Barsky clipping of 2-D segments a->b [N, 2] to [0, width-1] x [0, height-1]."""
    d = b - a
    t0, t1 = np.zeros(len(a)), np.ones(len(a))
    for p, q in ((-d[:, 0], a[:, 0]), (d[:, 0], width - 1 - a[:, 0]),
                 (-d[:, 1], a[:, 1]), (d[:, 1], height - 1 - a[:, 1])):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = q / p
        t0 = np.where(p < 0, np.maximum(t0, r), t0)
        t1 = np.where(p > 0, np.minimum(t1, r), t1)
        t1 = np.where((p == 0) & (q < 0), -1.0, t1)  # parallel to and outside this edge
    keep = t0 < t1
    return a[keep] + t0[keep, None] * d[keep], a[keep] + t1[keep, None] * d[keep]


def _wu_lines(plane, a, b, value, alpha):
    """Draw antialiased 1-px lines a->b [N, 2] (x=column, y=row, inside the image) of `value` into a
    uint8 plane [H, W] (the luma plane: the lines and the floor under them are grey).

    Xiaolin Wu's method, vectorised over every pixel column (or row, for steep lines) of every line:
    each sample covers the two pixels straddling the line with weights 1-f and f, times alpha[row, col].
    """
    steep = np.abs(b[:, 1] - a[:, 1]) > np.abs(b[:, 0] - a[:, 0])
    a, b = a.copy(), b.copy()
    a[steep], b[steep] = a[steep, ::-1], b[steep, ::-1]    # steep lines: step along rows instead
    swap = a[:, 0] > b[:, 0]
    a[swap], b[swap] = b[swap], a[swap].copy()
    start, stop = np.ceil(a[:, 0]).astype(np.int64), np.floor(b[:, 0]).astype(np.int64)
    n = np.maximum(stop - start + 1, 0)
    if n.sum() == 0:
        return
    line = np.repeat(np.arange(len(a)), n)
    u = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + start[line]   # the stepping coordinate
    slope = (b[:, 1] - a[:, 1]) / np.maximum(b[:, 0] - a[:, 0], 1e-9)
    v = a[line, 1] + (u - a[line, 0]) * slope[line]
    v0 = np.floor(v).astype(np.int64)
    f = (v - v0).astype(np.float32)
    st = steep[line]
    height, width = plane.shape
    v1 = np.minimum(v0 + 1, np.where(st, width, height) - 1)
    flat = plane.reshape(-1)
    for vv, w in ((v0, 1 - f), (v1, f)):
        p = np.where(st, u * width + vv, vv * width + u)             # flat pixel index
        w = w * alpha.reshape(-1)[p]
        y = flat[p].astype(np.float32)
        flat[p] = (y + w * (np.float32(value) - y) + 0.5).astype(np.uint8)


# BT.601 limited range, what ffmpeg's own rgb -> yuv420p conversion uses.
_TO_Y = np.array([0.2568, 0.5041, 0.0979], np.float32)
_TO_U = np.array([-0.1482, -0.2910, 0.4392], np.float32)
_TO_V = np.array([0.4392, -0.3678, -0.0714], np.float32)


def grey_to_y(g):
    """Luma of a grey level g in [0, 1]."""
    return 16.0 + 219.0 * g


def yuv_to_rgb(frame, size):
    """A yuv420p frame (flat uint8, as FrameDrawer.draw returns) -> RGB uint8 [size, size, 3]."""
    n = size * size
    y = frame[:n].reshape(size, size).astype(np.float32) - 16
    u = frame[n:n + n // 4].reshape(size // 2, size // 2).repeat(2, 0).repeat(2, 1).astype(np.float32) - 128
    v = frame[n + n // 4:].reshape(size // 2, size // 2).repeat(2, 0).repeat(2, 1).astype(np.float32) - 128
    rgb = np.stack([1.164 * y + 1.596 * v, 1.164 * y - 0.392 * u - 0.813 * v, 1.164 * y + 2.017 * u], -1)
    return np.clip(rgb + 0.5, 0, 255).astype(np.uint8)


class FrameDrawer:
    """Draws the frames of one clip as yuv420p (what the encoder wants); reused for every frame.

    The camera only translates (its orientation and height are fixed), so which floor point each pixel
    sees, relative to the look-at point, never changes: the floor disc and the grid's distance fade are
    computed once per size. Everything but the limbs is grey, so the background and grid live in the luma
    plane alone and the chroma planes are flat except where the figure is. Per frame: copy the blank luma
    plane, draw the world-fixed grid lines into it with numpy (Wu lines), draw the shadow, bones and head
    with Agg on a transparent buffer, and blend only the figure's bounding box into the three planes.
    This saves ffmpeg the RGBA -> yuv420p conversion and the pipe 60% of the bytes.
    """

    def __init__(self, parents, joint_names, size, camera=DEFAULT_CAMERA, style=DEFAULT_STYLE):
        if size % 2:
            raise RenderError(f"size must be even for yuv420p, got {size}")
        self.size, self.camera, self.style = size, camera, style
        self.proj = Projector(camera, size, size)
        self.renderer = RendererAgg(size, size, 72)
        self.rgba = np.asarray(self.renderer.buffer_rgba())  # the figure, on transparent black
        n = size * size
        self.frame = np.empty(n * 3 // 2, np.uint8)          # the yuv420p frame written to the encoder
        self.y = self.frame[:n].reshape(size, size)
        self.uv = self.frame[n:].reshape(2, size // 2, size // 2)
        self.parents = np.asarray(parents)
        self.child = np.nonzero(self.parents >= 0)[0]
        # A bone's side is its child joint's side (arms, legs); CMU-style names (LeftArm) count too.
        side = np.array([n.endswith("_L") or n.startswith("Left") for n in joint_names])
        side_r = np.array([n.endswith("_R") or n.startswith("Right") for n in joint_names])
        self.bone_side = np.where(side[self.child], -1, np.where(side_r[self.child], 1, 0))
        names = [n.lower() for n in joint_names]
        self.head = names.index("head") if "head" in names else None
        self.width = style.bone_width * size
        self.gcs = {}
        for key, colour in [("shadow", (style.shadow,) * 3), ("centre", style.centre), ("left", style.left),
                            ("right", style.right)]:
            gc = self.renderer.new_gc()
            gc.set_foreground(colour)
            gc.set_linewidth(self.width)
            gc.set_antialiased(True)
            gc.set_capstyle("round")
            gc.set_joinstyle("round")
            self.gcs[key] = gc
        self.blank_y, self.grid_alpha = _background(self.proj, camera, style, size)

    def _grid(self, target, eye):
        s, r = self.style.grid_spacing, self.style.grid_radius
        # World-fixed lines x = k s and z = k s, each only where it crosses the disc of radius r around the
        # look-at point (the grid fades out there: see _background).
        xs = np.arange(np.ceil((target[0] - r) / s), np.floor((target[0] + r) / s) + 1) * s
        zs = np.arange(np.ceil((target[2] - r) / s), np.floor((target[2] + r) / s) + 1) * s
        hx = np.sqrt(np.maximum(r * r - (xs - target[0]) ** 2, 0))      # half-chord of each line
        hz = np.sqrt(np.maximum(r * r - (zs - target[2]) ** 2, 0))
        a = np.concatenate([np.stack([xs, 0 * xs, target[2] - hx], 1), np.stack([target[0] - hz, 0 * zs, zs], 1)])
        b = np.concatenate([np.stack([xs, 0 * xs, target[2] + hx], 1), np.stack([target[0] + hz, 0 * zs, zs], 1)])
        a, b = _clip_near(self.proj.to_camera(a, eye), self.proj.to_camera(b, eye))
        a, b = (self._rows(self.proj.to_screen(p)) for p in (a, b))
        a, b = _clip_rect(a, b, self.size, self.size)
        _wu_lines(self.y, a, b, grey_to_y(self.style.grid), self.grid_alpha)

    def _rows(self, xy):
        """Agg display coordinates (y up) -> image (column, row)."""
        return xy * np.array([1.0, -1.0]) + np.array([0.0, self.size])

    def _figure(self, joints, eye):
        """Draw shadow, bones and head with Agg; returns the screen points drawn and the head radius."""
        r, t = self.renderer, IdentityTransform()
        r.clear()
        cam = self.proj.to_camera(joints, eye)
        scam = self.proj.to_camera(joints * np.array([1.0, 0.0, 1.0]), eye)
        points, radius = [], 0.0
        if (scam[:, 2] > _NEAR).all():
            seg = self.proj.to_screen(np.stack([scam[self.child], scam[self.parents[self.child]]], 1))
            r.draw_path(self.gcs["shadow"], _segments_path(seg), t)
            points.append(seg.reshape(-1, 2))
        if (cam[:, 2] > _NEAR).all():
            seg = self.proj.to_screen(np.stack([cam[self.child], cam[self.parents[self.child]]], 1))
            points.append(seg.reshape(-1, 2))
            depth = cam[self.child, 2] + cam[self.parents[self.child], 2]
            # Painter's order: the farther limb side first, then the trunk, then the nearer side.
            sides = [(-1, "left"), (1, "right")]
            d = {s: depth[self.bone_side == s].mean() if (self.bone_side == s).any() else 0 for s, _ in sides}
            far, near = sorted(sides, key=lambda sn: -d[sn[0]])
            for s, key in (far, (0, "centre"), near):
                m = self.bone_side == s
                if m.any():
                    r.draw_path(self.gcs[key], _segments_path(seg[m]), t)
            if self.head is not None and self.parents[self.head] >= 0:
                # Head: a disc of fixed size in metres, just beyond the head joint along the neck bone.
                neck = joints[self.head] - joints[self.parents[self.head]]
                centre = joints[self.head] + self.style.head_radius * neck / max(np.linalg.norm(neck), 1e-6)
                hc = self.proj.to_camera(centre, eye)
                if hc[2] > _NEAR:
                    radius = self.proj.focal * self.style.head_radius / hc[2]
                    centre = self.proj.to_screen(hc)
                    r.draw_path(self.gcs["centre"], Path.circle(centre, radius), t, rgbFace=self.style.centre)
                    points.append(centre[None])
        return (np.concatenate(points) if points else np.zeros((0, 2))), radius

    def draw(self, joints, target):
        """Render one frame (joints [J, 3], look-at target [3]); returns the yuv420p frame (flat uint8 view)."""
        eye = target + self.proj.offset
        np.copyto(self.y, self.blank_y)
        self.uv.fill(128)
        self._grid(target, eye)
        points, radius = self._figure(joints, eye)
        if len(points):
            # The figure's bounding box in image rows/columns, on even pixels (for the 2x2 chroma blocks).
            pad = radius + self.width + 2
            xy = self._rows(points)
            c0, r0 = (np.floor((xy.min(0) - pad) / 2) * 2).clip(0, self.size).astype(int)
            c1, r1 = (np.ceil((xy.max(0) + pad) / 2) * 2).clip(0, self.size).astype(int)
            if c1 > c0 and r1 > r0:
                self._blend(r0, r1, c0, c1)
        return self.frame

    def _blend(self, r0, r1, c0, c1):
        """Composite the Agg figure (straight alpha) over the planes inside rows r0:r1, columns c0:c1."""
        px = self.rgba[r0:r1, c0:c1].astype(np.float32)
        rgb, a = px[..., :3], px[..., 3] * np.float32(1 / 255)
        y = self.y[r0:r1, c0:c1]
        y[...] = (y + a * (rgb @ _TO_Y + 16 - y) + 0.5).astype(np.uint8)
        # Over the grey background (chroma 128) the chroma is 128 + a * (the figure's), averaged per 2x2 block.
        for k, m in enumerate((_TO_U, _TO_V)):
            c = a * (rgb @ m)
            c = c[0::2, 0::2] + c[1::2, 0::2] + c[0::2, 1::2] + c[1::2, 1::2]
            self.uv[k, r0 // 2:r1 // 2, c0 // 2:c1 // 2] = (c * np.float32(0.25) + np.float32(128.5)).astype(np.uint8)

    def rgb(self):
        """The current frame as RGB [size, size, 3] (for contact sheets and tests)."""
        return yuv_to_rgb(self.frame, self.size)


def _background(proj, camera, style, size):
    """The blank luma plane (sky, a grey floor disc fading out around the look-at point) and the grid's
    alpha map."""
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64) + 0.5
    # Camera-space ray through each pixel centre, then in world axes (rows of proj.rot are the camera axes).
    ray = np.stack([(cols - proj.centre[0]) / proj.focal, (size - rows - proj.centre[1]) / proj.focal,
                    np.ones_like(rows)], -1) @ proj.rot
    eye_y = proj.offset[1] + camera.height
    down = ray[..., 1] < -1e-9
    t = np.where(down, eye_y / np.maximum(-ray[..., 1], 1e-9), np.inf)
    hit = proj.offset[[0, 2]] + t[..., None] * ray[..., [0, 2]]     # floor point relative to the look-at point
    dist = np.where(down, np.linalg.norm(hit, axis=-1), np.inf)
    r = style.grid_radius
    floor_a = np.clip((1.2 * r - dist) / (0.6 * r), 0, 1)
    grid_a = np.clip((r - dist) / (0.5 * r), 0, 1).astype(np.float32)
    grey = (1 - floor_a) * style.background + floor_a * style.floor
    return np.round(grey_to_y(grey)).astype(np.uint8), grid_a


def _as_clip(clip_or_path):
    if isinstance(clip_or_path, dict):
        return clip_or_path
    return load_clip(clip_or_path)


def _check_joints(joints, name):
    if not np.isfinite(joints).all():
        raise RenderError(f"{name}: joints contain NaN or infinite values")
    if len(joints) < 1:
        raise RenderError(f"{name}: the clip has no frames")


def ffmpeg_writer(out_mp4, size, fps, preset="superfast", crf=20, threads=None):
    """An ffmpeg process reading raw yuv420p frames on stdin and writing H.264 yuv420p +faststart MP4, no audio."""
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "yuv420p",
           "-s", f"{size}x{size}", "-r", f"{fps:g}", "-i", "-", "-an", "-c:v", "libx264", "-preset", preset,
           "-crf", str(crf), "-pix_fmt", "yuv420p", "-movflags", "+faststart"]
    if threads is not None:
        cmd += ["-threads", str(threads), "-x264-params", f"threads={threads}:lookahead-threads=1"]
    return subprocess.Popen(cmd + [str(out_mp4)], stdin=subprocess.PIPE, stderr=subprocess.PIPE)


def render_clip(clip_or_path, out_mp4, size=640, camera=DEFAULT_CAMERA, style=DEFAULT_STYLE, sheet=None,
                sheet_frames=8, preset="superfast", crf=20, threads=None):
    """Render a clip (a path to a clip .npz, or a dict as from generation.clip.load_clip) to an MP4.

    sheet: optional PNG path for a contact sheet of `sheet_frames` evenly spaced frames.
    threads: ffmpeg/x264 threads (None = ffmpeg's choice; 1 for one-core rendering in a process pool).
    Returns the number of frames written.
    """
    clip = _as_clip(clip_or_path)
    name = str(clip_or_path) if not isinstance(clip_or_path, dict) else str(out_mp4)
    if size % 2 or size < 32:
        raise RenderError(f"{out_mp4}: size must be even and >= 32 (H.264 yuv420p), got {size}")
    joints = np.asarray(clip["joints"], dtype=np.float64)
    _check_joints(joints, name)
    fps = float(clip["fps"])
    drawer = FrameDrawer(clip["parents"], list(clip["joint_names"]), size, camera, style)
    targets = camera_targets(joints, fps, camera)
    keep = set(np.linspace(0, len(joints) - 1, sheet_frames).round().astype(int)) if sheet else set()
    kept = []
    proc = ffmpeg_writer(out_mp4, size, fps, preset, crf, threads)
    try:
        for t in range(len(joints)):
            proc.stdin.write(drawer.draw(joints[t], targets[t]))
            if t in keep:
                kept.append((t, drawer.rgb()))
        proc.stdin.close()
    except BrokenPipeError:
        pass
    err = proc.stderr.read().decode(errors="replace").strip()
    if proc.wait() != 0:
        raise RenderError(f"{out_mp4}: ffmpeg failed: {err.splitlines()[-1] if err else 'no message'}")
    if sheet:
        contact_sheet(kept, fps, sheet)
    return len(joints)


def contact_sheet(frames, fps, out_png, columns=4, thumb=240):
    """Tile (frame_index, RGB [H, W, 3]) pairs into one PNG with each frame's time written under it."""
    from PIL import Image, ImageDraw

    rows = -(-len(frames) // columns)
    label = 18
    sheet = Image.new("RGB", (columns * thumb, rows * (thumb + label)), "white")
    draw = ImageDraw.Draw(sheet)
    for k, (t, rgb) in enumerate(frames):
        im = Image.fromarray(rgb).resize((thumb, thumb), Image.LANCZOS)
        x, y = (k % columns) * thumb, (k // columns) * (thumb + label)
        sheet.paste(im, (x, y))
        draw.text((x + 4, y + thumb + 3), f"{t / fps:.2f} s", fill=(60, 60, 60))
    sheet.save(out_png, compress_level=1)  # fast; the sheets are for reports, not archives
