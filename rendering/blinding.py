"""Stimulus files that tell a rater nothing outside their pixels.

A hostile rater sees each video's byte size (Content-Length, download progress) and whatever time
stamps the server sends. Both follow the condition unless we intervene: jittery motion compresses
worse, and a pipeline that renders condition by condition stamps the files in condition order. So
every video of a stimulus set is padded to the same size with a trailing ISO-BMFF `free` box (which
every player skips; the `moov` box stays at the front, so +faststart streaming is unchanged), and
every file gets the same modification time.
"""

import os
from pathlib import Path

_FREE_HEADER = 8  # 32-bit box size + b"free"


def pad_to_common_size(videos):
    """Pad every MP4 in `videos` to one common size; returns that size."""
    sizes = [Path(v).stat().st_size for v in videos]
    if not sizes:
        return 0
    target = max(sizes) + _FREE_HEADER  # every file gets a box, so even the largest is padded the same way
    for path, size in zip(videos, sizes):
        pad = target - size
        with open(path, "ab") as f:
            f.write(pad.to_bytes(4, "big") + b"free" + bytes(pad - _FREE_HEADER))
    return target


def same_mtime(paths, mtime):
    """Give every file in `paths` the access and modification time `mtime` (seconds since the epoch)."""
    for path in paths:
        os.utime(path, (mtime, mtime))
