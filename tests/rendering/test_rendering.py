"""Stick-figure rendering: real MP4 files that decode, a fixed camera that follows the figure, the CLI."""

import re
import subprocess
import sys

import imageio_ffmpeg
import numpy as np
import pytest
from helpers.paths import ROOT, TEST_DATA
from PIL import Image

from generation.motion import skeleton
from generation.motion.features import load_take
from moglow_eval.core.clip import ClipError, save_clip
from rendering import Camera, RenderError, RenderOptions, render_clip
from rendering.camera import camera_targets
from rendering.raster import FrameDrawer, yuv_to_rgb

WALK = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"


def probe(path):
    """(frames, width, height, pix_fmt, codec, has_audio, moov_before_mdat) of a video, decoded for real."""
    info = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True
    ).stderr
    video = re.search(r"Video: (\w+).*?, (\w+)\(.*?\), (\d+)x(\d+)", info)
    assert video, info
    frames = sum(1 for _ in list(imageio_ffmpeg.read_frames(str(path)))[1:])
    data = open(path, "rb").read()
    return dict(
        frames=frames,
        width=int(video.group(3)),
        height=int(video.group(4)),
        pix_fmt=video.group(2),
        codec=video.group(1),
        audio="Audio:" in info,
        faststart=data.find(b"moov") < data.find(b"mdat"),
    )


@pytest.fixture(scope="module")
def walk_clip(tmp_path_factory):
    joints = load_take(WALK, 20.0)[:40]
    path = tmp_path_factory.mktemp("render") / "walk.npz"
    save_clip(path, joints, skeleton.PARENTS, skeleton.JOINT_NAMES, 20.0)
    return path, joints


def test_render_real_clip_to_h264_mp4_and_contact_sheet(walk_clip, tmp_path):
    path, joints = walk_clip
    n = render_clip(path, tmp_path / "walk.mp4", RenderOptions(size=320, rate_seed=0), sheet=tmp_path / "walk.png")
    assert n == len(joints) == 40
    p = probe(tmp_path / "walk.mp4")
    assert p == dict(frames=40, width=320, height=320, pix_fmt="yuv420p", codec="h264", audio=False, faststart=True)
    sheet = Image.open(tmp_path / "walk.png")
    assert sheet.size[0] == 4 * 240 and sheet.size[1] > 2 * 240  # 8 frames, 4 per row


@pytest.mark.parametrize("fps", [20.0, 30.0, 29.97, 25.0, 60.0])
def test_every_frame_is_one_whole_byte_size_at_any_frame_rate(tmp_path, fps):
    """The default rate is per second: a frame's budget is about the rate over the frame rate, in whole bytes and a
    whole number of kbit/s (else the filler alternates between two sizes), and every frame after the key frames has
    it (the key frame's larger budget: tests/rendering/test_encode.py)."""
    from rendering.encode import RATE_BITS_PER_ROW, frame_bits
    from rendering.mp4_layout import read_layout

    size = 320
    bits = frame_bits(size, fps)
    assert bits % 8 == 0 and abs(bits * fps - RATE_BITS_PER_ROW * size) <= 0.05 * RATE_BITS_PER_ROW * size
    joints = load_take(WALK, fps)[:24]
    clip = tmp_path / "walk.npz"
    save_clip(clip, joints, skeleton.PARENTS, skeleton.JOINT_NAMES, fps)
    render_clip(clip, tmp_path / "walk.mp4", RenderOptions(size=size, rate_seed=0))
    sizes = set(read_layout(tmp_path / "walk.mp4").sample_sizes[2:])
    assert len(sizes) == 1 and 0 <= sizes.pop() - bits // 8 <= 16, sizes  # the budget, and a few framing bytes


def _figure_pixels(rgb):
    """Mask of pixels drawn in the figure's colours (dark trunk, blue left, red right limbs)."""
    rgb = rgb.astype(int)
    dark = rgb.max(-1) < 90
    coloured = np.abs(rgb[..., 0] - rgb[..., 2]) > 80
    return dark | coloured


def test_render_camera_follows_so_the_figure_never_leaves_the_frame(walk_clip):
    joints = load_take(WALK, 20.0)[:40].astype(np.float64)
    fast = joints.copy()
    fast[..., 2] += 8.0 * np.arange(40)[:, None] / 20.0  # pushed along at 8 m/s: 16 m in 2 s
    drawer = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 200)
    targets = camera_targets(fast, 20.0)
    for t in range(0, 40, 3):
        drawer.draw(fast[t], targets[t])
        mask = _figure_pixels(drawer.rgb())
        rows, cols = np.nonzero(mask)
        assert mask.sum() > 100
        assert rows.min() > 2 and cols.min() > 2 and rows.max() < 197 and cols.max() < 197


