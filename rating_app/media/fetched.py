"""Which bytes of a video the server has sent to a session, so that an answer counts as watched only when the whole
file was fetched (CONTRACTS §5, *Viewing*).

A trial's video (a clip of a pairwise or parallel trial) keeps the byte ranges its GET responses carried, merged, as
text: "0-1000,2000-4096" (half-open [start, stop) ranges). A `200` carries the whole file, a `206` its Content-Range;
a HEAD request, a `304` and a `416` carry no bytes and count for nothing. The browser's cache can only hold bytes this
session's own URL was sent, so replays from the cache need nothing more. Ranges are recorded when the response is
made: a client that hangs up mid-body still counts as having fetched what it asked for (it cost it the same).
"""

from __future__ import annotations

MAX_RANGES = 16  # distinct stored ranges per video; a client that asks for more scattered bytes gains nothing


def parse(text: str | None) -> list[tuple[int, int]]:
    out = []
    for part in (text or "").split(","):
        if part:
            a, b = part.split("-")
            out.append((int(a), int(b)))
    return out


def dump(ranges: list[tuple[int, int]]) -> str:
    return ",".join(f"{a}-{b}" for a, b in ranges)


def merge(ranges: list[tuple[int, int]], new: tuple[int, int]) -> list[tuple[int, int]]:
    """`ranges` with `new` added, sorted, overlapping and touching ranges joined; at most MAX_RANGES (a new range
    that would make one more is left out)."""
    out: list[tuple[int, int]] = []
    for a, b in sorted([*ranges, new]):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out if len(out) <= MAX_RANGES else ranges


def covers(text: str | None, size: int | None) -> bool:
    """True when the stored ranges cover bytes 0..size of the file."""
    if size is None:
        return bool(text)
    end = 0
    for a, b in parse(text):
        if a > end:
            return False
        end = max(end, b)
    return end >= size


def served(resp, method: str, size: int) -> tuple[int, int] | None:
    """The byte range a video response carries, or None when it carries none."""
    if method != "GET" or size <= 0:
        return None
    if resp.status_code == 200:
        return (0, size)
    cr = resp.content_range if resp.status_code == 206 else None
    if cr is not None and cr.units == "bytes" and cr.start is not None and cr.stop is not None:
        return (int(cr.start), int(cr.stop))
    return None


def status(video_at, text: str | None, size: int | None) -> str | None:
    """The flag of one video at answer time: None (fetched in full), `no_video` (no byte of it was sent) or
    `partial_video` (some, not all)."""
    if video_at is None:
        return "no_video"
    return None if covers(text, size) else "partial_video"
