"""What a parser sees of an MP4 without decoding a pixel: its boxes, its sample-size table, each sample's NAL units.

A hostile rater can read all of it from the bytes the server sends: the size of every ISO-BMFF box, the size of
every video frame (the `stsz` table every MP4 carries), and the size and type of every H.264 NAL unit inside a
frame. `rendering.blinding` checks that a stimulus set's videos agree on all of it but the sizes of the coded
slices; bench/bench_blind_sizes.py measures how much those sizes tell.
"""

import struct
from dataclasses import dataclass
from pathlib import Path

from .errors import RenderError

# Boxes holding only boxes, and the boxes holding a fixed header before their child boxes (ISO/IEC 14496-12:
# stsd has 8 bytes of version, flags and entry count; a visual sample entry such as avc1 has 78 bytes of fields).
_CONTAINERS = {b"moov", b"trak", b"mdia", b"minf", b"stbl", b"edts", b"dinf", b"udta", b"mvex", b"moof", b"traf"}
_SKIP_BEFORE_CHILDREN = {b"stsd": 8, b"avc1": 78, b"avc3": 78}
FILLER = 12  # H.264 nal_unit_type of filler data (ITU-T H.264 Table 7-1)


@dataclass(frozen=True)
class Box:
    path: str  # e.g. "/moov/trak/mdia/minf/stbl/stsz"
    offset: int
    header: int  # 8, or 16 for a 64-bit size
    size: int  # header included


@dataclass(frozen=True)
class Layout:
    file_size: int
    boxes: list  # [Box], in file order, children after their parent
    sample_sizes: list  # bytes of each video sample (frame), from stsz
    nal_units: list  # per sample, [(nal_unit_type, bytes without the length prefix)]

    def box(self, path):
        found = [b for b in self.boxes if b.path == path]
        if len(found) != 1:
            raise RenderError(f"MP4: expected one {path} box, found {len(found)}")
        return found[0]


def _boxes(data, start, end, parent=""):
    off = start
    while off + 8 <= end:
        size, kind = struct.unpack_from(">I4s", data, off)
        header = 8
        if size == 1:
            (size,) = struct.unpack_from(">Q", data, off + 8)
            header = 16
        elif size == 0:
            size = end - off
        if size < header or off + size > end:
            raise RenderError(f"MP4: box {kind!r} at byte {off} runs past its parent")
        path = f"{parent}/{kind.decode('latin-1')}"
        yield Box(path, off, header, size)
        if kind in _CONTAINERS or kind in _SKIP_BEFORE_CHILDREN:
            yield from _boxes(data, off + header + _SKIP_BEFORE_CHILDREN.get(kind, 0), off + size, path)
        off += size


def _full_box(data, layout, name):
    """The payload of the one stbl/NAME full box, after its version and flags."""
    b = layout.box(f"/moov/trak/mdia/minf/stbl/{name}")
    return b.offset + b.header + 4


def _sample_sizes(data, layout):
    at = _full_box(data, layout, "stsz")
    common, count = struct.unpack_from(">II", data, at)
    return [common] * count if common else list(struct.unpack_from(f">{count}I", data, at + 8))


def _chunk_offsets(data, layout):
    paths = {b.path for b in layout.boxes}
    wide = "/moov/trak/mdia/minf/stbl/co64" in paths
    at = _full_box(data, layout, "co64" if wide else "stco")
    (count,) = struct.unpack_from(">I", data, at)
    return list(struct.unpack_from(f">{count}{'Q' if wide else 'I'}", data, at + 4))


def _samples_per_chunk(data, layout, chunks):
    at = _full_box(data, layout, "stsc")
    (count,) = struct.unpack_from(">I", data, at)
    runs = [struct.unpack_from(">III", data, at + 4 + 12 * i) for i in range(count)]  # first chunk (1-based), n, desc
    per = []
    for chunk in range(1, chunks + 1):
        per.append(max((r for r in runs if r[0] <= chunk), key=lambda r: r[0])[1])
    return per


def _length_size(data, layout):
    b = layout.box("/moov/trak/mdia/minf/stbl/stsd/avc1/avcC")
    return (data[b.offset + b.header + 4] & 3) + 1  # lengthSizeMinusOne


