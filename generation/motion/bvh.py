"""BVH motion-capture files: a reader for any hierarchy, and forward kinematics.

Reads `.bvh` and `.bvh.gz`; any number of joints, 3 or 6 (or any subset of the six) channels per joint,
any rotation order per joint, End Sites, tabs and CRLF line ends. The MOTION block is parsed in one
numpy call over the whole text (fast path); only when that finds something wrong is the block walked
line by line to name the offending line. Errors are `BvhError("FILE:LINE: message")`.

Conventions (the usual BVH ones): rotation channels are intrinsic rotations applied in the listed
order, so `Zrotation Xrotation Yrotation` gives R = Rz @ Rx @ Ry, angles in degrees; a joint's
position channels give its local translation and replace its OFFSET (CONTRACTS.md §1).
The product turns channels into rotations as quaternions (resample.local_quaternions, which resamples them);
tests/reference/bvh_fk.py does it with matrices, the plain way, as the reference.
"""

import gzip
import io
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from moglow_eval.core import user_files
from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import MAX_FPS, MIN_FPS

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
AXIS = {"X": 0, "Y": 1, "Z": 2}  # a channel name's first letter -> coordinate axis
# Beyond any real channel value (1e9 cm is 10,000 km); larger ones overflow forward kinematics.
MAX_VALUE = 1e9
# Bounds on what a file may make the reader hold, far beyond real capture: a hierarchy of 1000 joints is about
# 200 kB of text; an hour at 120 fps of 138 channels is 60 million values; no writer spends 64 bytes on a number.
MAX_HEADER_BYTES = 16 << 20
MAX_MOTION_VALUES = 60_000_000
MAX_BYTES_PER_VALUE = 64
_CHUNK = 1 << 20
PARSE_SPAN = 1 << 20  # bytes of frame text, or values, worked on at a time


class BvhError(UserError):
    """A malformed BVH file; the message reads `FILE:LINE: what is wrong`."""


@dataclass
class Bvh:
    names: list  # joint names [J] (End Sites are not joints)
    parents: np.ndarray  # int [J], -1 for the root; parents come before their children
    offsets: np.ndarray  # float [J, 3] OFFSET of each joint, file units
    channels: list  # per joint, its channel names in file order
    motion: np.ndarray  # float [T, C] the MOTION block, C = total channel count
    frame_time: float  # seconds per frame
    end_sites: list = field(default_factory=list)  # (parent joint index, offset [3]) per End Site
    path: str = ""

    @property
    def n_frames(self):
        return self.motion.shape[0]

    @property
    def fps(self):
        return 1.0 / self.frame_time

    def channel_columns(self):
        """First motion column of each joint (its channels follow consecutively)."""
        counts = [len(c) for c in self.channels]
        return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def _read_bytes(path):
    """The file's bytes (inflated where it is gzip), read no further than its header says the motion can take."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            gz = f.read(2) == b"\x1f\x8b"
        f = gzip.open(path, "rb") if gz else open(path, "rb")
    except OSError as e:
        raise BvhError(f"{path}:0: cannot read file ({e.strerror or e})") from None
    try:
        with f:
            return _read_bounded(f, str(path))
    except (OSError, EOFError, zlib.error) as e:
        if not gz:
            raise BvhError(f"{path}:0: cannot read file ({e.strerror or e})") from None
        raise BvhError(f"{path}:0: corrupt gzip data ({e})") from None


_MOTION = re.compile(rb"^[ \t]*MOTION(?![^\s])", re.M)
_CHANNELS = re.compile(rb"\bCHANNELS\s+(\d{1,12})\b")  # a longer count is the parser's to refuse
# A count as BVH writes it: ASCII digits (str.isdigit also takes "²" and other digits int() refuses), and few enough
# of them that int() reads it (Python refuses over 4300 digits) and any limit can be checked against it.
_WHOLE = re.compile(r"[0-9]{1,12}")


def _read_bounded(f, name):
    """Read a BVH stream in chunks: the header first (at most MAX_HEADER_BYTES up to the Frame Time line), then
    at most what its frames of its channels can take as text. A file that is more, such as a few megabytes of
    gzip that inflate to gigabytes, is refused once it passes that bound, so memory stays flat."""
    head, found = _read_head(f, name)
    if found is not None:
        budget = found[0]
        # To the end or one byte past the budget, in chunks: one read of the budget would ask the allocator for all
        # of it at once (the header's declared size, up to gigabytes), which a host that does not overcommit refuses.
        user_files.read_at_most(f, max(budget + 1 - len(head), 0), into=head)
        if len(head) > budget:
            raise BvhError(
                f"{name}:0: more data than its header's frames and channels can hold "
                f"(over {budget / 2**20:.1f} MB of text): refused"
            )
    return head


def _read_head(f, name):
    """(bytes read, (byte budget, frame time, frames) or None at the end of the file before the MOTION header is
    whole)."""
    head, seen, motion = bytearray(), 0, None  # `seen`: the start of the last line searched, which may go on
    while True:
        chunk = f.read(_CHUNK)
        if not chunk:
            return head, None
        if not head and chunk[:3] == b"\xef\xbb\xbf":  # UTF-8 byte-order mark
            chunk = chunk[3:]
        head += chunk
        motion = motion or _find_motion(head, seen)
        seen = head.rfind(b"\n") + 1
        found = None if motion is None else _budget(head, name, motion)
        if found is not None:
            return head, found
        if len(head) > MAX_HEADER_BYTES:
            raise BvhError(
                f"{name}:0: no whole MOTION header (its MOTION, Frames and Frame Time lines) in the first "
                f"{MAX_HEADER_BYTES >> 20} MB: not a BVH file"
            )


def _find_motion(head, seen):
    """The MOTION line at or after the line start `seen`, or None. The line at `seen` is matched where it starts
    and only whole new lines are searched, so a header of one endless line costs one pass, not one per chunk."""
    m = _MOTION.match(head, seen)
    after = head.find(b"\n", seen) + 1
    return m or (_MOTION.search(head, after) if after else None)


def header_fps(path):
    """A BVH file's frame rate, from its header alone (plain or gzip); BvhError naming the file otherwise."""
    return header_timing(path)[0]


