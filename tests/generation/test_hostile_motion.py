"""Errors and hostile files in a study of your own motion: a skeleton mismatch names the joints that differ, a clip
too short says its length without rounding up, and crafted files (a gzip bomb, a sparse .npy, an .npz whose headers
lie, a skeleton whose parents loop, audio that claims hours) are refused with one line naming the file, memory flat.

Memory is measured with tracemalloc (numpy reports its arrays to it): a bound, not a timing."""

import gzip
import io
import json
import subprocess
import zipfile
import zlib

import numpy as np
import pytest
from helpers.bvh_fixtures import write_family, write_family_study
from helpers.cli import fails_with
from helpers.memory import peak as _peak

from generation.data.motion_files import Motion, MotionError, Skeleton, read_motion
from generation.make_stimuli import main as make_stimuli
from generation.motion.bvh import BvhError, read_bvh
from generation.own_study.inputs import check_same_skeleton, seconds_text
from generation.stimuli.files import StimuliError
from moglow_eval.core.clip import ClipError, load_clip

FLAT = 64 << 20  # the most a refused file may make the reader hold (bytes), far below what it claims


def _fails(argv, capsys, needle):
    return fails_with(make_stimuli, argv, capsys, needle)


# ---------------------------------------------------------------- messages
def _motion(names, parents, path):
    return Motion(np.zeros((2, len(names), 3), np.float32), names, np.array(parents), 30.0, path)


def test_a_skeleton_mismatch_names_the_joints_that_differ():
    names = ["Hips", "Spine", "Neck", "Head", "LeftArm", "RightArm"]
    ref = _motion(names, [-1, 0, 1, 2, 1, 1], "real/a.bvh")
    other = _motion([*names[:4], "LeftArm", "LeftHandIndex1"], [-1, 0, 1, 2, 1, 4], "sys/a.bvh")
    with pytest.raises(StimuliError) as e:
        check_same_skeleton(other, ref)
    line = str(e.value)
    assert "sys/a.bvh: skeleton differs from real/a.bvh" in line
    assert "1 joint (LeftHandIndex1) only in sys/a.bvh" in line and "1 joint (RightArm) only in real/a.bvh" in line
    assert "Hips" not in line  # the joints both have are not listed
    moved = _motion(names, [-1, 0, 1, 2, 2, 1], "sys/a.bvh")  # LeftArm hangs from the neck here
    with pytest.raises(StimuliError, match="joint 4 is LeftArm .parent Neck. here and LeftArm .parent Spine. there"):
        check_same_skeleton(moved, ref)


def test_a_mismatch_in_a_study_names_the_missing_finger(tmp_path, capsys):
    study = write_family_study(tmp_path / "s", "zeroeggs", n_items=2)
    b = read_bvh(study.parent / "sys_a" / "item01.bvh")
    keep = [j for j, n in enumerate(b.names) if n != "LeftHandPinky4"]
    cols = np.concatenate(
        [np.arange(c, c + len(b.channels[j])) for j, c in enumerate(b.channel_columns()) if j in keep]
    )
    from helpers.own_study_data import write_bvh

    ch = [b.channels[j] for j in keep]
    names = [b.names[j] for j in keep]
    write_bvh(
        study.parent / "sys_a" / "item01.bvh",
        names,
        _reindex(b.parents, keep),
        b.offsets[keep],
        ch,
        b.motion[:, cols],
        b.frame_time,
    )
    line = _fails(["--study", str(study), "--out", str(tmp_path / "o"), "--quiet"], capsys, "sys_a/item01.bvh")
    assert "1 joint (LeftHandPinky4) only in real/item01.bvh" in line


def _reindex(parents, keep):
    new = {old: k for k, old in enumerate(keep)}
    return [-1 if parents[j] < 0 else new[parents[j]] for j in keep]


def test_lengths_are_never_rounded_up_to_the_limit(tmp_path, capsys):
    assert seconds_text(0.996) == "0.99 s" and seconds_text(2.0) == "2.00 s" and seconds_text(7.999) == "7.99 s"
    study = write_family_study(tmp_path / "s", "lafan1", n_items=2, frames=29, fps=30.0)  # 0.97 s
    line = _fails(["--study", str(study), "--out", str(tmp_path / "o"), "--quiet"], capsys, "item00.bvh: 0.96 s long")
    assert "a clip needs at least 1 s" in line


