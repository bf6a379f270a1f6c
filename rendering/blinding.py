"""Stimulus files that tell a rater nothing outside their pixels.

A hostile rater sees each video's byte size (Content-Length, download progress), whatever a parser reads from
its bytes (box sizes, the frame-size table every MP4 carries, the size of each NAL unit), and whatever time
stamps the server sends. All of these follow the condition unless we intervene: jittery motion compresses
worse, and a pipeline that renders condition by condition stamps the files in condition order.

Padding after the fact does not help: a parser skips any padding it can recognise (a trailing `free` box
states its own length, so file size minus box length is the encoded size again). So the sizes are equal by
construction: the encoder's default rate control (`rendering.encode`) makes every frame of every video the
same size, filler data included, and `check_one_size` checks that a set came out that way. Of the bytes a
parser sees, only the split of each frame between coded picture and filler follows the content: the rate
control sets the clip's total, and a random share of the rate per frame buries most of the frame-to-frame
swing that jitter adds (bench/bench_blind_sizes.py measures what is left).
Every file also gets the same modification time.
"""

import os

import numpy as np

from .errors import RenderError
from .mp4_layout import content_signal, read_layout, size_signals


def _shape(path):
    """What must agree across a set: every size a parser reads but the coded ones (file, boxes, frames)."""
    layout = read_layout(path)
    signals = {name: v for name, v in size_signals(layout).items() if not content_signal(name)}
    signals["frame sizes"] = layout.sample_sizes
    return signals


def check_one_size(videos):
    """Check that the MP4s in `videos` agree on byte size, boxes and frame sizes; returns the byte size.

    Raises RenderError naming a video and a size that differ: such a set was not encoded with the default rate
    control (a constant quantiser or rate factor lets the sizes follow the content), and nothing added
    afterwards could hide it.
    """
    videos = list(videos)
    if not videos:
        return 0
    first = _shape(videos[0])
    for path in videos[1:]:
        shape = _shape(path)
        if shape != first:
            name = next(k for k in {**first, **shape} if first.get(k) != shape.get(k))
            value = "" if name == "frame sizes" else f" ({shape.get(name, 'none')} against {first.get(name, 'none')})"
            raise RenderError(
                f"{path}: its {name}{value} differs from {videos[0]}'s; every video of a "
                "stimulus set must be encoded with the default rate control (rendering.encode), which makes them "
                "one size"
            )
    return first["file size"]


def odd_ones(videos):
    """The indices of the videos in `videos` whose sizes (file, boxes, frames) differ from the most common: the
    ones to encode again when the encoder overshot a frame's size by a byte or two (it can, on a frame dense with
    edges at a small size), which changes the sample-size table and so every box above it."""
    shapes = [repr(sorted(_shape(p).items())) for p in videos]
    common = max(set(shapes), key=shapes.count)
    return [k for k, shape in enumerate(shapes) if shape != common]


def same_mtime(paths, mtime):
    """Give every file in `paths` the access and modification time `mtime` (seconds since the epoch)."""
    for path in paths:
        os.utime(path, (mtime, mtime))


# How far from chance a size signal may tell catch clips from test clips (an AUC, CONTRACTS §4): what the
# built-in study holds, and what a study of your own is checked against (`coded_tells`).
SIZE_AUC_BAND = (0.25, 0.75)


def auc(a, b):
    """P(a value of `a` > one of `b`), ties counted half (the Mann-Whitney U over n_a n_b)."""
    from scipy.stats import rankdata

    ranks = rankdata(np.concatenate([np.asarray(a, float), np.asarray(b, float)]))
    return float((ranks[: len(a)].sum() - len(a) * (len(a) + 1) / 2) / (len(a) * len(b)))


def coded_tells(catch_videos, test_videos):
    """The coded-size signal (the only sizes that follow the content) that best tells catch videos from test
    videos: (signal name, AUC), the AUC furthest from 0.5; (None, 0.5) with no catch or test videos."""
    if not catch_videos or not test_videos:
        return None, 0.5
    signals = [{k: v for k, v in size_signals(read_layout(p)).items() if content_signal(k)} for p in catch_videos]
    tests = [{k: v for k, v in size_signals(read_layout(p)).items() if content_signal(k)} for p in test_videos]
    worst = (None, 0.5)
    for name in signals[0]:
        value = auc([s.get(name, -1) for s in signals], [t.get(name, -1) for t in tests])
        if abs(value - 0.5) > abs(worst[1] - 0.5):
            worst = (name, value)
    return worst