def header_timing(path):
    """(frame rate, frames) of a BVH file, from its header alone (plain or gzip): what a length check needs before
    the frames are read; BvhError naming the file otherwise."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            gz = f.read(2) == b"\x1f\x8b"
        with gzip.open(path, "rb") if gz else open(path, "rb") as f:
            _, found = _read_head(f, str(path))
    except (OSError, EOFError, zlib.error) as e:
        raise BvhError(f"{path}:0: cannot read file ({getattr(e, 'strerror', None) or e})") from None
    if found is None:
        bvh = read_bvh(path)  # a malformed file: the full reader names what is wrong
        return bvh.fps, bvh.n_frames
    return 1.0 / found[1], found[2]


def _budget(head, name, m):
    """(how many bytes the whole file may have, its frame time) once `head` holds the MOTION header that starts at
    the match `m`; None while it does not yet.
    The frame and channel counts are checked against MAX_MOTION_VALUES here, before the frames are read."""
    complete = head[: head.rfind(b"\n") + 1]  # only whole lines: a cut line would read as a malformed one
    line_no = head.count(b"\n", 0, m.start()) + 1
    try:
        cursor, _, n_frames, frames_line, dt = _motion_header(complete, m.end(), line_no, name)
    except BvhError as e:
        if "truncated before" in str(e):
            return None
        raise
    n_channels = sum(int(n) for n in _CHANNELS.findall(head, 0, m.start()))
    if n_frames * n_channels > MAX_MOTION_VALUES:
        raise BvhError(
            f"{name}:{frames_line}: {n_frames} frames of {n_channels} channels is more than the limit of "
            f"{MAX_MOTION_VALUES} values"
        )
    return cursor + 1 + n_frames * (n_channels * MAX_BYTES_PER_VALUE + 2) + _CHUNK, dt, n_frames


def _number(tok, where):
    try:
        value = float(tok)
    except ValueError:
        raise BvhError(f"{where}: expected a number, got {tok!r}") from None
    if not abs(value) <= MAX_VALUE:
        raise BvhError(f"{where}: number out of range (non-finite or beyond ±{MAX_VALUE:g}), got {tok!r}")
    return value


def read_bvh(path):
    """Read a BVH file (plain or gzip) into a `Bvh`; raise `BvhError` naming file and line."""
    raw = _read_bytes(path)
    name = str(path)
    # Only the header is split into lines; the MOTION block stays one buffer for the numeric parse.
    m = _MOTION.search(raw)
    if m is None:
        _no_motion(raw, name)
    lines = raw[: m.start()].decode("utf-8", errors="replace").split("\n")
    motion_line = len(lines) - 1  # 0-based index of the MOTION line
    h = _Hierarchy(lines[:motion_line], motion_line, name)
    n_channels = sum(len(c) for c in h.channels)
    cursor, line_no, n_frames, frames_line, dt = _motion_header(raw, m.end(), motion_line + 1, name)
    # bytes, not a slice of the bytearray read: np.loadtxt reads the block through io.BytesIO, which shares bytes
    # but copies anything else (a second copy of the frames' text while their values were made)
    block = bytes(memoryview(raw)[cursor + 1 :]) if cursor >= 0 else b""
    del raw, m  # the block is a copy (and the match holds the file): one copy of the frames' text at a time
    motion = _parse_motion(block, line_no + 1, n_frames, n_channels, frames_line, name)
    return Bvh(
        names=h.names,
        parents=np.array(h.parents, dtype=np.int64),
        offsets=np.array(h.offsets),
        channels=h.channels,
        motion=motion,
        frame_time=dt,
        end_sites=h.end_sites,
        path=name,
    )


def _no_motion(raw, name):
    """The error for a file without a MOTION line: empty, not BVH at all, or truncated."""
    lines = raw.decode("utf-8", errors="replace").split("\n")
    last = len(lines) - (1 if lines[-1].strip() == "" else 0)
    if not "".join(lines).strip():
        raise BvhError(f"{name}:1: empty file")
    if lines[0].split()[:1] != ["HIERARCHY"]:
        raise BvhError(f"{name}:1: expected 'HIERARCHY' at the start of the file")
    raise BvhError(f"{name}:{last}: no MOTION section (file truncated?)")


class _Hierarchy:
    """The HIERARCHY section parsed from its lines: names, parents, offsets, channels and end sites.

    The header is read as a token stream with line numbers, so layout (braces on their own line or not) is
    free; each keyword has its own method.
    """

    def __init__(self, lines, motion_line, name):
        self.name, self.motion_line = name, motion_line
        self.tokens = [(t, i + 1) for i, line in enumerate(lines) for t in line.split()]
        if not self.tokens or self.tokens[0][0] != "HIERARCHY":
            at = self.tokens[0][1] if self.tokens else 1
            raise BvhError(f"{name}:{at}: expected 'HIERARCHY' at the start of the file")
        self.names, self.parents, self.offsets, self.channels, self.end_sites = [], [], [], [], []
        self.stack = []  # indices of open joints; None for an open End Site
        self.pos = 1
        keywords = {
            "ROOT": self._joint,
            "JOINT": self._joint,
            "End": self._end_site,
            "OFFSET": self._offset,
            "CHANNELS": self._channels,
            "}": self._close,
        }
        while self.pos < len(self.tokens):
            tok, ln = self._take("a joint")
            where = f"{name}:{ln}"
            if tok not in keywords:
                raise BvhError(f"{where}: unexpected {tok!r} in HIERARCHY")
            keywords[tok](tok, where)
        self._check_complete()

    def _take(self, what):
        if self.pos >= len(self.tokens):
            raise BvhError(f"{self.name}:{self.motion_line + 1}: hierarchy ends early, expected {what}")
        self.pos += 1
        return self.tokens[self.pos - 1]

    def _open_brace(self, after):
        brace, bl = self._take("'{'")
        if brace != "{":
            raise BvhError(f"{self.name}:{bl}: expected '{{' after {after}, got {brace!r}")

    def _joint(self, tok, where):
        if tok == "ROOT" and self.stack:
            raise BvhError(f"{where}: ROOT inside another joint")
        if tok == "JOINT" and (not self.stack or self.stack[-1] is None):
            raise BvhError(f"{where}: JOINT outside a joint")
        jname, _ = self._take("a joint name")
        self._open_brace(f"{tok} {jname}")
        self.parents.append(self.stack[-1] if self.stack else -1)
        self.names.append(jname)
        self.offsets.append(None)
        self.channels.append([])
        self.stack.append(len(self.names) - 1)

    def _end_site(self, tok, where):
        site, sl = self._take("'Site'")
        if site != "Site" or not self.stack or self.stack[-1] is None:
            raise BvhError(f"{self.name}:{sl}: misplaced End Site")
        self._open_brace("End Site")
        self.end_sites.append([self.stack[-1], None])
        self.stack.append(None)

    def _offset(self, tok, where):
        if not self.stack:
            raise BvhError(f"{where}: OFFSET outside a joint")
        vals = np.array([_number(self._take("three OFFSET values")[0], where) for _ in range(3)])
        if self.stack[-1] is None:
            self.end_sites[-1][1] = vals
        else:
            self.offsets[self.stack[-1]] = vals

    def _channels(self, tok, where):
        if not self.stack or self.stack[-1] is None:
            raise BvhError(f"{where}: CHANNELS outside a joint")
        n_str, _ = self._take("a channel count")
        if not _WHOLE.fullmatch(n_str) or int(n_str) > len(CHANNEL_NAMES):
            raise BvhError(f"{where}: channel count must be a whole number 0-{len(CHANNEL_NAMES)}, got {n_str[:20]!r}")
        chans = []
        for _ in range(int(n_str)):
            ch, cl = self._take("a channel name")
            if ch not in CHANNEL_NAMES:
                raise BvhError(
                    f"{self.name}:{cl}: unknown channel name {ch!r} (expected one of {', '.join(CHANNEL_NAMES)})"
                )
            chans.append(ch)
        self.channels[self.stack[-1]] = chans

    def _close(self, tok, where):
        if not self.stack:
            raise BvhError(f"{where}: unmatched '}}'")
        self.stack.pop()

    def _check_complete(self):
        at = f"{self.name}:{self.motion_line + 1}"
        if self.stack:
            raise BvhError(f"{at}: hierarchy not closed ({len(self.stack)} '{{' left open)")
        if not self.names:
            raise BvhError(f"{at}: hierarchy has no joints")
        for j, off in enumerate(self.offsets):
            if off is None:
                raise BvhError(f"{self.name}: joint {self.names[j]!r} has no OFFSET")
        self.end_sites = [(p, off if off is not None else np.zeros(3)) for p, off in self.end_sites]


def _motion_header(raw, start, line_no, name):
    """The "Frames: N" and "Frame Time: dt" lines after the MOTION keyword (ending at byte `start`, line
    `line_no`) -> (cursor: the newline before the first frame, or -1; its line number; N; the Frames line; dt)."""
    cursor = raw.find(b"\n", start)
    header = {}
    while len(header) < 2:
        if cursor < 0:
            raise BvhError(
                f"{name}:{line_no}: MOTION block truncated before "
                f"{'Frames' if 'frames' not in header else 'Frame Time'}"
            )
        end = raw.find(b"\n", cursor + 1)
        text = raw[cursor + 1 : end if end >= 0 else len(raw)].decode("utf-8", errors="replace")
        cursor, line_no = end, line_no + 1
        parts = text.split()
        if parts:
            _motion_header_line(parts, text, header, f"{name}:{line_no}", line_no)
    n_frames, frames_line = header["frames"]
    return cursor, line_no, n_frames, frames_line, header["dt"]


def _motion_header_line(parts, text, header, where, line_no):
    """One non-blank MOTION header line into `header` ("frames": (N, line), then "dt")."""
    if parts[0] == "Frames:" and len(parts) == 2 and "frames" not in header:
        if not _WHOLE.fullmatch(parts[1]):
            raise BvhError(f"{where}: Frames must be a non-negative integer (12 digits at most), got {parts[1][:20]!r}")
        header["frames"] = (int(parts[1]), line_no)
    elif parts[:2] == ["Frame", "Time:"] and len(parts) == 3 and "frames" in header:
        dt = _number(parts[2], where)
        if not 1 / MAX_FPS <= dt <= 1 / MIN_FPS:  # also false for nan and inf
            raise BvhError(
                f"{where}: Frame Time must be between {1 / MAX_FPS:g} and "
                f"{1 / MIN_FPS:g} s ({MIN_FPS:g}-{MAX_FPS:g} fps), got {parts[2]!r}"
            )
        header["dt"] = dt
    else:
        want = "'Frames: N'" if "frames" not in header else "'Frame Time: SECONDS'"
        raise BvhError(f"{where}: expected {want}, got {text.strip()[:60]!r}")


def _parse_motion(block, first, n_frames, n_channels, frames_line, name):
    """Parse the bytes `block` (starting at line `first`) as n_frames rows of n_channels numbers.

    Vectorised: token counts per line from byte classes, then one np.loadtxt over the block;
    a line-by-line walk happens only to name the line of a non-numeric value.
    """
    b = np.frombuffer(block, dtype=np.uint8)
    newlines = (np.flatnonzero(b[part] == 10) + part.start + 1 for part in spans(len(b), PARSE_SPAN))
    line_begin = np.concatenate([[0], *newlines])
    line_begin = line_begin[line_begin < len(b)]
    per_line = _tokens_per_line(b, line_begin)
    nonempty = np.flatnonzero(per_line)
    bad = nonempty[per_line[nonempty] != n_channels]
    if len(bad):
        k = bad[0]
        got = per_line[k]
        what = "truncated frame" if k == nonempty[-1] and got < n_channels else "wrong number of values"
        raise BvhError(f"{name}:{first + k}: {what}: expected {n_channels} values, got {got}")
    if len(nonempty) != n_frames:
        if len(nonempty) < n_frames:
            raise BvhError(
                f"{name}:{frames_line}: MOTION block truncated: Frames says {n_frames}, "
                f"the file has {len(nonempty)} frame lines"
            )
        raise BvhError(
            f"{name}:{first + nonempty[n_frames]}: more frame lines than Frames: {n_frames} says "
            f"({len(nonempty)} lines)"
        )
    if n_frames == 0 or n_channels == 0:
        return np.zeros((n_frames, n_channels))
    try:
        # numpy's C text reader: bit-identical to float() and faster than np.fromstring
        values = np.loadtxt(io.BytesIO(block), dtype=np.float64, comments=None, ndmin=2).ravel()
    except ValueError:
        values = None
    if values is None or values.size != n_frames * n_channels:
        _find_bad_number(block.decode("utf-8", errors="replace").split("\n"), first, name)
        raise BvhError(f"{name}:{first}: MOTION block could not be parsed as numbers")
    for part in spans(values.size, PARSE_SPAN):  # a span at a time: |values| whole would be one more copy of them
        out = np.flatnonzero(~(np.abs(values[part]) <= MAX_VALUE))  # also catches nan and inf
        if len(out):
            k = (part.start + int(out[0])) // n_channels
            raise BvhError(
                f"{name}:{first + nonempty[k]}: value out of range (non-finite or beyond ±{MAX_VALUE:g}) in frame {k}"
            )
    return values.reshape(n_frames, n_channels)


def spans(n, size):
    """Slices of `size` elements covering n, the last one shorter: a long take worked a part at a time."""
    return (slice(start, min(start + size, n)) for start in range(0, n, size))


def _tokens_per_line(b, line_begin):
    """The number of values on each line of the text `b` (bytes) whose lines begin at `line_begin`.

    A value starts at a byte above 32 (not space) after one at or below it, or at the text's start. Counted a span
    of the text at a time: the byte classes of the whole text at once were twice its size again at the parse's peak
    (and, summed through an integer a byte, ten times it before that)."""
    per_line = np.zeros(len(line_begin), dtype=np.int64)
    for part in spans(len(b), PARSE_SPAN):
        text = b[part]
        before = np.empty(len(text), dtype=bool)  # whether the byte before each is a space
        before[0] = part.start == 0 or b[part.start - 1] <= 32
        np.less_equal(text[:-1], 32, out=before[1:])
        starts = np.flatnonzero(before & (text > 32)) + part.start
        if len(starts):
            lines = np.searchsorted(line_begin, starts, side="right") - 1  # ascending: the span's lines only
            counts = np.bincount(lines - lines[0])
            per_line[lines[0] : lines[0] + len(counts)] += counts
    return per_line


def _find_bad_number(lines, first, name):
    for k, line in enumerate(lines):
        for tok in line.split():
            try:
                float(tok)
            except ValueError:
                raise BvhError(f"{name}:{first + k}: non-numeric value {tok[:40]!r}") from None


def forward_kinematics(parents, rot, trans):
    """Global positions [T, J, 3] and rotations [T, J, 3, 3] from local ones (parents before children)."""
    T, J = trans.shape[:2]
    g_rot = np.empty_like(rot)
    g_pos = np.empty_like(trans)
    for j, p in enumerate(parents):
        if p < 0:
            g_rot[:, j] = rot[:, j]
            g_pos[:, j] = trans[:, j]
        else:
            g_pos[:, j] = g_pos[:, p] + np.einsum("tab,tb->ta", g_rot[:, p], trans[:, j])
            g_rot[:, j] = g_rot[:, p] @ rot[:, j]
    return g_pos, g_rot