def _nal_units(data, start, size, length_size):
    units, at, end = [], start, start + size
    while at < end:
        n = int.from_bytes(data[at : at + length_size], "big")
        if at + length_size + n > end or n == 0:
            raise RenderError(f"MP4: a NAL unit at byte {at} runs past its sample")
        units.append((data[at + length_size] & 0x1F, n))
        at += length_size + n
    return units


def _video_track(boxes):
    """The boxes of the file with, of its tracks, only the H.264 video track's (a stimulus with sound also has an
    AAC track, whose sample tables sit at the same paths)."""
    traks = [b for b in boxes if b.path == "/moov/trak"]

    def inside(b, t):
        return t.offset <= b.offset < t.offset + t.size

    video = [t for t in traks if any(b.path.endswith("/stsd/avc1") and inside(b, t) for b in boxes)]
    if len(video) != 1:
        raise RenderError(f"MP4: expected one H.264 video track, found {len(video)}")
    return [b for b in boxes if not b.path.startswith("/moov/trak") or inside(b, video[0])]


def read_layout(path):
    """The Layout of an H.264 MP4 (as `rendering.encode` writes, with or without an audio track): every box of the
    file, and the video track's frame sizes and NAL units."""
    data = Path(path).read_bytes()
    boxes = list(_boxes(data, 0, len(data)))
    layout = Layout(len(data), _video_track(boxes), [], [])
    sizes = _sample_sizes(data, layout)
    chunks = _chunk_offsets(data, layout)
    length_size = _length_size(data, layout)
    nals, k = [], 0
    for offset, n in zip(chunks, _samples_per_chunk(data, layout, len(chunks))):
        for size in sizes[k : k + n]:
            nals.append(_nal_units(data, offset, size, length_size))
            offset += size
        k += n
    if k != len(sizes):
        raise RenderError(f"{path}: the chunk table holds {k} samples, stsz {len(sizes)}")
    return Layout(len(data), boxes, sizes, nals)


def non_filler_sizes(layout):
    """Per sample, the bytes of its NAL units other than filler (what the encoder actually coded)."""
    return [sum(n for kind, n in units if kind != FILLER) for units in layout.nal_units]


def _per_frame(name, sizes):
    """Numbers a parser can draw from one size per frame."""
    sizes = [int(s) for s in sizes]
    ordered = sorted(sizes)
    mean = sum(sizes) / len(sizes)
    return {
        f"{name} total": sum(sizes),
        f"{name} sd": (sum((s - mean) ** 2 for s in sizes) / len(sizes)) ** 0.5,
        f"{name} min": ordered[0],
        f"{name} median": ordered[len(ordered) // 2],
        f"{name} max": ordered[-1],
        f"{name} first": sizes[0],
        f"{name} last": sizes[-1],
        f"{name} change": sum(abs(a - b) for a, b in zip(sizes, sizes[1:])) / max(len(sizes) - 1, 1),
    }


def size_signals(layout):
    """Every size a parser reads from the file without decoding, as named numbers.

    `file size`; `box PATH` (the n-th box of a path: `box PATH #n`); `frame ...`: numbers from the frame-size
    table (total, sd, min, median, max, first, last, mean change between neighbours); `NAL units` (non-filler
    units), `filler units`, `NAL type T bytes`; and `coded ...`: the same numbers as for frames, from each
    frame's NAL units other than filler. Every signal but the coded ones and those of filler, which the coded ones
    determine, is equal for every video of a blinded set (rendering.blinding).
    """
    signals = {"file size": layout.file_size}
    seen = {}
    for b in layout.boxes:
        seen[b.path] = seen.get(b.path, 0) + 1
        signals[f"box {b.path}" + (f" #{seen[b.path]}" if seen[b.path] > 1 else "")] = b.size
    signals.update(_per_frame("frame", layout.sample_sizes))
    units = [u for frame in layout.nal_units for u in frame]
    signals["NAL units"] = sum(kind != FILLER for kind, _ in units)
    signals["filler units"] = sum(kind == FILLER for kind, _ in units)
    for kind in sorted({kind for kind, _ in units} - {FILLER}):
        signals[f"NAL type {kind} bytes"] = sum(n for k, n in units if k == kind)
    signals.update(_per_frame("coded", non_filler_sizes(layout)))
    return signals


def content_signal(name):
    """Whether a signal of `size_signals` may follow the content in a blinded set (the coded sizes and filler)."""
    return name.startswith(("coded ", "NAL type ", "filler units")) or name == "NAL units"
