"""BVH reader and forward kinematics (issue 2): exactness against scipy, real files, malformed files."""

import gzip
import re
import subprocess
import sys

import numpy as np
import pytest
from helpers.paths import ROOT, TEST_DATA
from helpers.small_bvh import END_SITES, HIERARCHY, JOINTS, N_FRAMES, bvh_text, motion_values
from reference.bvh_fk import fk_positions
from scipy.spatial.transform import Rotation

from generation.data import import_motion
from generation.motion import bvh
from generation.motion.bvh import BvhError, read_bvh


def scipy_fk(motion):
    """Positions of joints and end sites, frame by frame with scipy's Rotation (independent reference)."""
    out = []
    for row in motion:
        col, g_rot, g_pos = 0, [], []
        for name, parent, offset, chans in JOINTS:
            chans = chans.split()
            vals = row[col : col + len(chans)]
            col += len(chans)
            trans = np.array(offset, float)
            rot_axes, rot_angles = "", []
            for ch, v in zip(chans, vals):
                if ch.endswith("position"):
                    trans["XYZ".index(ch[0])] = v
                else:
                    rot_axes += ch[0]
                    rot_angles.append(v)
            local = Rotation.from_euler(rot_axes, rot_angles, degrees=True)  # upper case = intrinsic
            if parent < 0:
                g_rot.append(local)
                g_pos.append(trans)
            else:
                g_rot.append(g_rot[parent] * local)
                g_pos.append(g_pos[parent] + g_rot[parent].apply(trans))
        ends = [g_pos[p] + g_rot[p].apply(off) for p, off in END_SITES]
        out.append(np.array(g_pos + ends))
    return np.array(out)


@pytest.fixture()
def handwritten(tmp_path):
    motion = motion_values()
    path = tmp_path / "mixed.bvh"
    path.write_bytes(bvh_text(motion).encode())
    return path, motion


def test_handwritten_structure(handwritten):
    path, motion = handwritten
    b = read_bvh(path)
    assert b.names == [j[0] for j in JOINTS]
    assert b.parents.tolist() == [j[1] for j in JOINTS]
    assert b.channels == [j[3].split() for j in JOINTS]
    np.testing.assert_allclose(b.offsets, [j[2] for j in JOINTS])
    np.testing.assert_allclose(b.motion, motion)
    assert b.frame_time == pytest.approx(0.04)
    assert [p for p, _ in b.end_sites] == [p for p, _ in END_SITES]


def test_fk_matches_scipy(handwritten):
    path, motion = handwritten
    pos = fk_positions(read_bvh(path), end_sites=True)
    ref = scipy_fk(motion)
    assert pos.shape == (N_FRAMES, len(JOINTS) + len(END_SITES), 3)
    np.testing.assert_allclose(pos, ref, atol=1e-6, rtol=0)
    assert np.ptp(ref, axis=0).max() > 1.0  # the reference really moves: the check can fail


def test_gzip_lf_and_bom_give_the_same(tmp_path, handwritten):
    path, motion = handwritten
    gz = tmp_path / "mixed.bvh.gz"
    gz.write_bytes(gzip.compress(bvh_text(motion, crlf=False).encode()))
    np.testing.assert_array_equal(fk_positions(read_bvh(gz)), fk_positions(read_bvh(path)))
    bom = tmp_path / "bom.bvh"
    bom.write_bytes(b"\xef\xbb\xbf" + bvh_text(motion).encode())
    np.testing.assert_array_equal(read_bvh(bom).motion, read_bvh(path).motion)