def test_render_same_camera_set_up_wherever_the_clip_is(walk_clip):
    joints = walk_clip[1].astype(np.float64)
    # Moving a clip by whole grid cells leaves every frame identical: the camera is placed relative to the
    # clip's root path, with the same elevation, azimuth, distance and field of view.
    moved = joints + np.array([5.0, 0.0, -3.0])
    a = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 160)
    ta, tb = camera_targets(joints, 20.0), camera_targets(moved, 20.0)
    for t in (0, 17, 39):
        fa = a.draw(joints[t], ta[t]).copy()
        fb = a.draw(moved[t], tb[t]).copy()
        assert fa.shape == (160 * 160 * 3 // 2,)  # a yuv420p frame
        fa, fb = (yuv_to_rgb(f, 160) for f in (fa, fb))
        diff = np.abs(fa.astype(int) - fb.astype(int))
        assert diff[1:-1, 1:-1].max() <= 2  # (lines clipped at the image border may differ by a pixel)
    # ...while another camera does change the picture.
    other = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 160, camera=Camera(azimuth=150.0))
    assert np.abs(other.draw(joints[0], ta[0]).astype(int) - a.draw(joints[0], ta[0]).astype(int)).max() > 100


def test_render_frames_do_not_depend_on_the_frames_before():
    """The drawer reuses its buffers (only the figure's blocks are cleared): a frame drawn after others equals
    the same frame from a fresh drawer, and nothing is left in the figure buffer."""
    joints = load_take(WALK, 20.0)[:30].astype(np.float64)
    targets = camera_targets(joints, 20.0)
    used = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 200)
    for t in range(0, 29, 4):
        used.draw(joints[t], targets[t])
    fresh = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 200)
    assert np.array_equal(used.draw(joints[29], targets[29]), fresh.draw(joints[29], targets[29]))
    assert not used.rgba.any()


def test_a_frame_from_the_look_at_point_before_is_the_frame_a_fresh_drawer_draws():
    """The floor is drawn again only where the look-at point moved (a still camera's frames start from the last
    floor): frames from the same point, from another and back, with the frame written over in between as captions
    write over it, each equal the frame a fresh drawer draws."""
    joints = load_take(WALK, 20.0)[:30].astype(np.float64)
    targets = camera_targets(joints, 20.0)
    still, moved = targets[0], targets[0] + np.array([0.37, 0.0, -0.21])
    used = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 200)
    for t, target in enumerate((still,) * 3 + (moved,) * 3 + (still,) * 3):
        frame = used.draw(joints[3 * t], target).copy()
        fresh = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 200)
        assert np.array_equal(frame, fresh.draw(joints[3 * t], target)), t
        used.frame[: 200 * 20] = 235  # a caption's band over the top rows
    assert not np.array_equal(fresh.draw(joints[0], still).copy(), fresh.draw(joints[0], moved))  # the floor moved


def test_render_colours_survive_the_yuv_path():
    """Frames are made as yuv420p directly; converted back, the background, floor and limbs have their colours."""
    joints = load_take(WALK, 20.0)[:1].astype(np.float64)
    drawer = FrameDrawer(skeleton.PARENTS, skeleton.JOINT_NAMES, 240)
    drawer.draw(joints[0], camera_targets(joints, 20.0)[0])
    rgb = drawer.rgb().astype(int)
    assert np.abs(rgb[2, 2] - 0.97 * 255).max() <= 3  # sky, top left
    assert np.abs(rgb[-2, 120] - 0.88 * 255).max() <= 8  # floor near the camera (or a grid line)
    red = (rgb[..., 0] > 150) & (rgb[..., 2] < 90)
    blue = (rgb[..., 2] > 150) & (rgb[..., 0] < 90)
    assert red.sum() > 30 and blue.sum() > 30  # right and left limbs


def test_render_rejects_bad_clips(tmp_path):
    bad = np.zeros((10, skeleton.N_JOINTS, 3), np.float32)
    bad[3, 4, 1] = np.nan
    clip = dict(joints=bad, parents=skeleton.PARENTS, joint_names=skeleton.JOINT_NAMES, fps=20.0)
    with pytest.raises(ClipError, match="NaN"):  # the clip contract is broken, whoever renders it
        render_clip(clip, tmp_path / "x.mp4")
    clip["joints"] = np.zeros((10, skeleton.N_JOINTS, 3), np.float32)
    with pytest.raises(RenderError, match="even"):
        render_clip(clip, tmp_path / "x.mp4", RenderOptions(size=101))


def test_render_cli(walk_clip, tmp_path):
    ok = subprocess.run(
        [sys.executable, "-m", "rendering", str(walk_clip[0]), str(tmp_path / "o.mp4"), "--size", "128"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert ok.returncode == 0, ok.stderr
    assert probe(tmp_path / "o.mp4")["frames"] == 40
    crf = subprocess.run(
        [
            sys.executable,
            "-m",
            "rendering",
            str(walk_clip[0]),
            str(tmp_path / "c.mp4"),
            "--size",
            "64",
            "--preset",
            "superfast",
            "--crf",
            "23",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert crf.returncode == 0, crf.stderr
    assert probe(tmp_path / "c.mp4")["frames"] == 40
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    bad = subprocess.run(
        [sys.executable, "-m", "rendering", str(tmp_path / "junk.npz"), str(tmp_path / "j.mp4")],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert bad.returncode == 2
    assert bad.stderr.startswith("error: ") and "junk.npz" in bad.stderr and bad.stderr.count("\n") == 1
