"""Videos of motion clips: one fixed camera, a stick figure, a solid body or a mesh (RenderOptions.style) over a
floor grid, H.264 MP4.

`render_clip` composes the three parts: the camera (`camera`: where it looks in each frame), the rasteriser
(`raster`: each frame drawn as yuv420p) and the encoder (`encode`: ffmpeg, libx264 ultrafast with a rate control
that makes every frame one size, fed ready yuv420p frames through a pipe). bench/bench_render.py compares this
with a matplotlib FuncAnimation + ffmpeg writer; at 1000x1000 a third of our time is drawing, two thirds the
pipe and x264.
"""

import argparse
import contextlib
import os
import queue
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from moglow_eval.core import cli, skeleton_names
from moglow_eval.core.blas import one_blas_thread
from moglow_eval.core.clip import check_fps, check_joints, load_clip

from .camera import DEFAULT_CAMERA, Camera, camera_targets
from .captions import CaptionLayer
from .encode import MESH_RATE_BITS_PER_ROW, ffmpeg_writer
from .errors import RenderError
from .raster import DEFAULT_STYLE, FrameDrawer, Style, one_colour

MIN_SIZE, MAX_SIZE = 32, 4096  # pixels; beyond 4096 x264's level limits and memory get in the way
MIN_ASPECT, MAX_ASPECT = 0.25, 4.0  # width / height: from a tall 1:4 to a wide 4:1 frame
MAX_WIDTH = 8192  # pixels: a wide frame's memory and x264's levels
MESH_CHUNK = 64  # frames of a mesh's vertices skinned and held at once
MESH_AHEAD = 8  # frames of drawn meshes the skinning thread keeps ready ahead of the frame being composed
SHEET_TILE = 240  # pixels: the height of a contact sheet's tiles


def size_flag(text):
    """An argparse type for a video size: an even integer in [MIN_SIZE, MAX_SIZE] (yuv420p halves both sides)."""
    size = cli.number(int, MIN_SIZE, MAX_SIZE)(text)
    if size % 2:
        raise argparse.ArgumentTypeError(f"must be even (H.264 yuv420p), got {size}")
    return size


def frame_width(size, aspect=1.0):
    """The width in pixels of a frame `size` pixels high at `aspect` (width / height): the nearest even number
    (yuv420p halves both sides), the height itself for a square frame."""
    return size if aspect == 1 else max(2, 2 * round(size * float(aspect) / 2))


def _as_clip(clip_or_path):
    if isinstance(clip_or_path, dict):
        return clip_or_path
    return load_clip(clip_or_path)