def test_real_bandai_and_pfnn_files():
    b = read_bvh(TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz")
    assert len(b.names) == 22 and b.names[0] == "joint_Root" and b.motion.shape[1] == 22 * 6
    assert round(b.fps) == 30
    p = read_bvh(TEST_DATA / "bvh" / "pfnn_locomotion_flat04_head.bvh.gz")
    assert len(p.names) == 31 and p.motion.shape == (240, 6 + 30 * 3) and round(p.fps) == 120
    pos = fk_positions(p)
    assert np.isfinite(pos).all() and pos.shape == (240, 31, 3)


# ---- malformed files: (name, edit of the valid text, expected line, words in the message) ----
def _lines(motion=None):
    return bvh_text(motion if motion is not None else motion_values(), crlf=False).split("\n")


HEADER_LINES = len(HIERARCHY.split("\n")) - 1  # lines before MOTION
FRAMES_LINE = HEADER_LINES + 2
FIRST_FRAME = HEADER_LINES + 4


def _edit(kind):
    lines = _lines()
    edited = _edit_motion(kind, lines) or _edit_header(kind, lines)
    if edited is None:
        raise AssertionError(kind)
    return edited


def _edit_motion(kind, lines):
    """Edits of the MOTION block (None for other kinds)."""
    if kind == "truncated_block":  # file ends two frames early
        return "\n".join(lines[: FIRST_FRAME - 1 + N_FRAMES - 2]) + "\n", FRAMES_LINE, "truncated"
    if kind == "truncated_line":  # file cut in the middle of the last frame
        last = FIRST_FRAME - 1 + N_FRAMES - 1
        return "\n".join(lines[:last] + [lines[last][:40]]), last + 1, "truncated frame"
    if kind == "wrong_count":  # one value too many on the third frame
        lines[FIRST_FRAME + 1] += " 1.0"
        return "\n".join(lines), FIRST_FRAME + 2, "expected 24 values, got 25"
    if kind == "non_numeric":
        parts = lines[FIRST_FRAME + 3].split("\t")
        parts[5] = "12.x5"
        lines[FIRST_FRAME + 3] = "\t".join(parts)
        return "\n".join(lines), FIRST_FRAME + 4, "non-numeric value '12.x5'"
    if kind == "out_of_range":  # a value no capture has, in the sixth frame
        parts = lines[FIRST_FRAME + 4].split("\t")
        parts[7] = "nan"
        lines[FIRST_FRAME + 4] = "\t".join(parts)
        return "\n".join(lines), FIRST_FRAME + 5, "value out of range (non-finite or beyond ±1e+09) in frame 5"
    if kind == "frames_too_few":  # Frames says fewer than the data holds
        lines[FRAMES_LINE - 1] = f"Frames: {N_FRAMES - 2}"
        return "\n".join(lines), FIRST_FRAME + N_FRAMES - 2, "more frame lines"
    if kind == "frames_too_many":  # Frames says more than the data holds
        lines[FRAMES_LINE - 1] = f"Frames: {N_FRAMES + 3}"
        return "\n".join(lines), FRAMES_LINE, "Frames says 10"
    if kind in ("frames_superscript", "frames_5000_digits"):  # str.isdigit takes both, int() refuses them
        lines[FRAMES_LINE - 1] = "Frames: " + ("12\u00b2" if kind == "frames_superscript" else "7" * 5000)
        return "\n".join(lines), FRAMES_LINE, "Frames must be a non-negative integer"
    return None


def _edit_header(kind, lines):
    """Edits of the hierarchy and the MOTION header, and files that are not BVH (None for other kinds)."""
    if kind == "unknown_channel":
        i = next(k for k, line in enumerate(lines) if "CHANNELS 3 Yrotation" in line)
        lines[i] = lines[i].replace("Zrotation", "Wrotation")
        return "\n".join(lines), i + 1, "unknown channel name 'Wrotation'"
    if kind in ("channels_superscript", "channels_5000_digits", "channels_seven"):
        i = next(k for k, line in enumerate(lines) if "CHANNELS 3 Yrotation" in line)
        count = {"channels_superscript": "\u00b2", "channels_5000_digits": "3" * 5000, "channels_seven": "7"}[kind]
        lines[i] = lines[i].replace("CHANNELS 3", f"CHANNELS {count}")
        return "\n".join(lines), i + 1, "channel count must be a whole number 0-6"
    if kind == "no_motion":
        return "\n".join(lines[:HEADER_LINES]) + "\n", HEADER_LINES, "no MOTION"
    if kind == "bad_offset":
        lines[3] = "\tOFFSET 1 two 3"
        return "\n".join(lines), 4, "expected a number, got 'two'"
    if kind == "unclosed":
        del lines[HEADER_LINES - 1]
        return "\n".join(lines), HEADER_LINES, "not closed"
    if kind == "bad_frame_time":
        lines[FRAMES_LINE] = "Frame Time: fast"
        return "\n".join(lines), FRAMES_LINE + 1, "expected a number"
    if kind == "empty":
        return "\n\n", 1, "empty file"
    if kind == "not_bvh":
        return "time,x,y\n0,1,2\n", 1, "expected 'HIERARCHY'"
    return None


CASES = [
    "truncated_block",
    "truncated_line",
    "wrong_count",
    "unknown_channel",
    "non_numeric",
    "out_of_range",
    "frames_too_few",
    "frames_too_many",
    "frames_superscript",
    "frames_5000_digits",
    "channels_superscript",
    "channels_5000_digits",
    "channels_seven",
    "no_motion",
    "bad_offset",
    "unclosed",
    "bad_frame_time",
    "empty",
    "not_bvh",
]


@pytest.mark.parametrize("kind", CASES)
def test_malformed_file_error(tmp_path, capsys, kind):
    text, line, words = _edit(kind)
    path = tmp_path / f"{kind}.bvh"
    path.write_text(text)
    with pytest.raises(BvhError) as e:
        read_bvh(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}:{line}: "), msg
    assert words in msg and "\n" not in msg
    # the CLI: one line on stderr, exit 2, no traceback
    assert import_motion.main([str(path), str(tmp_path / "out.npz")]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {msg}\n"
    assert not (tmp_path / "out.npz").exists()


@pytest.mark.parametrize("kind", [k for k in CASES if _edit_motion(k, _lines()) is not None])
def test_frames_are_checked_a_span_at_a_time_naming_the_same_line(tmp_path, monkeypatch, kind):
    """The frames' text is counted, and their values checked, a span at a time (bvh.PARSE_SPAN): with spans of a
    few bytes or values, which split values, lines and frames, the same line is named as with one span."""
    monkeypatch.setattr(bvh, "PARSE_SPAN", 7)
    text, line, words = _edit(kind)
    path = tmp_path / f"{kind}.bvh"
    path.write_text(text)
    with pytest.raises(BvhError, match=rf"^{re.escape(str(path))}:{line}: .*{re.escape(words)}"):
        read_bvh(path)


def test_a_take_read_a_few_bytes_at_a_time_is_the_same(monkeypatch):
    take = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"
    whole = read_bvh(take).motion
    monkeypatch.setattr(bvh, "PARSE_SPAN", 7)
    assert np.array_equal(read_bvh(take).motion, whole)


def test_cli_subprocess_no_traceback(tmp_path):
    text, line, _ = _edit("non_numeric")
    bad = tmp_path / "bad.bvh.gz"
    bad.write_bytes(gzip.compress(text.encode()))
    r = subprocess.run(
        [sys.executable, "-m", "generation.data.import_motion", str(bad), str(tmp_path / "o.npz")],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert r.stderr.startswith(f"error: {bad}:{line}: non-numeric") and r.stderr.count("\n") == 1
    assert "Traceback" not in r.stderr
    corrupt = tmp_path / "corrupt.bvh.gz"
    corrupt.write_bytes(gzip.compress(b"HIERARCHY\n" * 50)[:30])
    with pytest.raises(BvhError, match=r"corrupt\.bvh\.gz:0: corrupt gzip"):
        read_bvh(corrupt)
    with pytest.raises(BvhError, match=r"missing\.bvh:0: cannot read"):
        read_bvh(tmp_path / "missing.bvh")


def test_import_motion_writes_clip(tmp_path, handwritten):
    from moglow_eval.core.clip import load_clip

    path, motion = handwritten
    out = tmp_path / "clip.npz"
    assert import_motion.main([str(path), str(out), "--scale", "0.5"]) == 0
    clip = load_clip(out)
    assert clip["joint_names"] == [j[0] for j in JOINTS] and clip["fps"] == pytest.approx(25.0)
    np.testing.assert_allclose(clip["joints"], 0.5 * scipy_fk(motion)[:, : len(JOINTS)], atol=1e-4)
    assert "control" not in clip  # unknown skeleton: no 21-joint body, so no control


def test_import_motion_real_take_resampled(tmp_path):
    from moglow_eval.core.clip import load_clip

    out = tmp_path / "walk.npz"
    take = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"
    assert import_motion.main([str(take), str(out), "--fps", "20"]) == 0
    clip = load_clip(out)
    b = read_bvh(take)
    assert clip["joints"].shape == ((b.n_frames - 1) * 2 // 3 + 1, 22, 3) and clip["fps"] == 20.0
    # output frame 2k falls on input frame 3k exactly: plain FK positions there, in metres
    np.testing.assert_allclose(clip["joints"][::2], fk_positions(b)[::3] * 0.01, atol=1e-5)
    assert clip["control"].shape == (len(clip["joints"]), 3)


# The peak resident memory of this process's own image (VmHWM: ru_maxrss keeps the peak of the process it was
# forked from, here the test's), before and after one read.
READ_AND_MEASURE = """
import re, sys
from generation.data.motion_files import read_motion
def peak():
    return int(re.search(r"VmHWM:\\s*(\\d+) kB", open("/proc/self/status").read()).group(1)) * 1024
before = peak()
joints = read_motion(sys.argv[1], 30.0, units=0.05).joints
print(joints.shape[0], peak() - before)
"""


def test_a_long_take_is_read_holding_a_few_times_its_size(tmp_path):
    """A 30-MB take at 120 fps read at 30 fps: the reader's peak (resident, in a process of its own) stays within
    three times the file. It was twelve (the text counted through an integer per byte, every step holding all the
    frames' temporaries at once), then 4.3: numpy's reader was given a second copy of the text, the range check made
    |values| whole, and the resampler held the take's rotations three times at the file's rate. A study's takes may
    be long, and a reader's peak is a machine's limit."""
    rng = np.random.default_rng(0)
    n, block = 150_000, 1000  # a second of random motion, repeated: the reader's work is the same, the writing quick
    values = np.round(rng.uniform(-30, 30, size=(block, motion_values().shape[1])), 4)
    head = HIERARCHY.split("\n")[:-1] + ["MOTION", f"Frames: {n}", "Frame Time: 0.0083333"]
    second = "".join(" ".join(f"{v:.4f}" for v in row) + "\n" for row in values)
    path = tmp_path / "long.bvh"
    path.write_text("\n".join(head) + "\n" + second * (n // block))
    r = subprocess.run([sys.executable, "-c", READ_AND_MEASURE, str(path)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    frames, grown = map(int, r.stdout.split())
    assert frames == (n - 1) // 4 + 1  # the whole take, at 30 fps
    assert grown < 3 * path.stat().st_size, grown / path.stat().st_size
