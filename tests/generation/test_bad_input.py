"""Bad and hostile input to the motion tools: one line naming the file, line or flag, exit code 2, never a
traceback or a runaway allocation (issue 11, finding 10); and property-based fuzzing of the BVH and clip readers
on random corruptions of real files."""

import gzip
import io
import zipfile

import numpy as np
import pytest
from helpers.cli import one_line_error
from helpers.paths import ROOT, TEST_DATA
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from generation.data import import_motion
from generation.motion.bvh import read_bvh
from moglow_eval.core.cli import UserError
from moglow_eval.core.clip import ClipError, load_clip, save_clip
from rendering import __main__ as render_cli

TAKE = TEST_DATA / "bvh" / "bandai_dash_normal_001.bvh.gz"  # the smallest real take (85 frames)


@pytest.fixture(scope="module")
def take_text():
    return gzip.decompress(TAKE.read_bytes()).decode()


@pytest.fixture(scope="module")
def real_clip(tmp_path_factory, take_text):
    folder = tmp_path_factory.mktemp("clip")
    (folder / "take.bvh").write_text(take_text)
    import_motion.import_motion(folder / "take.bvh", folder / "take.npz")
    return folder / "take.npz"


# ------------------------------------------------------------------ import_motion
@pytest.mark.parametrize(
    "flags, says",
    [
        (["--fps", "1e9"], "--fps: must be >= 1.0 and <= 1000.0"),  # once a MemoryError
        (["--fps", "inf"], "--fps: must be finite"),  # once an OverflowError
        (["--fps", "0"], "--fps: must be >= 1.0"),
        (["--scale", "inf"], "--scale: must be finite"),  # once exit 0 with infinite joints
        (["--scale", "-1"], "--scale: must be > 0"),
        (["--fps", "abc"], "--fps: expected a number"),
    ],
)
def test_import_motion_bad_flags(tmp_path, capsys, flags, says):
    code, line = one_line_error(import_motion.main, [str(TAKE), str(tmp_path / "o.npz"), *flags], capsys)
    assert code == 2 and says in line
    assert not (tmp_path / "o.npz").exists()


@pytest.mark.parametrize("out, says", [("folder", "is a folder"), ("clip", "must end in .npz")])
def test_import_motion_output_path_is_the_one_written(tmp_path, capsys, out, says):
    (tmp_path / "folder").mkdir()
    code, line = one_line_error(import_motion.main, [str(TAKE), str(tmp_path / out)], capsys)
    assert code == 2 and says in line and str(tmp_path / out) in line
    assert not list(tmp_path.glob("*.npz"))  # numpy would have written clip.npz beside 'clip'


def test_import_motion_huge_position_refused(tmp_path, capsys, take_text):
    lines = take_text.split("\n")
    at = next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    lines[at] = "1e308 " + lines[at].split(" ", 1)[1]
    (tmp_path / "big.bvh").write_text("\n".join(lines))
    code, line = one_line_error(import_motion.main, [str(tmp_path / "big.bvh"), str(tmp_path / "o.npz")], capsys)
    assert code == 2 and f"big.bvh:{at + 1}:" in line and "out of range" in line


def test_import_motion_a_known_skeleton_missing_a_joint_imports_without_control(tmp_path, capsys, take_text):
    (tmp_path / "odd.bvh").write_text(take_text.replace("Hand_R", "HandR", 1))
    assert import_motion.main([str(tmp_path / "odd.bvh"), str(tmp_path / "o.npz")]) == 0  # once a KeyError
    assert "has no joint 'Hand_R'" in capsys.readouterr().err
    clip = load_clip(tmp_path / "o.npz")
    assert "control" not in clip and "HandR" in clip["joint_names"]


# ------------------------------------------------------------------ rendering
def _variant(real_clip, tmp_path, name, **changes):
    d = dict(np.load(real_clip))
    d.update(changes)
    np.savez(tmp_path / name, **d)
    return tmp_path / name