@dataclass(frozen=True)
class RenderOptions:
    """How render_clip draws and encodes a clip: plain data, one field per setting, so that a render job carries it
    to a worker process as it is. `dataclasses.replace(options, size=480)` makes a variant.

    Attributes
    ----------
    size : int
        The frame's height in pixels: even, 32-4096 (H.264 yuv420p).
    camera : Camera
        The camera (rendering.camera); it follows the root unless `target` is given.
    style : Style
        Colours and line widths, and the body drawn: stick, solid or mesh (rendering.raster).
    partner_style : Style or None
        A second person's drawing; None: `style` in one neutral colour (raster.one_colour).
    target : sequence of float or None
        A fixed look-at point [3] for every frame (a two-person video's camera stays put, so that the partner is
        the same pixels in every condition's video); None: the camera follows the body's root
        (core.skeleton_names.body_root).
    hide : sequence of str
        Joint names not drawn.
    thin : sequence of str or None
        Joint names drawn thinner (None: finger and face joints, by name); see raster.FrameDrawer.
    sheet_frames : int
        The frames on the contact sheet, when one is asked for.
    preset : str
        The x264 speed preset. ultrafast is the fastest and, for these drawings, loses nothing visible (it
        skips deblocking and CABAC).
    qp, crf : int or None
        Neither (the default): every frame one size, filler data included (`encode.frame_bits`: 1.47 Mb/s at
        640x640, a 4-s clip 0.74 MB, at any frame rate; more in a set with a mesh body, `bits_per_row`), so that a
        set's videos are one size (rendering.blinding).
        qp (a constant quantiser; 17 was the default before) or crf (x264's rate factor): sizes that follow the
        content, for a video that is not a stimulus.
    threads : int or None
        ffmpeg/x264 threads (None: ffmpeg's choice; 1 for one-core rendering in a process pool).
    rate_seed : int or None
        The seed of the default rate control's random share of the rate per frame (None: fresh randomness, so
        the bytes differ from one render to the next; the pixels hardly do).
    aspect : float
        The frame's width over its height (MIN_ASPECT-MAX_ASPECT): 1 a square frame (one person), 3 the wide
        frame two people are filmed in; the width is `frame_width(size, aspect)`.
    bits_per_row : int or None
        The default rate control's rate in bits per second per row of the frame's height (`encode.frame_bits`):
        None is encode.RATE_BITS_PER_ROW; a set that draws a mesh body in any of its styles takes
        `rate_for_set(styles)` for every video, whatever each one's style, so that they stay one size.
    key_qp : int or None
        The default rate control's quantiser for the key frame (`encode.ffmpeg_writer`): None, the rate control's
        own, but one of `encode.KEY_QP` for a video encoded again because its key frame came out a few bytes short.
    """

    size: int = 640
    camera: Camera = DEFAULT_CAMERA
    style: Style = DEFAULT_STYLE
    partner_style: Style | None = None
    target: tuple | None = None
    hide: tuple = ()
    thin: tuple | None = None
    sheet_frames: int = 8
    preset: str = "ultrafast"
    qp: int | None = None
    crf: int | None = None
    threads: int | None = None
    rate_seed: int | None = None
    aspect: float = 1.0
    bits_per_row: int | None = None
    key_qp: int | None = None


def rate_for_set(styles):
    """The `bits_per_row` of every video of a set whose clips are drawn in `styles` (rendering.raster.Style): the
    mesh body's higher rate (encode.MESH_RATE_BITS_PER_ROW) if any of them draws a mesh, else None (the default,
    encode.RATE_BITS_PER_ROW). Decided once for the set: every video of an item must be one size."""
    return MESH_RATE_BITS_PER_ROW if any(style.body == "mesh" for style in styles) else None


