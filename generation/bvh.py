"""BVH motion-capture files: a reader for any hierarchy and vectorised forward kinematics.

Reads `.bvh` and `.bvh.gz`; any number of joints, 3 or 6 (or any subset of the six) channels per joint,
any rotation order per joint, End Sites, tabs and CRLF line ends. The MOTION block is parsed in one
numpy call over the whole text (fast path); only when that finds something wrong is the block walked
line by line to name the offending line. Errors are `BvhError("FILE:LINE: message")`.

Conventions (the usual BVH ones): rotation channels are intrinsic rotations applied in the listed
order, so `Zrotation Xrotation Yrotation` gives R = Rz @ Rx @ Ry, angles in degrees; a joint's
position channels give its local translation and replace its OFFSET (CONTRACTS.md §1).
"""
from dataclasses import dataclass, field
import gzip
from pathlib import Path
import warnings

import numpy as np

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
_AXIS = {"X": 0, "Y": 1, "Z": 2}


class BvhError(ValueError):
    """A malformed BVH file; the message reads `FILE:LINE: what is wrong`."""


@dataclass
class Bvh:
    names: list            # joint names [J] (End Sites are not joints)
    parents: np.ndarray    # int [J], -1 for the root; parents come before their children
    offsets: np.ndarray    # float [J, 3] OFFSET of each joint, file units
    channels: list         # per joint, its channel names in file order
    motion: np.ndarray     # float [T, C] the MOTION block, C = total channel count
    frame_time: float      # seconds per frame
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


def _read_text(path):
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise BvhError(f"{path}:0: cannot read file ({e.strerror or e})") from None
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError) as e:
            raise BvhError(f"{path}:0: corrupt gzip data ({e})") from None
    return raw.decode("utf-8", errors="replace")


def _number(tok, where):
    try:
        return float(tok)
    except ValueError:
        raise BvhError(f"{where}: expected a number, got {tok!r}") from None


