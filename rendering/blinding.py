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

from moglow_eval.core.ranks import auc_of_rank_sums, average_ranks

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
# A study of your own is warned only where relabelling its videos at random rarely (under CHANCE_P of
# CHANCE_SHUFFLES draws) puts a signal as far out: else a small catch pool is warned about by chance.
CHANCE_P = 0.05
CHANCE_SHUFFLES = 2000


def coded_sizes(videos):
    """Each video's coded-size signals (the only sizes that follow the content): [{signal name: value}]."""
    return [{k: v for k, v in size_signals(read_layout(p)).items() if content_signal(k)} for p in videos]


def _ranks(catch, test):
    """(signal names, ranks [n_catch + n_test, n_signals] of every video's value among all, ties averaged)."""
    names = list(catch[0])
    values = np.array([[s.get(name, -1) for name in names] for s in [*catch, *test]], dtype=float)
    return names, average_ranks(values, axis=0)


def worst_signal(catch, test):
    """The signal of coded_sizes' tables that best tells the catch videos from the test videos: (signal name,
    AUC), the AUC furthest from 0.5 (the first such signal); (None, 0.5) with no catch or test videos."""
    if not catch or not test or not catch[0]:
        return None, 0.5
    names, ranks = _ranks(catch, test)
    aucs = auc_of_rank_sums(ranks[: len(catch)].sum(0), len(catch), len(test))
    k = int(np.argmax(np.abs(aucs - 0.5)))
    return (names[k], float(aucs[k])) if aucs[k] != 0.5 else (None, 0.5)


def chance_of_worst(catch, test, shuffles=CHANCE_SHUFFLES, seed=0):
    """How often chance alone tells the videos apart as well: the share of `shuffles` random relabellings of the
    same videos (as many called catch) whose best signal's AUC is as far from 0.5 as worst_signal's, counting the
    observed labelling once (so never 0). A few catch clips put some signal outside SIZE_AUC_BAND by chance, the
    more so as there are several signals to look at."""
    if not catch or not test or not catch[0]:
        return 1.0
    _, ranks = _ranks(catch, test)
    n = len(catch) + len(test)
    observed = np.abs(auc_of_rank_sums(ranks[: len(catch)].sum(0), len(catch), len(test)) - 0.5).max()
    rng, as_far = np.random.default_rng(seed), 0
    for start in range(0, shuffles, 100):  # a hundred splits at a time: memory stays small for a challenge's set
        draws = min(100, shuffles - start)
        drawn = np.argsort(rng.random((draws, n)), axis=1)[:, : len(catch)]  # [draws, n_catch] video indices
        far = np.abs(auc_of_rank_sums(ranks[drawn].sum(1), len(catch), len(test)) - 0.5).max(1)
        as_far += int(np.count_nonzero(far >= observed - 1e-12))
    return float((1 + as_far) / (shuffles + 1))


def coded_tells(catch_videos, test_videos):
    """The coded-size signal that best tells catch videos from test videos: (signal name, AUC), the AUC furthest
    from 0.5; (None, 0.5) with no catch or test videos."""
    if not catch_videos or not test_videos:
        return None, 0.5
    return worst_signal(coded_sizes(catch_videos), coded_sizes(test_videos))