# ---------------------------------------------------------------- hostile files
def _bomb(path, head, line=b"0 ", mb=4096):
    """A gzip file of `head` then one line of `line` repeated to `mb` MB, without writing that much anywhere: a
    fully flushed deflate block of a repeated megabyte is the same bytes every time, so it is written `mb` times.
    The trailer is never reached by a reader that stops early, so it is left out."""
    chunk = line * ((1 << 20) // len(line))
    c = zlib.compressobj(9, zlib.DEFLATED, 31)
    first = c.compress(head) + c.flush(zlib.Z_FULL_FLUSH)
    block = c.compress(chunk) + c.flush(zlib.Z_FULL_FLUSH)
    assert c.compress(chunk) + c.flush(zlib.Z_FULL_FLUSH) == block
    with open(path, "wb") as f:
        f.write(first)
        for _ in range(mb):
            f.write(block)
    return path


def _header(n_frames=10):
    text = "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation"
    text += " Yrotation\n  End Site\n  {\n    OFFSET 0 10 0\n  }\n}\nMOTION\n"
    return (text + f"Frames: {n_frames}\nFrame Time: 0.0333333\n").encode()


@pytest.mark.parametrize(
    "where, head, needle",
    [
        ("frames", _header(), "more data than its header's frames and channels can hold"),
        ("header", b"HIERARCHY\nROOT Hips\n{\n  OFFSET ", "no whole MOTION header"),
        ("frame_time", _header()[: _header().index(b"Frame Time")], "no whole MOTION header"),
    ],
)
def test_a_gzip_bomb_is_refused_naming_the_file_with_memory_flat(tmp_path, where, head, needle):
    path = _bomb(tmp_path / f"bomb_{where}.bvh.gz", head)
    assert path.stat().st_size < 6 << 20  # a few megabytes that inflate to 4 GB
    raised, peak = _peak(read_bvh, path)
    assert isinstance(raised, BvhError) and str(path) in str(raised) and needle in str(raised)
    assert peak < FLAT


def test_a_header_claiming_absurd_frames_is_refused_before_reading(tmp_path):
    path = tmp_path / "claims.bvh.gz"
    path.write_bytes(gzip.compress(_header(n_frames=10**9) + b"0 0 0 0 0 0\n"))
    with pytest.raises(BvhError, match=r"claims.bvh.gz:\d+: 1000000000 frames of 6 channels is more than the limit"):
        read_bvh(path)


def test_a_gzip_bomb_in_a_study_is_one_line(tmp_path, capsys):
    study = write_family_study(tmp_path / "s", "lafan1", n_items=2)
    (study.parent / "sys_a" / "item01.bvh").unlink()
    _bomb(study.parent / "sys_a" / "item01.bvh.gz", _header(), mb=64)
    _fails(["--study", str(study), "--out", str(tmp_path / "o"), "--quiet"], capsys, "sys_a/item01.bvh.gz:0: more data")


def test_a_sparse_npy_claiming_terabytes_is_refused(tmp_path):
    path = tmp_path / "huge.npy"
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, dict(descr="<f4", fortran_order=False, shape=(10**9, 3, 3)))
        f.truncate(f.tell() + 10**9 * 36)  # sparse: takes no disk, reads as zeros
    skel = Skeleton(["Hips", "Spine", "Head"], np.array([-1, 0, 1]))
    raised, peak = _peak(read_motion, path, 30.0, skeleton=skel, source_fps=30.0)
    assert isinstance(raised, MotionError) and "huge.npy: 1000000000 frames" in str(raised) and peak < FLAT


def test_an_npz_whose_headers_claim_gigabytes_is_refused(tmp_path):
    path = tmp_path / "clip.npz"
    with zipfile.ZipFile(path, "w") as z:
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, dict(descr="<f4", fortran_order=False, shape=(10**8, 100, 3)))
        z.writestr("joints.npy", buf.getvalue() + b"\0" * 100)
    raised, peak = _peak(load_clip, path)
    assert isinstance(raised, ClipError) and "clip.npz: its arrays would take" in str(raised) and peak < FLAT
    with pytest.raises(MotionError, match="clip.npz: its arrays would take"):
        read_motion(path, 30.0)


def test_a_skeleton_whose_parents_loop_is_not_a_tree(tmp_path, capsys):
    (tmp_path / "loop.json").write_text(json.dumps({"names": ["Hips", "A", "B"], "parents": [None, "B", "A"]}))
    with pytest.raises(
        MotionError, match=r"loop.json: the skeleton is not a tree: its parents form a cycle \(A -> B -> A\)"
    ):
        Skeleton.load(tmp_path / "loop.json")
    from moglow_eval.core.clip import save_clip

    save_clip(tmp_path / "ok.npz", np.zeros((3, 3, 3)), [-1, 0, 1], ["Hips", "A", "B"], 30)
    arrays = dict(np.load(tmp_path / "ok.npz"))
    arrays["parents"] = np.array([-1, 2, 1])
    np.savez(tmp_path / "loop.npz", **arrays)
    with pytest.raises(ClipError, match="not a tree"):
        load_clip(tmp_path / "loop.npz")