def read_bvh(path):
    """Read a BVH file (plain or gzip) into a `Bvh`; raise `BvhError` naming file and line."""
    text = _read_text(path)
    lines = text.split("\n")
    name = str(path)

    # Header: a token stream with line numbers, so layout (braces on their own line or not) is free.
    motion_line = None
    tokens = []
    for i, line in enumerate(lines):
        parts = line.split()
        if parts and parts[0] == "MOTION":
            motion_line = i
            break
        tokens.extend((t, i + 1) for t in parts)
    if not tokens or tokens[0][0] != "HIERARCHY":
        raise BvhError(f"{name}:{tokens[0][1] if tokens else 1}: expected 'HIERARCHY' at the start of the file")
    if motion_line is None:
        last = len(lines) - (1 if lines[-1].strip() == "" else 0)
        raise BvhError(f"{name}:{last}: no MOTION section (file truncated?)")

    names, parents, offsets, channels, end_sites = [], [], [], [], []
    stack = []  # indices of open joints; None for an open End Site
    pos = 1
    n_tok = len(tokens)

    def take(what):
        nonlocal pos
        if pos >= n_tok:
            raise BvhError(f"{name}:{motion_line + 1}: hierarchy ends early, expected {what}")
        tok = tokens[pos]
        pos += 1
        return tok

    while pos < n_tok:
        tok, ln = take("a joint")
        where = f"{name}:{ln}"
        if tok in ("ROOT", "JOINT"):
            if tok == "ROOT" and stack:
                raise BvhError(f"{where}: ROOT inside another joint")
            if tok == "JOINT" and (not stack or stack[-1] is None):
                raise BvhError(f"{where}: JOINT outside a joint")
            jname, _ = take("a joint name")
            brace, bl = take("'{'")
            if brace != "{":
                raise BvhError(f"{name}:{bl}: expected '{{' after {tok} {jname}, got {brace!r}")
            parents.append(stack[-1] if stack else -1)
            names.append(jname)
            offsets.append(None)
            channels.append([])
            stack.append(len(names) - 1)
        elif tok == "End":
            site, sl = take("'Site'")
            if site != "Site" or not stack or stack[-1] is None:
                raise BvhError(f"{name}:{sl}: misplaced End Site")
            brace, bl = take("'{'")
            if brace != "{":
                raise BvhError(f"{name}:{bl}: expected '{{' after End Site, got {brace!r}")
            end_sites.append([stack[-1], None])
            stack.append(None)
        elif tok == "OFFSET":
            if not stack:
                raise BvhError(f"{where}: OFFSET outside a joint")
            vals = np.array([_number(take("three OFFSET values")[0], where) for _ in range(3)])
            if stack[-1] is None:
                end_sites[-1][1] = vals
            else:
                offsets[stack[-1]] = vals
        elif tok == "CHANNELS":
            if not stack or stack[-1] is None:
                raise BvhError(f"{where}: CHANNELS outside a joint")
            n_str, _ = take("a channel count")
            if not n_str.isdigit():
                raise BvhError(f"{where}: channel count must be an integer, got {n_str!r}")
            chans = []
            for _ in range(int(n_str)):
                ch, cl = take("a channel name")
                if ch not in CHANNEL_NAMES:
                    raise BvhError(f"{name}:{cl}: unknown channel name {ch!r} (expected one of {', '.join(CHANNEL_NAMES)})")
                chans.append(ch)
            channels[stack[-1]] = chans
        elif tok == "}":
            if not stack:
                raise BvhError(f"{where}: unmatched '}}'")
            stack.pop()
        else:
            raise BvhError(f"{where}: unexpected {tok!r} in HIERARCHY")
    if stack:
        raise BvhError(f"{name}:{motion_line + 1}: hierarchy not closed ({len(stack)} '{{' left open)")
    if not names:
        raise BvhError(f"{name}:{motion_line + 1}: hierarchy has no joints")
    for j, off in enumerate(offsets):
        if off is None:
            raise BvhError(f"{name}: joint {names[j]!r} has no OFFSET")
    end_sites = [(p, off if off is not None else np.zeros(3)) for p, off in end_sites]

    # MOTION header lines: "Frames: N" and "Frame Time: dt".
    n_channels = sum(len(c) for c in channels)
    i = motion_line + 1
    header = {}
    while len(header) < 2:
        if i >= len(lines):
            raise BvhError(f"{name}:{i}: MOTION block truncated before {'Frames' if 'frames' not in header else 'Frame Time'}")
        parts = lines[i].split()
        i += 1
        if not parts:
            continue
        if parts[0] == "Frames:" and len(parts) == 2 and "frames" not in header:
            if not parts[1].isdigit():
                raise BvhError(f"{name}:{i}: Frames must be a non-negative integer, got {parts[1]!r}")
            header["frames"] = (int(parts[1]), i)
        elif parts[:2] == ["Frame", "Time:"] and len(parts) == 3 and "frames" in header:
            dt = _number(parts[2], f"{name}:{i}")
            if not dt > 0:
                raise BvhError(f"{name}:{i}: Frame Time must be positive, got {parts[2]!r}")
            header["dt"] = dt
        else:
            want = "'Frames: N'" if "frames" not in header else "'Frame Time: SECONDS'"
            raise BvhError(f"{name}:{i}: expected {want}, got {lines[i - 1].strip()[:60]!r}")
    n_frames, frames_line = header["frames"]
    motion = _parse_motion(lines, i, n_frames, n_channels, frames_line, name)
    return Bvh(names=names, parents=np.array(parents, dtype=np.int64), offsets=np.array(offsets),
               channels=channels, motion=motion, frame_time=header["dt"], end_sites=end_sites, path=name)


