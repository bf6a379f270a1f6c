"""Issue 64, intake: a team's submission checked against the released test inputs, every problem at once, a report
per team (CSV and HTML) and a verdict in the exit status (generation.challenge.intake). The motion is a real take
(tests/data/bvh) cut into items; each problem is made from it by hand, and each test asserts the check that must
find it, so none passes without its check."""

import csv
import os
import shutil
import wave
from pathlib import Path

import numpy as np
import pytest
from helpers.paths import TEST_DATA

from generation.challenge.intake import main as intake
from generation.data.motion_files import read_motion
from moglow_eval.core.clip import save_clip

TAKE = TEST_DATA / "bvh" / "bandai_walk_angry_002.bvh.gz"
FPS, FRAMES, ITEMS = 30.0, 60, ("item01", "item02", "item03")


@pytest.fixture(scope="module")
def take():
    return read_motion(TAKE, FPS, up="y")  # the walk goes a long way: its up axis is told, not guessed


def write_speech(folder: Path, seconds: dict):
    folder.mkdir(parents=True, exist_ok=True)
    for item, s in seconds.items():
        with wave.open(str(folder / f"{item}.wav"), "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(16000)
            w.writeframes(np.zeros(round(16000 * s), np.int16).tobytes())
    return folder


def clip(take, k, frames=FRAMES):
    """Item k's motion: its own stretch of the real take."""
    return take.joints[k * 40 : k * 40 + frames]


def write_team(root: Path, take, edit=None, samples=1):
    """A team folder of clip files, one per item (or `samples` per item, each a stretch a frame later), after
    `edit(folder)` has spoiled it."""
    folder = root / "team"
    for k, item in enumerate(ITEMS):
        for s in range(samples):
            path = folder / f"{item}.npz" if samples == 1 else folder / item / f"{s + 1}.npz"
            path.parent.mkdir(parents=True, exist_ok=True)
            joints = take.joints[k * 40 + s : k * 40 + s + FRAMES]
            save_clip(path, joints, take.parents, take.names, FPS)
    if edit:
        edit(folder)
    return folder


def run(tmp_path, folders, samples=1, extra=()):
    speech = write_speech(tmp_path / "speech", {i: FRAMES / FPS for i in ITEMS})
    out = tmp_path / "out"
    argv = ["--inputs", str(speech), "--fps", "30", "--out", str(out), "--quiet", "--samples", str(samples)]
    code = intake([*argv, *extra, *map(str, folders)])
    return code, out


def problems(out, team="team"):
    with open(out / team / "intake.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_a_good_submission_is_accepted_with_its_report(tmp_path, take):
    code, out = run(tmp_path, [write_team(tmp_path, take)])
    assert code == 0 and problems(out) == []
    with open(out / "teams.csv", newline="") as f:
        (row,) = list(csv.DictReader(f))
    assert row["verdict"] == "accepted" and row["files"] == "3" and row["items_given"] == "3"
    assert b"\r" not in (out / "teams.csv").read_bytes()  # the project's LF, as its other new tables
    page = (out / "team" / "intake.html").read_text()
    assert "accepted" in page and "<script" not in page and 'name="viewport"' in page


def _resave(item, fn):
    """An edit that rewrites one item's clip through fn(joints, fps) -> (joints, fps)."""

    def edit(folder):
        from moglow_eval.core.clip import load_clip

        path = folder / f"{item}.npz"
        c = load_clip(path)
        joints, fps = fn(np.array(c["joints"]), float(c["fps"]))
        path.unlink()
        np.savez(path, joints=joints.astype(np.float32), parents=c["parents"], joint_names=c["joint_names"],
                 fps=np.float64(fps))  # fmt: skip

    return edit


def _nan(j, fps):
    j[7, 3] = np.nan
    return j, fps


def _jump(j, fps):
    j[30:] += np.float32([2.0, 0.0, 0.0])  # the body leaps 2 m sideways between two frames (60 m/s), bones intact
    return j, fps


def _z_up(j, fps):
    return np.stack([j[..., 0], -j[..., 2], j[..., 1]], axis=-1), fps  # turned to stand along Z


def _stretch(j, fps):
    j[20:25, 5] += (j[20:25, 5] - j[20:25, 4]) * 0.5  # one bone half as long again for five frames
    return j, fps


@pytest.mark.parametrize(
    "edit, check, needle",
    [
        (lambda f: (f / "item02.npz").unlink(), "missing", "no motion for test item item02: add item02.npz, as the"),
        (
            lambda f: (f / "item09.npz").write_bytes((f / "item01.npz").read_bytes()),
            "entry",
            "item09 is not a test item",
        ),
        (lambda f: (f / "readme.txt").write_text("hi"), "entry", "not a motion file"),
        (_resave("item01", lambda j, fps: (j[:50], 25.0)), "fps", "25 fps, where the dataset is 30 fps"),
        (_resave("item02", lambda j, fps: (j[:-10], fps)), "length", "give 60 frames"),
        (_resave("item03", _nan), "finite", "NaN"),
        (_resave("item01", _jump), "speed", "m/s between frames 29 and 30"),
        (_resave("item02", _stretch), "bones", "changes its length by"),
        (_resave("item03", lambda j, fps: (j * 100, fps)), "height", "tall"),
        (_resave("item02", _z_up), "height", "m along Z and"),  # its depth passes for a height along Y
    ],
    ids=["missing", "extra", "not-motion", "fps", "length", "nan", "speed", "bones", "height", "z-up"],
)
def test_each_problem_is_found_and_named(tmp_path, take, edit, check, needle):
    code, out = run(tmp_path, [write_team(tmp_path, take, edit)])
    found = problems(out)
    assert code == 1, found
    assert [p["check"] for p in found] == [check], found
    assert needle in found[0]["problem"] and ":" in found[0]["problem"], found  # what, then what to do
    assert str(tmp_path) not in found[0]["problem"], found  # the file as the team knows it, not the organiser's path
    assert "[skeleton]" not in found[0]["problem"] and "study file" not in found[0]["problem"], found  # a study's
    assert (out / "team" / "intake.html").stat().st_mode & 0o777 == 0o644  # a page to pass on


def _first_joint(take, kind):
    """The take as a skeleton whose first joint is the hips (its root marker dropped), or whose first joint is a
    floor point named otherwise than a root (`Reference`)."""
    from types import SimpleNamespace

    from moglow_eval.core.skeleton_names import body_skeleton

    if kind == "hips":
        keep, names, parents = body_skeleton(take.names, take.parents)
        return SimpleNamespace(joints=take.joints[:, keep], names=names, parents=np.asarray(parents))
    return SimpleNamespace(joints=take.joints, names=["Reference", *take.names[1:]], parents=take.parents)


def test_a_hips_first_skeletons_hip_bones_are_checked_and_a_floor_points_link_is_not(tmp_path, take):
    """The hips' bones to the spine and thighs are a body's, checked where the hips are the first joint; a floor
    point's link to the hips moves as the body walks (here about 8 m), named as a root or not."""
    hips = _first_joint(take, "hips")
    assert hips.names[0] == "Hips"
    code, out = run(tmp_path / "good", [write_team(tmp_path / "good", hips)])
    assert code == 0 and problems(out) == []

    def lift_hips(folder):  # the hips alone 15 cm up for five frames: only their own bones change
        _resave("item02", lambda j, fps: (_lift(j, 0, 0.15), fps))(folder)

    code, out = run(tmp_path / "bad", [write_team(tmp_path / "bad", hips, lift_hips)])
    found = problems(out)
    assert code == 1 and [p["check"] for p in found] == ["bones"], found
    assert "the bone Hips-" in found[0]["problem"], found
    floor = _first_joint(take, "reference")
    code, out = run(tmp_path / "floor", [write_team(tmp_path / "floor", floor)])
    assert code == 0 and problems(out) == []


def _lift(j, joint, metres):
    j[20:25, joint, 1] += metres
    return j


def test_every_problem_at_once_and_one_format(tmp_path, take):
    def spoil(folder):
        _resave("item01", lambda j, fps: (j[:50], 25.0))(folder)
        (folder / "item02.npz").unlink()
        np.save(folder / "item02.npy", clip(take, 1))  # a second format
        _resave("item03", _jump)(folder)

    code, out = run(tmp_path, [write_team(tmp_path, take, spoil)])
    checks = sorted(p["check"] for p in problems(out))
    assert code == 1 and checks == ["format", "fps", "speed"], checks


def test_samples_per_item(tmp_path, take):
    def drop(folder):
        (folder / "item02" / "3.npz").unlink()

    code, out = run(tmp_path, [write_team(tmp_path, take, drop, samples=3)], samples=3)
    found = problems(out)
    assert code == 1 and [p["check"] for p in found] == ["samples"] and "2 samples of item02" in found[0]["problem"]
    code, out = run(tmp_path / "again", [write_team(tmp_path / "again", take, samples=3)], samples=3)
    assert code == 0
    gone = write_team(tmp_path / "gone", take, lambda f: shutil.rmtree(f / "item02"), samples=3)
    found = problems(run(tmp_path / "gone", [gone], samples=3)[1])
    assert [p["problem"] for p in found] == ["no motion for test item item02: add a folder item02/ of 3 samples "
                                             "(1.npz .. 3.npz)"], found  # fmt: skip
    code, out = run(tmp_path / "one", [write_team(tmp_path / "one", take)], samples=3)  # one file each: 3 asked
    assert code == 1 and {p["check"] for p in problems(out)} == {"samples"}
    # GENEA 2026's rule (--or-one): a deterministic system's one file per item is accepted; a stochastic one's
    # folders still need every sample
    code, out = run(tmp_path / "or1", [write_team(tmp_path / "or1", take)], samples=3, extra=["--or-one"])
    assert code == 0
    with open(out / "teams.csv", newline="") as f:
        assert next(csv.DictReader(f))["samples_per_item"] == "1"
    code, out = run(tmp_path / "or3", [write_team(tmp_path / "or3", take, drop, samples=3)], samples=3,
                    extra=["--or-one"])  # fmt: skip
    assert code == 1 and [p["check"] for p in problems(out)] == ["samples"]
    # an archive's stray folder beside one file per item: the folder is an entry to remove, the team deterministic
    code, out = run(tmp_path / "mac", [write_team(tmp_path / "mac", take, lambda f: (f / "__MACOSX").mkdir())],
                    samples=3, extra=["--or-one"])  # fmt: skip
    found = problems(out)
    assert code == 1 and [(p["check"], "__MACOSX is not a test item" in p["problem"]) for p in found] == [
        ("entry", True)
    ], found


def test_a_file_at_another_rate_and_length_is_told_one_rate(tmp_path, take):
    """A 25-fps file a little short: its fps problem asks for the dataset's 30 fps, and its length problem gives
    the frames at that rate (it said "give 50 frames at 25 fps" beside "export it at 30 fps")."""
    code, out = run(tmp_path, [write_team(tmp_path, take, _resave("item01", lambda j, fps: (j[:40], 25.0)))])
    found = {p["check"]: p["problem"] for p in problems(out)}
    assert code == 1 and set(found) == {"fps", "length"}, found
    assert "export it at 30 fps" in found["fps"] and found["length"].endswith("give 60 frames at 30 fps"), found


def test_a_joint_name_with_a_terminals_escape_is_refused(tmp_path, take):
    """Joint names go into every problem's text, the team's CSV among them, which a terminal would obey."""

    def escape(folder):
        c = dict(np.load(folder / "item01.npz"))
        c["joint_names"] = np.array([*c["joint_names"][:-1], "Head\x1b[31m"])
        np.savez(folder / "item01.npz", **c)

    code, out = run(tmp_path, [write_team(tmp_path, take, escape)])
    found = problems(out)
    assert code == 1 and [p["check"] for p in found] == ["read"], found
    assert "joint name must be printable text" in found[0]["problem"] and "\x1b" not in found[0]["problem"]


def test_npy_files_without_their_frame_rate_name_the_intakes_flag(tmp_path, take):
    """A .npy file stores no frame rate, which the intake's --source-fps gives (the study reader's words name a study
    file's setting, which neither the organiser nor the team has here)."""

    def as_npy(folder):
        for item in ITEMS:
            np.save(folder / f"{item}.npy", np.load(folder / f"{item}.npz")["joints"])
            (folder / f"{item}.npz").unlink()

    code, out = run(tmp_path, [write_team(tmp_path, take, as_npy)])
    found = problems(out)
    assert code == 1 and all("--source-fps" in p["problem"] and "study file" not in p["problem"] for p in found)


def test_two_files_for_one_item_or_sample_are_refused_naming_both(tmp_path, take):
    """Which of two files for one item (or one sample) the team meant is the team's to say: the intake read one of
    them and said nothing of the other, and a team with a broken ITEM.bvh beside its ITEM.npz was accepted."""

    def beside(folder):
        (folder / "item01.bvh").write_text("not a BVH")

    code, out = run(tmp_path, [write_team(tmp_path, take, beside)])
    two = [p for p in problems(out) if "two files" in p["problem"]]
    assert code == 1 and len(two) == 1 and "two files for item01: item01.bvh and item01.npz: keep" in two[0]["problem"]

    def samples_twice(folder):
        (folder / "item02" / "1.bvh").write_text("not a BVH")
        (folder / "item03.npz").write_bytes((folder / "item03" / "1.npz").read_bytes())

    code, out = run(tmp_path / "k", [write_team(tmp_path / "k", take, samples_twice, samples=3)], samples=3)
    found = [p["problem"] for p in problems(out)]
    assert code == 1 and any("two files for item02/1: 1.bvh and 1.npz" in p for p in found), found
    assert any("two files for item03/1: 1.npz and item03.npz" in p for p in found), found


def test_hostile_entries_are_one_line_each(tmp_path, take):
    def hostile(folder):
        os.symlink("/etc/passwd", folder / "item04.npz")
        os.mkfifo(folder / "item05.npz")
        (folder / "item\x1b[31m.npz").write_bytes(b"x")
        (folder / "item01" / "deeper").mkdir(parents=True)
        (folder / "item01.npz").unlink()
        bomb = folder / "item02.npz"  # a header that declares 2 TB of joints
        bomb.unlink()
        with open(bomb, "wb") as f:
            np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (10**9, 100, 3)})

    code, out = run(tmp_path, [write_team(tmp_path, take, hostile)])
    lines = problems(out)
    text = "\n".join(f"{p['file']}: {p['check']}: {p['problem']}" for p in lines)
    assert code == 1
    assert "item04.npz: entry: a symbolic link" in text
    assert "item05.npz: entry: not a regular file" in text
    assert "'item\\x1b[31m.npz': entry: a name that is not plain" in text
    assert "a folder inside item01/" in text and "item01: samples: a folder" in text
    assert "item02.npz: read:" in text
    assert "\x1b" not in (out / "team" / "intake.html").read_text()