def render_clip(clip_or_path, out_mp4, options=None, *, sheet=None, partner=None, captions=None, mesh=None,
                partner_mesh=None):  # fmt: skip
    """Render a clip to an MP4 of a stick figure, a solid body or a mesh, with a second person and captions if asked.

    Parameters
    ----------
    clip_or_path : str or Path or dict
        A clip .npz, or a clip dict as `moglow_eval.core.clip.load_clip` returns it.
    out_mp4 : str or Path
        The video to write.
    options : RenderOptions or None
        How it is drawn and encoded (size, camera, style, rate control, ...); None: RenderOptions().
    sheet : str or Path or None
        A PNG to write a contact sheet of `options.sheet_frames` evenly spaced frames to; None: no sheet.
    partner : str or Path or dict or None
        A second person (a clip .npz or dict of as many frames, any skeleton) drawn in the same frame: the real
        interlocutor of a two-person video. The farther of the two is drawn first in every frame.
    captions : sequence of captions.Phrase or None
        Phrases burned in at the bottom while they are on (rendering.captions).
    mesh, partner_mesh : object or None
        With `options.style.body == "mesh"`: the person's (and the partner's) skinned mesh, with `faces` [F, 3],
        `mask` [V] (the face mask's vertices) and `vertices(a, b)` -> frames a..b's vertices [b - a, V, 3] in the
        joints' world (generation.data.skinning.MeshSource), read a chunk at a time so that memory does not grow
        with the clip.

    Returns
    -------
    int
        The number of frames written.

    Raises
    ------
    RenderError
        One line naming the file: a bad size, a sheet not named .png, joints that are not [T >= 1, J, 3], or
        ffmpeg failing.
    ClipError
        An unreadable clip file, or implausible joints or frame rate.

    Examples
    --------
    >>> from rendering.render import RenderOptions
    >>> RenderOptions(size=480).preset
    'ultrafast'
    """
    _check_sheet_name(sheet)  # before the video, not after it
    o = RenderOptions() if options is None else options
    size = o.size
    clip = _as_clip(clip_or_path)
    name = str(clip_or_path) if not isinstance(clip_or_path, dict) else str(out_mp4)
    if size % 2 or not MIN_SIZE <= size <= MAX_SIZE:
        raise RenderError(f"{out_mp4}: size must be even and {MIN_SIZE}-{MAX_SIZE} (H.264 yuv420p), got {size}")
    if not MIN_ASPECT <= o.aspect <= MAX_ASPECT:
        raise RenderError(f"{out_mp4}: aspect (width / height) must be {MIN_ASPECT:g}-{MAX_ASPECT:g}, got {o.aspect}")
    frame = (frame_width(size, o.aspect), size)
    if frame[0] > MAX_WIDTH:
        raise RenderError(f"{out_mp4}: {frame[0]}x{size} pixels; at most {MAX_WIDTH} wide")
    joints = np.asarray(clip["joints"], dtype=np.float64)
    if joints.ndim != 3 or joints.shape[2] != 3 or len(joints) < 1:
        raise RenderError(f"{name}: joints must be [T >= 1, J, 3], got {joints.shape}")
    check_joints(joints, name)
    fps = check_fps(clip["fps"], name)
    people, meshes = _people(clip, joints, name, o, frame, partner, mesh, partner_mesh)
    drawer = people[0][0]
    if o.target is None:
        targets = camera_targets(joints, fps, o.camera, skeleton_names.body_root(clip["joint_names"], clip["parents"]))
    else:
        targets = np.tile(np.asarray(o.target, np.float64), (len(joints), 1))
    layer = CaptionLayer(captions, frame) if captions else None
    keep = set(np.linspace(0, len(joints) - 1, o.sheet_frames).round().astype(int)) if sheet else set()
    kept, half = [], size >= 2 * SHEET_TILE  # a tile of half the frame or less: convert at half size, a 4th the work
    proc = ffmpeg_writer(
        out_mp4,
        size,
        fps,
        o.preset,
        o.qp,
        o.crf,
        o.threads,
        frames=len(joints),
        seed=o.rate_seed,
        width=frame[0],
        bits_per_row=o.bits_per_row,
        key_qp=o.key_qp,
    )
    painted = _painted(people, [m if d.style.body == "mesh" else None for (d, _), m in zip(people, meshes)], targets)
    try:
        for t, meshes_t in enumerate(painted):
            proc.stdin.write(compose(people, t, targets[t], layer, fps, meshes_t))
            if t in keep:
                kept.append((t, drawer.rgb(half)))
        proc.stdin.close()
    except BrokenPipeError:
        pass
    finally:
        painted.close()
        for d, _ in people:
            d.close()
    err = proc.stderr.read().decode(errors="replace").strip()
    if proc.wait() != 0:
        raise RenderError(f"{out_mp4}: ffmpeg failed: {err.splitlines()[-1] if err else 'no message'}")
    if sheet:
        contact_sheet(kept, fps, sheet)
    return len(joints)


def _check_sheet_name(sheet):
    """RenderError unless the contact sheet `sheet` (or None: no sheet) is named as the PNG it will be."""
    if sheet is not None and os.path.splitext(sheet)[1].lower() != ".png":
        raise RenderError(f"{sheet}: a contact sheet is a PNG file; give a name ending in .png")


def _people(clip, joints, name, o, frame, partner, mesh, partner_mesh):
    """([(drawer, joints [T, J, 3])], [each one's mesh or None]): the clip's person, and the partner (a clip, or
    None) drawing into the same frame `frame` (width, height), as RenderOptions `o` says."""
    for m in (mesh, partner_mesh):
        if m is not None and getattr(m, "n_frames", len(joints)) != len(joints):
            raise RenderError(f"{name}: a mesh of {m.n_frames} frames for {len(joints)} frames of joints")
    meshes = [mesh] if mesh is not None else None
    names = list(clip["joint_names"])
    drawer = FrameDrawer(clip["parents"], names, frame, o.camera, o.style, o.hide, o.thin, meshes=meshes)
    people, meshes = [(drawer, joints)], [mesh]
    if partner is not None:
        second = o.partner_style or one_colour(o.style)
        people.append(_partner(partner, len(joints), frame, o.camera, second, drawer, name, partner_mesh))
        meshes.append(partner_mesh)
    return people, meshes