def _parse_motion(lines, first, n_frames, n_channels, frames_line, name):
    """Parse lines[first:] as n_frames rows of n_channels numbers, vectorised; exact errors otherwise."""
    block = "\n".join(lines[first:])
    data = block.encode("utf-8", errors="replace")
    b = np.frombuffer(data, dtype=np.uint8)
    # Token count per line, without a Python loop: a token starts at a non-space after a space.
    space = (b == 32) | (b == 9) | (b == 13) | (b == 10) | (b == 11) | (b == 12)
    starts = ~space
    starts[1:] &= space[:-1]
    line_of_byte = np.cumsum(b == 10)
    per_line = np.bincount(line_of_byte[starts], minlength=len(lines) - first)
    nonempty = np.flatnonzero(per_line)
    bad = nonempty[per_line[nonempty] != n_channels]
    if len(bad):
        k = bad[0]
        got = per_line[k]
        what = "truncated frame" if k == nonempty[-1] and got < n_channels else "wrong number of values"
        raise BvhError(f"{name}:{first + k + 1}: {what}: expected {n_channels} values, got {got}")
    if len(nonempty) != n_frames:
        if len(nonempty) < n_frames:
            raise BvhError(f"{name}:{frames_line}: MOTION block truncated: Frames says {n_frames}, "
                           f"the file has {len(nonempty)} frame lines")
        raise BvhError(f"{name}:{first + nonempty[n_frames] + 1}: more frame lines than Frames: {n_frames} says "
                       f"({len(nonempty)} lines)")
    if n_frames == 0 or n_channels == 0:
        return np.zeros((n_frames, n_channels))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            values = np.fromstring(block, sep=" ")
    except (ValueError, DeprecationWarning):
        values = None
    if values is None or values.size != n_frames * n_channels:
        _find_bad_number(lines, first, name)
        raise BvhError(f"{name}:{first + 1}: MOTION block could not be parsed as numbers")
    if not np.all(np.isfinite(values)):
        k = int(np.flatnonzero(~np.isfinite(values))[0]) // n_channels
        raise BvhError(f"{name}:{first + nonempty[k] + 1}: non-finite value in frame {k}")
    return values.reshape(n_frames, n_channels)


def _find_bad_number(lines, first, name):
    for k in range(first, len(lines)):
        for tok in lines[k].split():
            try:
                float(tok)
            except ValueError:
                raise BvhError(f"{name}:{k + 1}: non-numeric value {tok[:40]!r}") from None


def _axis_rotations(axis, degrees):
    """Rotation matrices [T, 3, 3] about one coordinate axis (0=X, 1=Y, 2=Z)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def local_transforms(bvh, frames=None):
    """Local rotation matrices [T, J, 3, 3] and translations [T, J, 3] of every joint.

    `frames` optionally selects frames (index or slice) before any work is done.
    """
    motion = bvh.motion if frames is None else bvh.motion[frames]
    T, J = motion.shape[0], len(bvh.names)
    rot = np.broadcast_to(np.eye(3), (T, J, 3, 3)).copy()
    trans = np.broadcast_to(bvh.offsets, (T, J, 3)).copy()
    for j, (chans, col) in enumerate(zip(bvh.channels, bvh.channel_columns())):
        R = None
        for k, ch in enumerate(chans):
            axis = _AXIS[ch[0]]
            if ch.endswith("position"):
                trans[:, j, axis] = motion[:, col + k]
            else:
                Ra = _axis_rotations(axis, motion[:, col + k])
                R = Ra if R is None else R @ Ra
        if R is not None:
            rot[:, j] = R
    return rot, trans


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


def fk_positions(bvh, end_sites=False):
    """World positions [T, J, 3] of every joint in file units (End Sites appended when asked)."""
    rot, trans = local_transforms(bvh)
    pos, g_rot = forward_kinematics(bvh.parents, rot, trans)
    if end_sites and bvh.end_sites:
        ends = [pos[:, p] + g_rot[:, p] @ off for p, off in bvh.end_sites]
        pos = np.concatenate([pos, np.stack(ends, axis=1)], axis=1)
    return pos
