"""Blinded video sizes (issue 37, item 1): nothing a parser reads from a stimulus video tells a catch clip.

A small set of real walks rendered small: "test" clips as they are, "catch" clips the same walks with the joints
shaken each frame (as the early-checkpoint BAD clips are jittery, and so compress worse).
bench/bench_blind_sizes.py measures the same on whole stimulus sets.
"""

import subprocess

import imageio_ffmpeg
import numpy as np
import pytest
from helpers.paths import BANDAI
from scipy.stats import mannwhitneyu

from generation.motion import skeleton
from generation.motion.features import load_take
from rendering import RenderError, RenderOptions, render_clip
from rendering.blinding import check_one_size
from rendering.mp4_layout import FILLER, content_signal, non_filler_sizes, read_layout, size_signals

pytestmark = pytest.mark.full  # the full tier: real takes from ../shared

TAKES = ["dataset-1_walk_angry_002", "dataset-1_walk_normal_001", "dataset-1_run_happy_001", "dataset-1_walk_old_002"]
SIZE, FRAMES = 128, 40
SEI = 6  # H.264 nal_unit_type


def auc(a, b):
    return mannwhitneyu(a, b).statistic / (len(a) * len(b))


def clips():
    """(role, clip dict) for 4 real takes, each smooth ("test") and shaken ("catch")."""
    rng = np.random.default_rng(37)
    out = []
    for name in TAKES:
        joints = load_take(BANDAI / "dataset-1" / "data" / f"{name}.bvh.gz", 20.0)[:FRAMES].astype(np.float64)
        for role, shake in (("test", 0.0), ("catch", 0.1)):
            j = joints + rng.normal(0, shake, joints.shape) if shake else joints
            out.append((role, dict(joints=j, parents=skeleton.PARENTS, joint_names=skeleton.JOINT_NAMES, fps=20.0)))
    return out


@pytest.fixture(scope="module")
def small_set(tmp_path_factory):
    """{"default": [(role, path)], "qp17": [...]}: the set with today's default encoding and with qp 17."""
    tmp = tmp_path_factory.mktemp("blind")
    sets = {"default": [], "qp17": []}
    for k, (role, clip) in enumerate(clips()):
        for label, rate in (("default", {"rate_seed": k}), ("qp17", {"qp": 17})):
            path = tmp / f"{label}_{k}.mp4"
            render_clip(clip, path, RenderOptions(size=SIZE, threads=1, **rate))
            sets[label].append((role, path))
    return sets


def size_aucs(videos):
    """{signal: AUC of catch against test} over every size signal of the videos."""
    signals = [(role, size_signals(read_layout(path))) for role, path in videos]
    names = dict.fromkeys(n for _, s in signals for n in s)
    return {
        n: auc([s.get(n, -1) for r, s in signals if r == "catch"], [s.get(n, -1) for r, s in signals if r == "test"])
        for n in names
    }


def test_the_parser_reads_the_frame_sizes_ffmpeg_reads(small_set):
    for _, path in small_set["default"][:2] + small_set["qp17"][:2]:
        crc = subprocess.run(
            [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-c", "copy", "-f", "framecrc", "-"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        sizes = [int(line.split(",")[4]) for line in crc.splitlines() if line and not line.startswith("#")]
        layout = read_layout(path)
        assert layout.sample_sizes == sizes and len(sizes) == FRAMES
        assert sum(layout.sample_sizes) + 8 == layout.box("/mdat").size
        # Each frame is its NAL units, each behind a 4-byte length.
        assert [sum(4 + n for _, n in units) for units in layout.nal_units] == sizes


def test_every_size_a_parser_reads_is_one_for_every_video_but_the_coded_ones(small_set):
    videos = [p for _, p in small_set["default"]]
    size = check_one_size(videos)
    assert size == videos[0].stat().st_size
    layouts = [read_layout(p) for p in videos]
    assert len({tuple(x.sample_sizes) for x in layouts}) == 1
    # The filler is inside the frames (x264's, not appended by us), and x264's options, which name each frame's
    # random share of the rate, are not in the file.
    assert all(sum(any(k == FILLER for k, _ in units) for units in x.nal_units) > FRAMES / 2 for x in layouts)
    assert not any(k == SEI for x in layouts for units in x.nal_units for k, _ in units)
    aucs = size_aucs(small_set["default"])
    assert {n for n, v in aucs.items() if v != 0.5} <= {n for n in aucs if content_signal(n)}
    assert not any(content_signal(n) for n in ("file size", "box /mdat", "frame total", "frame max"))


def test_the_coded_size_of_a_shaken_clip_is_not_the_larger(small_set):
    """The encoded size (what a parser gets by leaving out filler) is set by the rate, not by the jitter."""
    aucs = size_aucs(small_set["default"])
    assert 0.25 <= aucs["coded total"] <= 0.75, aucs["coded total"]
    coded = [sum(non_filler_sizes(read_layout(p))) for _, p in small_set["default"]]
    # at qp 17: 1.4; at the default rate the spread is the per-frame dither's and the aim's, whatever the jitter
    assert max(coded) / min(coded) < 1.15


def test_before_issue_37_the_sizes_told_the_catch_clips(small_set):
    """What the test above guards against: at a constant quantiser the shaken clips are the big ones, and the
    blinding check refuses such a set (padding it to one size would only hide this from `ls`)."""
    aucs = size_aucs(small_set["qp17"])
    assert aucs["file size"] == 1.0 and aucs["coded total"] == 1.0
    with pytest.raises(RenderError, match="differs"):
        check_one_size([p for _, p in small_set["qp17"]])