def _partner(partner, frames, size, camera, style, drawer, name, mesh=None):
    """(drawer, joints) of the second person, drawing into `drawer`'s frame; RenderError naming the clip when its
    joints are not [frames, J, 3]."""
    other = _as_clip(partner)
    joints = np.asarray(other["joints"], dtype=np.float64)
    if joints.ndim != 3 or joints.shape[2] != 3 or len(joints) != frames:
        raise RenderError(f"{name}: the partner's joints must be [{frames}, J, 3] as the clip's, got {joints.shape}")
    check_joints(joints, name)
    meshes = [mesh] if mesh is not None else None
    second = FrameDrawer(
        other["parents"], list(other["joint_names"]), size, camera, style, frame=drawer.frame, meshes=meshes
    )
    return second, joints


def compose(people, t, target, layer=None, fps=1.0, vertices=None):
    """Frame t as yuv420p: the floor, then each person [(drawer, joints [T, J, 3])] from the farthest to the
    nearest (with the mesh style, `vertices`: each person's [V, 3] at t, or their rendering.mesh.Painted, or None),
    then the captions on at t / fps."""
    people[0][0].background(target)
    vertices = vertices or [None] * len(people)
    order = sorted(range(len(people)), key=lambda k: -people[k][0].depth(people[k][1][t], target))
    for k in order:
        drawer, joints = people[k]
        drawer.add_figure(joints[t], target, None if vertices[k] is None else [vertices[k]])
    frame = people[0][0].frame
    return layer.apply(frame, t / fps) if layer is not None else frame


def _painted(people, meshes, targets):
    """Each frame's [each person's mesh drawn (rendering.mesh.Painted), or None where the person is no mesh].

    Each person's mesh has a thread of its own (_mesh_thread): it skins a chunk of frames at a time (MESH_CHUNK; a
    short first one, so that the first frame is not kept waiting), sums their normals, and draws each frame's mesh
    with its own painter (an OpenGL context is a thread's), MESH_AHEAD frames ahead of the frame being composed. The
    skinning's products, the sparse sums and the readback, where llvmpipe rasterises (rendering.mesh.egl_read_pixels),
    let go of the GIL, so two people's meshes are drawn side by side while the floor, the blending and x264 take what
    the cores have left: with one thread for both, that thread alone set a two-person clip's pace. What it holds is
    bounded by the chunk, whatever the clip's length; an error there is raised here."""
    n = len(targets)
    drawn = [k for k, m in enumerate(meshes) if m is not None]
    if not drawn:
        yield from ([None] * len(meshes) for _ in range(n))
        return
    ready = {k: queue.Queue(maxsize=MESH_AHEAD) for k in drawn}
    stop = threading.Event()
    with _one_blas_thread():
        with _SUBMITTING:  # a clip's people in a row on every mesh thread: two clips at once never wait on each other
            jobs = [_mesh_thread(i).submit(_paint, people[k][0], targets, ready[k], stop) for i, k in enumerate(drawn)]
        try:
            for _ in range(n):
                frame = [None] * len(meshes)
                for k in drawn:
                    frame[k] = ready[k].get()
                    if isinstance(frame[k], BaseException):
                        raise frame[k]
                yield frame
        finally:
            stop.set()
            while not all(job.done() for job in jobs):  # take what they still put, so that they see the stop
                for q in ready.values():
                    try:
                        q.get(timeout=0.05 / len(ready))
                    except queue.Empty:
                        pass


_MESH_THREADS = {}  # {process id: its mesh threads}, empty until a process first draws a mesh
_SUBMITTING = threading.Lock()
_BLAS = {"clips": 0, "limits": None, "lock": threading.Lock()}  # the clips drawing meshes in this process now