def test_a_whole_challenge_in_one_run(tmp_path, take):
    teams = tmp_path / "teams"
    good = write_team(tmp_path / "a", take)
    bad = write_team(tmp_path / "b", take, lambda f: (f / "item03.npz").unlink())
    good.rename(teams / "alpha") if teams.exists() else (teams.mkdir(), good.rename(teams / "alpha"))
    bad.rename(teams / "beta")
    (teams / ".git").mkdir()  # hidden: the organiser's, no team
    code, out = run(tmp_path, [], extra=["--teams", str(teams)])
    with open(out / "teams.csv", newline="") as f:
        rows = {r["team"]: r for r in csv.DictReader(f)}
    assert code == 1 and set(rows) == {"alpha", "beta"}
    assert rows["alpha"]["verdict"] == "accepted" and rows["beta"]["verdict"] == "refused"
    index = (out / "index.html").read_text()
    assert 'href="alpha/intake.html"' in index and 'href="beta/intake.html"' in index
    hashed = teams / "T#1"  # a name a URL reads otherwise: its link is encoded
    write_team(tmp_path / "h", take).rename(hashed)
    code, out = run(tmp_path / "hash", [hashed])
    assert code == 0 and 'href="T%231/intake.html"' in (out / "index.html").read_text()
    hashed.rename(tmp_path / "T#1")
    # A team that sent an archive, or a link, is judged unusable and named, never left out unsaid (exit 2).
    (teams / "gamma.zip").write_text("an archive, not a folder")
    (teams / "delta").symlink_to(teams / "alpha")
    code, out = run(tmp_path / "again", [], extra=["--teams", str(teams)])
    with open(out / "teams.csv", newline="") as f:
        rows = {r["team"]: r["verdict"] for r in csv.DictReader(f)}
    assert code == 2 and rows == {"alpha": "accepted", "beta": "refused", "delta": "unusable", "gamma.zip": "unusable"}