def test_a_looping_skeleton_builds_no_study(tmp_path, capsys):
    """The case that built a study: .npy positions with a skeleton file whose parents form a cycle."""
    study = write_family_study(tmp_path / "s", "lafan1", n_items=2)
    path, names, per_metre = write_family(tmp_path / "x.bvh", "lafan1")
    joints = read_motion(path, 30.0).joints
    (study.parent / "npy").mkdir()
    for k in range(2):
        np.save(study.parent / "npy" / f"item{k:02d}.npy", joints[:, : len(names)])
    parents = [None, *names[: len(names) - 1]]
    parents[2], parents[3] = names[3], names[2]
    (study.parent / "skel.json").write_text(json.dumps({"names": names, "parents": parents}))
    text = study.read_text().replace('SYS_A = "sys_a"', 'SYS_A = "sys_a"\nNPY = "npy"')
    study.write_text(text + '[skeleton]\nfile = "skel.json"\nfps = 30\n')
    _fails(
        ["--study", str(study), "--out", str(tmp_path / "o"), "--quiet"],
        capsys,
        "skel.json: the skeleton is not a tree",
    )
    assert not (tmp_path / "o" / "manifest.csv").exists()


# ---------------------------------------------------------------- audio
def test_audio_decodes_no_more_than_is_asked(tmp_path):
    import imageio_ffmpeg

    from rendering import audio

    path = tmp_path / "long.flac"
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-f", "lavfi", "-i", "sine=frequency=220:duration=60"]
    subprocess.run([*cmd, "-ar", "8000", str(path)], check=True)
    raised, peak = _peak(audio.read_audio, path, max_seconds=2.0)
    assert raised is None and peak < FLAT
    assert len(audio.read_audio(path, max_seconds=2.0)) == 2 * audio.RATE


def test_a_wav_header_with_an_absurd_sample_rate_is_refused(tmp_path):
    from rendering import audio
    from rendering.errors import RenderError

    buf = io.BytesIO()
    import wave

    with wave.open(buf, "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(8000)
        w.writeframes(b"\0\0" * 800)
    raw = bytearray(buf.getvalue())
    raw[24:28] = (4_000_000_000).to_bytes(4, "little")  # the fmt chunk's sample rate
    (tmp_path / "fast.wav").write_bytes(bytes(raw))
    with pytest.raises(RenderError, match="fast.wav: the sample rate is 4000000000 Hz, more than the limit"):
        audio.read_audio(tmp_path / "fast.wav")


def test_a_motion_file_that_cannot_be_read_is_said_in_its_own_words(tmp_path):
    """A clip or .npy file of mode 000 is "not a readable ... (Permission denied)", not numpy's "[Errno 13] Permission
    denied: 'PATH'" repeating the path the line names already (without root's rights over files, in a process of its
    own)."""
    import sys

    from helpers.cli import as_a_plain_user
    from helpers.paths import ROOT

    clip, array = tmp_path / "a.npz", tmp_path / "a.npy"
    np.savez(clip, joints=np.zeros((4, 2, 3), np.float32))
    np.save(array, np.zeros((4, 2, 3), np.float32))
    code = """
import sys
from generation.data.motion_files import MotionError, Skeleton, read_motion
import numpy as np
for path in sys.argv[1:]:
    try:
        read_motion(path, 30.0, skeleton=Skeleton(["root", "head"], np.array([-1, 0])), source_fps=30.0)
    except MotionError as e:
        print(e)
"""
    for path in (clip, array):
        path.chmod(0)
    try:
        r = subprocess.run(as_a_plain_user([sys.executable, "-c", code, str(clip), str(array)]),
                           capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    finally:
        for path in (clip, array):
            path.chmod(0o644)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [
        f"{clip}: not a readable .npz clip (Permission denied)",
        f"{array}: not a readable .npy array (Permission denied)",
    ]


def test_a_header_declaring_many_frames_is_read_without_reserving_them(tmp_path):
    """A BVH whose header declares 900,000 frames (1.4 GB of text by the reader's bound) and holds ten: the reader
    asked for the whole bound in one read, which a host that does not overcommit memory refuses (here an address-space
    cap 512 MB above the process's imports, in a process of its own); it reads in chunks and names the short file."""
    from helpers.memory import run_under_address_cap
    from helpers.small_bvh import bvh_text, motion_values

    path = tmp_path / "claims.bvh"
    path.write_text(bvh_text(motion_values(), frames=900_000, crlf=False))
    work = "try:\n    read_motion(sys.argv[1], 30.0, units=0.05)\nexcept MotionError as e:\n    print(e)"
    r = run_under_address_cap("import sys\nfrom generation.data.motion_files import MotionError, read_motion", work,
                              512 << 20, path)  # fmt: skip
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-2000:]
    assert r.stdout.startswith(f"{path}:") and "MOTION block truncated: Frames says 900000" in r.stdout, r.stdout