@contextlib.contextmanager
def _one_blas_thread():
    """numpy's BLAS held to one thread while any clip of this process draws a mesh (the limit is the process's: the
    first clip sets it, the last restores it). In two BLAS threads the skinning's matrix products spun on the cores
    that the other mesh thread, the composing thread and x264 needed, and took longer than in one."""
    with _BLAS["lock"]:
        if _BLAS["clips"] == 0:
            _BLAS["limits"] = one_blas_thread()
        _BLAS["clips"] += 1
    try:
        yield
    finally:
        with _BLAS["lock"]:
            _BLAS["clips"] -= 1
            if _BLAS["clips"] == 0:
                _BLAS["limits"].restore_original_limits()


def _mesh_thread(k=0):
    """The k-th thread that skins and draws meshes (one per person of a clip), for every clip this process renders:
    its OpenGL context (rendering.mesh.gl_context, a thread's) is made once, not once a clip. Made on first use, so
    that importing rendering starts nothing; keyed by the process, so that a forked child, which inherits the
    parent's entry but not its threads, makes its own (no fork hook needed)."""
    pid = os.getpid()
    if pid not in _MESH_THREADS:
        _MESH_THREADS.clear()
        _MESH_THREADS[pid] = []
    threads = _MESH_THREADS[pid]
    while len(threads) <= k:
        threads.append(ThreadPoolExecutor(1, thread_name_prefix=f"mesh{len(threads)}"))
    return threads[k]


def _paint(drawer, targets, ready, stop):
    """_painted's thread for one person (`drawer`'s): skins, sums the normals and draws, putting each frame's Painted
    (or the error) on `ready` until the clip ends or `stop` is set."""
    painter = None
    try:
        painter = drawer.mesh_painter()
        a, size, n = 0, MESH_AHEAD, len(targets)
        while a < n and not stop.is_set():
            b = min(n, a + size)
            vertices, normals = painter.vertices_and_normals(a, b)
            for t in range(a, b):
                if stop.is_set():
                    return
                ready.put(painter(vertices[t - a], normals[t - a], targets[t] + drawer.proj.offset))
            a, size = b, MESH_CHUNK
    except BaseException as e:  # noqa: BLE001 -- raised again in the composing thread, which reports it
        ready.put(e)
    finally:
        if painter is not None:
            painter.release()


def contact_sheet(frames, fps, out_png, columns=4, thumb=SHEET_TILE):
    """Tile frames into one PNG, each frame's time written under it; a frame lower than `thumb` is not enlarged.

    Parameters
    ----------
    frames : sequence of (int, ndarray)
        (frame index, RGB [H, W, 3] uint8) pairs, in the order they are tiled.
    fps : float
        The clip's frame rate, for the times.
    out_png : str or Path
        The PNG to write.
    columns : int
        Frames per row.
    thumb : int
        The height of each tile in pixels (its width keeps the frames' aspect), at most the frames' own.

    Returns
    -------
    None
        The sheet is written to `out_png`.
    """
    from PIL import Image, ImageDraw

    rows = -(-len(frames) // columns)
    label = 18
    thumb = min(thumb, frames[0][1].shape[0]) if frames else thumb  # enlarging a small video adds bytes, not detail
    wide = round(thumb * frames[0][1].shape[1] / frames[0][1].shape[0]) if frames else thumb
    sheet = Image.new("RGB", (columns * wide, rows * (thumb + label)), "white")
    draw = ImageDraw.Draw(sheet)
    for k, (t, rgb) in enumerate(frames):
        im = Image.fromarray(rgb)
        im = im if im.size == (wide, thumb) else im.resize((wide, thumb), Image.LANCZOS)
        x, y = (k % columns) * wide, (k // columns) * (thumb + label)
        sheet.paste(im, (x, y))
        draw.text((x + 4, y + thumb + 3), f"{t / fps:.2f} s", fill=(60, 60, 60))
    sheet.save(out_png, compress_level=1)  # fast; the sheets are for reports, not archives