def test_the_reports_folder_and_the_organisers_flags_are_checked_first(tmp_path, take, capsys):
    """Mistakes of the organiser's command stop it at once with one line naming the flag, before any team is read:
    the reports written into the submissions (--out as the --teams folder), over a file or into the current folder
    (an empty --out), team folders given twice over, or a body model that is not there (each team was refused for
    it, told to export its files again)."""
    teams = tmp_path / "teams"
    teams.mkdir()
    write_team(tmp_path, take).rename(teams / "alpha")
    (tmp_path / "afile").write_text("x")
    cases = [
        (["--teams", str(teams), "--out", str(teams)], "--out"),
        (["--teams", str(teams), "--out", str(teams / "alpha" / "reports")], "--out"),
        (["--teams", str(teams), "--out", str(tmp_path / "afile")], "--out"),
        (["--teams", str(teams), "--out", ""], "--out: empty"),
        (["--teams", str(teams), str(teams / "alpha")], "not both"),
        (["--teams", str(teams), "--smpl-model", str(tmp_path / "no.npz")], "--smpl-model"),
    ]
    speech = write_speech(tmp_path / "speech", {i: FRAMES / FPS for i in ITEMS})
    for extra, says in cases:
        try:
            code = intake(["--inputs", str(speech), "--fps", "30", "--quiet", "--out", str(tmp_path / "out"), *extra])
        except SystemExit as e:  # a flag's own value refused by the parser ("" as --out)
            code = e.code
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and says in err[0], (extra, err)
    assert sorted(p.name for p in (teams / "alpha").iterdir()) == [f"{i}.npz" for i in ITEMS]  # nothing written
    assert not (tmp_path / "out").exists()