@pytest.mark.parametrize(
    "changes, says",
    [
        (dict(fps=np.float64(0)), "fps must be between 1 and 1000, got 0"),
        (dict(fps=np.float64(-20)), "fps must be between"),
        (dict(fps=np.float64("nan")), "got nan"),
        (dict(fps=np.float64(1e12)), "got 1e+12"),
        (dict(fps=np.array("fast")), "fps must be a number"),
        (dict(fps=np.arange(3.0)), "'fps' must be a single number"),
        (dict(parents=np.full(22, 40)), "has parent 40"),
        (dict(parents=np.full(22, -1.0)), "'parents' must be integers"),
        (
            dict(joints=np.zeros((5, 0, 3), np.float32), parents=np.zeros(0, np.int64), joint_names=np.zeros(0, str)),
            "[T >= 1, J >= 1, 3]",
        ),
    ],
)
def test_render_refuses_broken_clip_files(real_clip, tmp_path, capsys, changes, says):
    bad = _variant(real_clip, tmp_path, "bad.npz", **changes)
    code, line = one_line_error(render_cli.main, [str(bad), str(tmp_path / "o.mp4")], capsys)
    assert code == 2 and says in line and "bad.npz" in line
    assert not (tmp_path / "o.mp4").exists()


def test_render_refuses_files_that_are_not_clips(tmp_path, capsys):
    np.savez(tmp_path / "empty.npz")
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04" + b"junk" * 50)
    np.save(tmp_path / "array.npy", np.zeros(4))
    (tmp_path / "array.npy").rename(tmp_path / "array.npz")
    # Not archives at all: numpy's own words for these are about pickled data.
    (tmp_path / "take.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    (tmp_path / "take.txt").write_text("HIERARCHY\nROOT Hips\n{\n")
    (tmp_path / "manifest.csv").write_text("clip_id,condition\na,NAT\n")
    (tmp_path / "touched.npz").touch()
    for name, says in (
        ("empty.npz", "missing key 'joints'"),
        ("junk.npz", "not a readable .npz"),
        ("array.npz", "a single .npy array"),
        ("take.bvh", "a BVH file, not an .npz clip (python -m generation.data.import_motion"),
        ("take.txt", "a BVH file, not an .npz clip"),
        ("manifest.csv", "not an .npz clip (a clip is a NumPy .npz archive"),
        ("touched.npz", "not an .npz clip"),
    ):
        code, line = one_line_error(render_cli.main, [str(tmp_path / name), str(tmp_path / "o.mp4")], capsys)
        assert code == 2 and says in line and name in line and "pickle" not in line


@pytest.mark.parametrize(
    "flags, says",
    [
        (["--size", "100000"], "--size: must be >= 32 and <= 4096"),
        (["--size", "101"], "--size: must be even"),
        (["--qp", "99"], "--qp: must be >= 0 and <= 51"),
        (["--crf", "-1"], "--crf: must be >= 0"),
        (["--preset", "warp"], "--preset: invalid choice"),
        (
            ["--sheet", "/nonexistent/dir/s.png"],
            "--sheet /nonexistent/dir/s.png: folder /nonexistent/dir does not exist",
        ),
        (["--sheet", "{tmp}/s.txt"], "a contact sheet is a PNG file"),
        (["--sheet", "{tmp}"], "is a folder"),
    ],
)
def test_render_bad_flags(real_clip, tmp_path, capsys, flags, says):
    """Refused before the first frame: no video is left behind."""
    flags = [f.replace("{tmp}", str(tmp_path)) for f in flags]
    code, line = one_line_error(render_cli.main, [str(real_clip), str(tmp_path / "o.mp4"), *flags], capsys)
    assert code == 2 and says in line
    assert not (tmp_path / "o.mp4").exists()


@pytest.mark.parametrize("out, says", [("{tmp}", "OUT {tmp}: is a folder"), ("{clip}", "is the clip itself")])
def test_render_refuses_an_output_that_is_a_folder_or_the_clip(real_clip, tmp_path, capsys, out, says):
    out, says = (x.replace("{tmp}", str(tmp_path)).replace("{clip}", str(real_clip)) for x in (out, says))
    code, line = one_line_error(render_cli.main, [str(real_clip), out], capsys)
    assert code == 2 and says in line
    assert real_clip.is_file() and load_clip(real_clip)["joints"].size


def test_make_stimuli_refuses_the_built_in_studys_flags_with_a_study(tmp_path, capsys):
    """However the flag is written, and from `python -m` (whose argv is sys.argv) too."""
    import subprocess
    import sys

    from generation.make_stimuli import main as make_stimuli

    study = str(tmp_path / "study.toml")
    for flags, says in (
        (["--retrain"], "--retrain: not used by a study from folders"),
        (["--retr"], "--retrain: not used by a study from folders"),
        (["--n-items=5"], "--n-items: not used"),
        (["--catch-kinds", "mg-early"], "--catch-kinds: not used"),
    ):
        code, line = one_line_error(make_stimuli, ["--study", study, *flags], capsys)
        assert code == 2 and says in line, line
    r = subprocess.run(
        [sys.executable, "-m", "generation.make_stimuli", "--study", study, "--temperature", "0.9"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 2 and "--temperature: not used by a study from folders" in r.stderr, r.stderr


def test_cli_entry_point_prints_one_line(tmp_path):
    """The real `python -m` entry, not only main(): still one line and exit code 2."""
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-m", "rendering", str(tmp_path / "none.npz"), str(tmp_path / "o.mp4")],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [f"error: {tmp_path / 'none.npz'}: no such file"]


# ------------------------------------------------------------------ fuzzing the readers
def _is_one_line(exc):
    return isinstance(exc, UserError) and str(exc).strip() and "\n" not in str(exc)


def _corrupt(data, edits):
    """Apply (kind, position fraction, payload) edits to bytes: overwrite, insert, delete or truncate."""
    data = bytearray(data)
    for kind, where, payload in edits:
        at = int(where * len(data))
        if kind == "overwrite":
            data[at : at + len(payload)] = payload
        elif kind == "insert":
            data[at:at] = payload
        elif kind == "delete":
            del data[at : at + 1 + len(payload) * 16]
        else:
            del data[at:]
    return bytes(data)


NUMBERS = st.sampled_from([b"1e308", b"-1e308", b"inf", b"nan", b"1e-9", b"0", b"-0", b"1e9", b"x", b"", b"3.5e2"])
EDITS = st.lists(
    st.tuples(
        st.sampled_from(["overwrite", "insert", "delete", "truncate"]),
        st.floats(0, 1, exclude_max=True),
        st.one_of(st.binary(max_size=12), NUMBERS, st.sampled_from([b"{", b"}", b"\n", b"\xff"])),
    ),
    min_size=1,
    max_size=4,
)
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(edits=EDITS)
def test_fuzz_bvh_import_gives_a_valid_clip_or_one_line(tmp_path_factory, take_text, edits):
    folder = tmp_path_factory.mktemp("fz")
    (folder / "in.bvh").write_bytes(_corrupt(take_text.encode(), edits))
    try:
        import_motion.import_motion(folder / "in.bvh", folder / "out.npz", fps=20)
    except Exception as e:  # noqa: BLE001 - the property is exactly "nothing but a one-line UserError"
        assert _is_one_line(e), repr(e)
        return
    clip = load_clip(folder / "out.npz")  # what was written reads back as a valid clip
    assert np.isfinite(clip["joints"]).all() and clip["fps"] == 20
    read_bvh(folder / "in.bvh")


@FUZZ
@given(edits=EDITS)
def test_fuzz_clip_reader_gives_a_valid_clip_or_one_line(tmp_path_factory, real_clip, edits):
    folder = tmp_path_factory.mktemp("fz")
    (folder / "c.npz").write_bytes(_corrupt(real_clip.read_bytes(), edits))
    try:
        clip = load_clip(folder / "c.npz")
    except Exception as e:  # noqa: BLE001
        assert _is_one_line(e), repr(e)
        return
    assert clip["joints"].ndim == 3 and np.isfinite(clip["joints"]).all() and 1 <= clip["fps"] <= 1000


VALUES = st.one_of(
    st.just(np.float64("nan")),
    st.just(np.float64(1e12)),
    st.just(np.zeros((0, 0, 3))),
    st.just(np.array(["a", "b"])),
    st.just(np.zeros((4, 22, 3), np.float32) + 1e30),
    st.just(np.arange(22) - 5),
    st.just(np.int64(20)),
    st.just(np.zeros((85, 22, 2))),
)


@FUZZ
@given(key=st.sampled_from(["joints", "parents", "joint_names", "fps", "control"]), value=VALUES)
def test_fuzz_clip_fields_give_a_valid_clip_or_one_line(tmp_path_factory, real_clip, key, value):
    folder = tmp_path_factory.mktemp("fz")
    d = dict(np.load(real_clip))
    d[key] = value
    np.savez(folder / "c.npz", **d)
    try:
        clip = load_clip(folder / "c.npz")
    except ClipError as e:
        assert _is_one_line(e), repr(e)
        return
    save_clip(folder / "again.npz", clip["joints"], clip["parents"], clip["joint_names"], clip["fps"])


def test_zip_member_corruption_is_one_line(real_clip, tmp_path):
    """A zip whose member data is damaged (CRC or deflate errors raise outside numpy's own error types)."""
    raw = bytearray(real_clip.read_bytes())
    with zipfile.ZipFile(real_clip) as z:
        info = z.getinfo("joints.npy")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 20
    raw[start : start + 40] = bytes(40)
    (tmp_path / "c.npz").write_bytes(bytes(raw))
    with pytest.raises(ClipError) as e:
        load_clip(tmp_path / "c.npz")
    assert _is_one_line(e.value)


def _with_member(real_clip, out, name, data=b"", count=1):
    """The clip `real_clip` with `count` more members called `name` (numbered after the first) holding `data`."""
    out.write_bytes(real_clip.read_bytes())
    with zipfile.ZipFile(out, "a", zipfile.ZIP_DEFLATED) as z:
        for k in range(count):
            z.writestr(name if k == 0 else f"{name}{k}", data)
    return out


def test_an_archives_other_members_are_bounded_before_numpy_reads_them(real_clip, tmp_path):
    """numpy reads every member of an .npz: one not named .npy is read as an array when it starts as one (its header
    can ask for any amount of memory), else as bytes (a small deflated member can inflate to gigabytes), and an
    archive of many members takes minutes to list. All three are refused from the archive's directory and headers,
    before a byte of them is read (they were a machine-wide "out of memory" naming no file, gigabytes accepted, and
    minutes)."""
    from moglow_eval.core.clip import MAX_NPZ_MEMBERS, npz_headers

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (25 * 10**9,)})
    big = _with_member(real_clip, tmp_path / "declared.npz", "extra", header.getvalue())
    with pytest.raises(ClipError, match=r"declared\.npz: its arrays would take \d+ MiB, over the limit"):
        load_clip(big)
    arrays = sum(int(np.prod(shape)) * dtype.itemsize for shape, dtype in npz_headers(real_clip).values())
    raw = _with_member(real_clip, tmp_path / "raw.npz", "readme", bytes(4096))
    assert "readme" not in npz_headers(raw, limit=arrays + 4096)  # bytes, not an array: counted by their size
    with pytest.raises(ClipError, match="over the limit"):
        npz_headers(raw, limit=arrays + 2048)
    many = _with_member(real_clip, tmp_path / "many.npz", "m", b"x", count=MAX_NPZ_MEMBERS)
    with pytest.raises(ClipError, match=rf"many\.npz: \d+ members, more than the limit of {MAX_NPZ_MEMBERS}"):
        load_clip(many)
    assert load_clip(_with_member(real_clip, tmp_path / "fine.npz", "notes", b"a note"))["fps"] > 0


def test_a_system_folder_names_its_missing_items_or_says_it_has_none(tmp_path):
    """--system NAME=DIR: a folder lacking some items names the first five of them and how many more; a folder
    holding none of them says so in a line, not the whole list."""
    from generation.data.systems import SystemError_, find_system_files

    items = [f"item{i:02d}" for i in range(8)]
    with pytest.raises(SystemError_, match=r"no motion file for any of the 8 items \(expected ITEM\.bvh"):
        find_system_files(tmp_path, items)
    (tmp_path / "item00.npz").write_bytes(b"")
    (tmp_path / "notes.txt").write_text("not an item")
    with pytest.raises(SystemError_) as e:
        find_system_files(tmp_path, items)
    assert "item(s) item01, item02, item03, item04, item05 and 2 more (expected" in str(e.value)
    assert "\n" not in str(e.value)


def test_a_bvh_of_more_joints_than_a_clip_holds_is_refused_before_its_kinematics(tmp_path):
    """A BVH is read into a clip, which holds at most MAX_JOINTS joints: a file of more (a chain of 1,001 here,
    20,000 in the intake's probe) is refused naming the file, before forward kinematics over all of them."""
    from generation.data.motion_files import MotionError, read_motion
    from moglow_eval.core.clip import MAX_JOINTS

    n = MAX_JOINTS + 1
    lines = ["HIERARCHY", "ROOT Hips", "{", "OFFSET 0 0 0", "CHANNELS 6 Xposition Yposition Zposition Zrotation "
             "Xrotation Yrotation"]  # fmt: skip
    for i in range(1, n):
        lines += [f"JOINT J{i}", "{", "OFFSET 0 0.001 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["}"] * n + ["MOTION", "Frames: 2", "Frame Time: 0.0333333"] + [" ".join(["0"] * (3 * n + 3))] * 2
    (tmp_path / "deep.bvh").write_text("\n".join(lines) + "\n")
    with pytest.raises(MotionError, match=rf"deep\.bvh: {n} joints and 0 End Sites, more than a clip's limit"):
        read_motion(tmp_path / "deep.bvh", 30.0, up="y")


# ------------------------------------------------------------------ --out, before any work
def test_an_empty_out_or_one_in_the_way_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    """`--out ""` is the current folder to Python: training and sampling wrote there, and the built-in study was
    built into it; preparing a dataset or training the motion encoder read and trained first, then stopped on an
    --out that was a folder (with a traceback, or naming the hidden temporary file). Each command now says so at
    once: the inputs named here do not exist, so any work before the check would be the error instead."""
    from generation import make_stimuli
    from generation.data import prepare
    from generation.metrics import fmd
    from generation.own_study import demo_study
    from generation.sampling import sample
    from generation.training import train

    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "afolder").mkdir()
    none = str(tmp_path / "none.npz")
    commands = {
        "make_stimuli": (make_stimuli.main, [], "folder"),
        "train": (train.main, ["--model", "mg", "--config", "tiny", "--data", none], "folder"),
        "sample": (sample.main, ["--checkpoint", none, "--data", none], "folder"),
        "demo_study": (demo_study.main, [], "folder"),
        "prepare": (prepare.main, ["--data", str(tmp_path / "no-takes")], "file"),
        "fmd": (fmd.main, ["--data", none], "file"),
    }
    for name, (main, argv, kind) in commands.items():
        in_the_way = "afile" if kind == "folder" else "afolder"
        code, line = one_line_error(main, [*argv, "--out", ""], capsys)  # by the parser every command uses
        assert code == 2 and "argument --out: empty; give a value" in line, (name, line)
        code, line = one_line_error(main, [*argv, "--out", in_the_way], capsys)
        assert code == 2 and line.startswith(f"error: --out {in_the_way}: a f"), (name, line)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "afolder"] and not any(
        (tmp_path / "afolder").iterdir()
    )
    # the encoder written over the dataset it trains on (after the training, which read it whole)
    code, line = one_line_error(fmd.main, ["--data", "afile", "--out", str(tmp_path / "afile")], capsys)
    assert code == 2 and "is the file --data names" in line and (tmp_path / "afile").read_text() == "x", line