def test_unusable_inputs_exit_2_with_one_line(tmp_path, take, capsys):
    team = write_team(tmp_path, take)
    assert intake(["--inputs", str(tmp_path / "nowhere"), "--fps", "30", str(team)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "nowhere" in err and "\n" not in err
    code, out = run(tmp_path, [tmp_path / "no_team"])
    assert code == 2 and "not a folder" in capsys.readouterr().err


def _declares_450000_frames(folder: Path, take):
    """item01 as a clip whose joints' header declares 450,000 frames (its data a few bytes), and item02 as a BVH
    whose Frames line does (its frames a handful): each a small file that says it is hours long."""
    import gzip
    import io
    import zipfile

    header = io.BytesIO()
    shape = (450_000, take.joints.shape[1], 3)
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": shape})
    good = dict(np.load(folder / "item01.npz"))
    (folder / "item01.npz").unlink()
    with zipfile.ZipFile(folder / "item01.npz", "w") as z:
        z.writestr("joints.npy", np.lib.format.MAGIC_PREFIX + b"\x01\x00" + header.getvalue()[8:] + bytes(64))
        for key in ("parents", "joint_names", "fps"):
            buf = io.BytesIO()
            np.save(buf, good[key])
            z.writestr(f"{key}.npy", buf.getvalue())
    (folder / "item02.npz").unlink()
    head, frames = gzip.decompress(TAKE.read_bytes()).decode().split("MOTION", 1)
    lines = frames.strip().splitlines()
    frame_lines = "\n".join(lines[2:12])  # ten frames of the take
    (folder / "item02.bvh").write_text(head + "MOTION\nFrames: 450000\nFrame Time: 0.0333333\n" + frame_lines + "\n")


def test_a_file_whose_header_says_hours_is_refused_for_its_length_unread(tmp_path, take):
    """A file whose header declares far more frames than its item has is refused for its length from the header
    alone: read, such a file (within the reader's bounds) took gigabytes and half a minute, and the truncated ones
    here would have been refused as unreadable instead, hiding what is wrong with them."""
    from generation.challenge.checks import Rules, check_file

    team = write_team(tmp_path, take, lambda f: _declares_450000_frames(f, take))
    bvh = team / "item02.bvh"
    bvh.rename(tmp_path / "item02.bvh")  # the team's files in one format; the BVH is checked on its own below
    save_clip(team / "item02.npz", clip(take, 1), take.parents, take.names, FPS)
    code, out = run(tmp_path, [team])
    found = [(p["item"], p["check"], p["problem"]) for p in problems(out)]
    assert code == 1 and [f[:2] for f in found] == [("item01", "length")] and "450000 frames" in found[0][2], found
    alone = check_file(tmp_path / "item02.bvh", "item02", "", FRAMES / FPS, Rules(FPS, read={"up": "y"}), "bvh")
    assert [(p.check, "450000 frames" in p.text) for p in alone] == [("length", True)], alone


def _wav_field(path: Path, at: int, value: int):
    """The WAV written by write_speech with the 4 bytes at `at` (28: the byte rate, 40: the data's size) set."""
    raw = bytearray(path.read_bytes())
    raw[at : at + 4] = value.to_bytes(4, "little")
    path.write_bytes(bytes(raw))


@pytest.mark.parametrize(
    "at, value, code, says",
    [
        (40, 0xFFFFFFFF, 1, "give 60 frames"),  # streamed: the data the file holds, so the length is still checked
        (40, 0xFFFFFFF0, 1, "give 60 frames"),  # more than the file holds: hours long by the header alone
        (40, 0, 2, "holds no sound"),
        (28, 0, 2, "byte rate is 0"),
    ],
    ids=["streamed", "over-long", "empty", "no-byte-rate"],
)
def test_a_speech_header_neither_turns_the_length_check_off_nor_misstates_it(tmp_path, take, capsys, at, value,
                                                                              code, says):  # fmt: skip
    """The speech's WAV header gives each item its length, which every team's motion is checked against: a
    streamed WAV's size or a byte rate of 0 turned the check off (a motion a second short was accepted), a size the
    file does not hold made the item a day long, and an empty data chunk refused every team."""

    def short(folder):  # item01's motion a second short of its speech
        m = read_motion(folder / "item01.npz", FPS)
        save_clip(folder / "item01.npz", m.joints[: FRAMES - 30], take.parents, take.names, FPS)

    team = write_team(tmp_path, take, short)
    speech = write_speech(tmp_path / "speech", {i: FRAMES / FPS for i in ITEMS})
    _wav_field(speech / "item01.wav", at, value)
    argv = ["--inputs", str(speech), "--fps", "30", "--out", str(tmp_path / "out"), "--quiet", str(team)]
    assert intake(argv) == code
    if code == 1:
        found = problems(tmp_path / "out")
        assert [(p["item"], p["check"]) for p in found] == [("item01", "length")] and says in found[0]["problem"]
    else:
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "item01.wav" in err[0] and says in err[0], err


@pytest.mark.parametrize(
    "extra, says",
    [
        (b"item\xff4.wav", "a speech file's name is its item's"),
        (b"ITEM04.WAV", "the extension in lower case"),
        (b"item01.flac", "two speech files for item item01"),
    ],
    ids=["not-printable", "upper-case", "wav-and-flac"],
)
def test_a_speech_file_that_names_no_item_plainly_is_refused(tmp_path, take, capsys, extra, says):
    """A released item's speech is never skipped (its item would go unchecked, and a team without it accepted);
    hidden files and other files beside the speech are not items."""
    speech = write_speech(tmp_path / "speech", {i: FRAMES / FPS for i in ITEMS})
    (speech / ".DS_Store").write_bytes(b"\0")
    (speech / "README.txt").write_text("the test items' speech")
    team = write_team(tmp_path, take)
    argv = ["--inputs", str(speech), "--fps", "30", "--out", str(tmp_path / "out"), "--quiet", str(team)]
    assert intake(argv) == 0
    (speech / os.fsdecode(extra)).write_bytes((speech / "item01.wav").read_bytes())
    capsys.readouterr()
    assert intake(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and says in err and "\n" not in err, err


def test_seamless_and_amass_layout_submissions_with_their_body_model(tmp_path):
    """GENEA 2026's formats: Seamless Interaction's smplh:* files (is_valid respected: an invalid frame is a problem)
    and the AMASS/BEAT2 layout (poses, trans, betas), each read through the SMPL-H body model."""
    from helpers import seamless_fixtures
    from helpers.smpl_fixtures import write_body_model, write_motion

    model = write_body_model(tmp_path / "SMPLH_NEUTRAL.npz", "smplh")
    teams = tmp_path / "teams"
    for k, item in enumerate(ITEMS):
        orient, body, left, right, trans = seamless_fixtures.pose_arrays(0, FRAMES)
        valid = np.ones(FRAMES, bool)
        valid[10:15] = k != 1  # item02's frames 10-14 invalid
        (teams / "seamless").mkdir(parents=True, exist_ok=True)
        np.savez(teams / "seamless" / f"{item}.npz", **{"smplh:global_orient": orient, "smplh:body_pose": body.reshape(
            FRAMES, 63), "smplh:left_hand_pose": left.reshape(FRAMES, 45), "smplh:right_hand_pose": right.reshape(
            FRAMES, 45), "smplh:translation": trans, "smplh:is_valid": valid})  # fmt: skip
        (teams / "amass").mkdir(exist_ok=True)
        write_motion(teams / "amass" / f"{item}.npz", "smplh", frames=FRAMES, fps=FPS)
    code, out = run(tmp_path, [], extra=["--teams", str(teams), "--smpl-model", str(model)])
    with open(out / "teams.csv", newline="") as f:
        rows = {r["team"]: r for r in csv.DictReader(f)}
    assert code == 1 and rows["amass"]["verdict"] == "accepted" and rows["seamless"]["verdict"] == "refused"
    assert rows["seamless"]["format"].startswith("Seamless") and rows["amass"]["format"].startswith("SMPL-family")
    (found,) = problems(out, "seamless")
    assert found["check"] == "valid" and found["item"] == "item02" and "frames 10-14" in found["problem"]


def test_what_cannot_be_read_is_its_teams_problem_and_every_team_is_checked(tmp_path, take):
    """A file, a sample folder or a whole team folder the intake may not read (an archive unpacked with its own
    permissions) is one problem in its team's report, said as such; it stopped the whole intake (a folder), or was
    called a file in no format the reader takes (a file)."""
    import subprocess
    import sys

    from helpers.cli import as_a_plain_user
    from helpers.paths import ROOT

    teams = tmp_path / "teams"
    teams.mkdir()
    for name, samples in (("alpha", 1), ("file", 1), ("folder", 2), ("whole", 1)):
        write_team(tmp_path / name, take, samples=samples).rename(teams / name)
    (teams / "file" / "item02.npz").chmod(0)
    (teams / "folder" / "item02").chmod(0)
    (teams / "whole").chmod(0)
    speech = write_speech(tmp_path / "speech", {i: FRAMES / FPS for i in ITEMS})
    out = tmp_path / "out"
    argv = ["--inputs", str(speech), "--fps", "30", "--samples", "2", "--or-one", "--teams", str(teams)]
    cmd = [sys.executable, "-m", "generation.challenge.intake", *argv, "--out", str(out), "--quiet"]
    try:
        r = subprocess.run(as_a_plain_user(cmd), capture_output=True, text=True, cwd=ROOT)
    finally:
        for path in (teams / "whole", teams / "folder" / "item02", teams / "file" / "item02.npz"):
            path.chmod(0o755)  # so that the test's folder can be removed
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    with open(out / "teams.csv", newline="") as f:
        assert {r["team"]: r["verdict"] for r in csv.DictReader(f)} == {
            "alpha": "accepted",
            "file": "refused",
            "folder": "refused",
            "whole": "refused",
        }
    for team, where in (("file", "item02.npz"), ("folder", "item02"), ("whole", "whole/")):
        found = problems(out, team)
        assert [(p["file"], p["check"]) for p in found] == [(where, "read")], found
        assert "cannot be read (Permission denied)" in found[0]["problem"]
