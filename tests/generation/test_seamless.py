"""Seamless Interaction's files read as loaders read them: SMPL-H under `smplh:*` keys (flat or per joint, no betas,
unknown keys ignored), the validity mask, each person in their own camera's frame stood upright, axis-angle flips
near pi moving nothing, word-timed transcripts and VAD; and hostile files (an npz or a JSON that claims or nests
too much) refused in one line with memory flat. Every fixture is written here (tests/helpers/seamless_fixtures.py,
smpl_fixtures.py): the fast tier."""

import io
import json
import os
import zipfile

import numpy as np
import pytest
from helpers import seamless_fixtures, smpl_fixtures
from helpers.memory import peak as _peak
from helpers.own_study_data import NO_GESTURE_MEASURES

from generation.data import transcripts
from generation.data.motion_files import MotionError, read_motion
from generation.data.seamless_files import invalid_spans, parse_name, read_seamless, spans_text
from generation.data.transcripts import TranscriptError, read_transcript
from moglow_eval.core import user_files
from moglow_eval.core.cli import UserError

FLAT = 64 << 20


@pytest.fixture(scope="module")
def conversation(tmp_path_factory):
    return seamless_fixtures.write_conversation(tmp_path_factory.mktemp("seamless") / "raw")


def test_names_tell_the_interaction_and_a_participant_ending_in_a_letter():
    assert parse_name("x/V00_S0809_I00000582_P0947A.npz") == ("V00_S0809_I00000582", "P0947A")
    assert parse_name("V01_S2022_I00001199_P1275.wav") == ("V01_S2022_I00001199", "P1275")
    assert parse_name("item00.npz") is None and parse_name("V00_S1_I2_Pxyz.npz") is None


def test_flat_and_per_joint_layouts_give_the_same_joints(conversation, tmp_path):
    """The first participant's file has flat arrays; the same numbers per joint read the same."""
    src = conversation.files["P0299A"]["motion"]
    arrays = dict(np.load(src))
    frames = len(arrays["smplh:translation"])
    arrays["smplh:body_pose"] = arrays["smplh:body_pose"].reshape(frames, 21, 3)
    arrays["smplh:left_hand_pose"] = arrays["smplh:left_hand_pose"].reshape(frames, 15, 3)
    arrays["smplh:global_orient"] = arrays["smplh:global_orient"].reshape(frames, 1, 3)
    np.savez(tmp_path / "joints.npz", **arrays)
    flat = read_motion(src, 30.0, smpl_model=conversation.model)
    per_joint = read_motion(tmp_path / "joints.npz", 30.0, smpl_model=conversation.model)
    assert np.array_equal(flat.joints, per_joint.joints) and np.array_equal(flat.valid, per_joint.valid)
    assert flat.names[15] == "head" and len(flat.names) == 52


def test_no_betas_means_the_mean_shape(conversation, tmp_path):
    """The joints are the model's at zero shape: as a poses/trans file with zero betas gives them."""
    m = read_seamless(conversation.files["P0301B"]["motion"])
    np.savez(
        tmp_path / "plain.npz", poses=m.poses, trans=m.trans, betas=np.zeros(10), mocap_framerate=30.0
    )  # AMASS layout: no hand mean, as Seamless
    plain = read_motion(tmp_path / "plain.npz", 30.0, smpl_model=conversation.model, up="y")
    seamless = read_motion(conversation.files["P0301B"]["motion"], 30.0, smpl_model=conversation.model, up="y")
    assert np.allclose(plain.joints, seamless.joints, atol=1e-5)


def test_invalid_frames_are_marked_and_never_numbers_of_their_own(conversation):
    m = read_motion(conversation.files["P0299A"]["motion"], 30.0, smpl_model=conversation.model)
    (a, b) = conversation.invalid[0]
    assert invalid_spans(m.valid) == [(a, b)] and spans_text(invalid_spans(m.valid)) == f"{a}-{b}"
    assert np.isfinite(m.joints).all()
    assert np.array_equal(m.joints[a : b + 1], np.repeat(m.joints[a - 1 : a], b + 1 - a, 0))  # held, not invented
    twenty = read_motion(conversation.files["P0299A"]["motion"], 20.0, smpl_model=conversation.model)
    u = np.arange(len(twenty.valid)) * 1.5  # each output frame's place among the input frames
    touches = ((np.floor(u) >= a) & (np.floor(u) <= b)) | ((np.ceil(u) >= a) & (np.ceil(u) <= b))
    assert np.array_equal(~twenty.valid, touches)  # invalid wherever it leans on an invalid frame, nowhere else


def test_a_person_filmed_in_a_cameras_frame_stands_upright(conversation):
    """The second participant is stored Y down; read, the head is above the pelvis, as for the first."""
    for participant in seamless_fixtures.PARTICIPANTS:
        m = read_motion(conversation.files[participant]["motion"], 30.0, smpl_model=conversation.model)
        assert (m.joints[:, 15, 1] - m.joints[:, 0, 1]).min() > 0.4  # head 0.6 m above the pelvis, Y up


def test_an_axis_angle_flip_near_pi_moves_no_joint(tmp_path):
    """A shoulder turning steadily through pi, stored as loaders wrap it (the angle kept below pi by flipping the
    axis), is as smooth after resampling as before: the rotations are posed per frame, never interpolated."""
    frames = 31
    model = smpl_fixtures.write_model(tmp_path / "SMPLH.npz", "smplh")
    angle = np.linspace(2.9, 3.4, frames)
    rotvec = np.zeros((frames, 3))
    rotvec[:, 2] = np.where(angle <= np.pi, angle, angle - 2 * np.pi)  # the same rotations, the axis flipped
    body = np.zeros((frames, 21, 3))
    body[:, 15] = rotvec  # the left shoulder
    arrays = {
        "smplh:global_orient": np.zeros((frames, 3)),
        "smplh:body_pose": body,
        "smplh:left_hand_pose": np.zeros((frames, 45)),
        "smplh:right_hand_pose": np.zeros((frames, 45)),
        "smplh:translation": np.tile([0.0, 0.93, 0.0], (frames, 1)),
        "smplh:is_valid": np.ones(frames, bool),
    }
    np.savez(tmp_path / "V00_S0001_I00000001_P0001A.npz", **arrays)
    m = read_motion(tmp_path / "V00_S0001_I00000001_P0001A.npz", 20.0, smpl_model=model)
    wrist = m.joints[:, 20]  # the left wrist
    step = np.linalg.norm(np.diff(wrist, axis=0), axis=1)
    assert step.max() < 2.0 * np.median(step)  # an interpolated flip would swing the arm through the body


def test_unknown_members_are_never_read(conversation, tmp_path):
    """A `movement:*` member whose header claims 100 GB is left alone: only the smplh:* members are read."""
    src = conversation.files["P0301B"]["motion"]
    path = tmp_path / "V00_S0001_I00000001_P0002A.npz"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(path, "w") as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, zin.read(info.filename))
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, dict(descr="<f4", fortran_order=False, shape=(10**8, 256)))
        zout.writestr("movement:frame_latent.npy", buf.getvalue() + b"\0" * 64)
    raised, peak = _peak(read_motion, path, 30.0, smpl_model=conversation.model)
    assert raised is None and peak < FLAT


def _claiming(path, frames, dtype="<f4"):
    """A Seamless Interaction file whose members' headers claim `frames` frames over a few bytes of data."""
    widths = {"global_orient": (3,), "body_pose": (63,), "left_hand_pose": (45,), "right_hand_pose": (45,)}
    widths.update(translation=(3,), is_valid=())
    with zipfile.ZipFile(path, "w") as z:
        for key, width in widths.items():
            buf = io.BytesIO()
            np.lib.format.write_array_header_1_0(buf, dict(descr=dtype, fortran_order=False, shape=(frames, *width)))
            z.writestr(f"smplh:{key}.npy", buf.getvalue() + b"\0" * 64)
    return path


def test_a_huge_smplh_file_is_refused_with_memory_flat(tmp_path):
    path = _claiming(tmp_path / "V00_S0001_I00000001_P0003A.npz", 10**8, "<f8")  # 90 GB claimed
    raised, peak = _peak(read_seamless, path)
    assert isinstance(raised, Exception) and "100000000 frames; a motion file holds 2 to" in str(raised)
    assert path.name in str(raised) and peak < FLAT
    path = _claiming(tmp_path / "V00_S0001_I00000001_P0004A.npz", 300_000)  # within bounds, but the data is missing
    raised, _ = _peak(read_motion, path, 30.0, smpl_model=tmp_path / "none.npz")
    assert isinstance(raised, MotionError) and "unreadable" in str(raised) and path.name in str(raised)


@pytest.mark.parametrize(
    "edit, needle",
    [
        (lambda a: a.pop("smplh:translation"), "without 'smplh:translation'"),
        (lambda a: a.update({"smplh:body_pose": a["smplh:body_pose"][:, :60]}), "'smplh:body_pose' must be numbers"),
        (lambda a: a.update({"smplh:is_valid": a["smplh:is_valid"][:-3]}), "'smplh:is_valid' has"),
        (lambda a: a.update({"smplh:is_valid": 0 * a["smplh:is_valid"]}), "no valid frame"),
    ],
)
def test_bad_seamless_files_are_one_line_naming_the_key(conversation, tmp_path, edit, needle):
    arrays = dict(np.load(conversation.files["P0299A"]["motion"]))
    edit(arrays)
    path = tmp_path / "V00_S0001_I00000001_P0004A.npz"
    np.savez(path, **arrays)
    with pytest.raises(MotionError, match=str(path.name)) as e:
        read_motion(path, 30.0, smpl_model=conversation.model)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_a_seamless_file_without_a_body_model_says_where_to_get_one(conversation):
    with pytest.raises(MotionError, match="smplh:\\* keys.*licensed and not shipped.*smpl_model"):
        read_motion(conversation.files["P0299A"]["motion"], 30.0)


# ---------------------------------------------------------------- transcripts
def test_a_transcript_has_its_words_and_vad(conversation, tmp_path):
    t = read_transcript(conversation.files["P0299A"]["transcript"])
    first = seamless_fixtures.words_of(seamless_fixtures.TURNS[0])
    assert [(w.text, w.start, w.end) for w in t.words[: len(first)]] == first
    assert t.speech() == [(a, b) for who, a, b, _ in seamless_fixtures.TURNS if who == 0]
    cut = t.cut(10.0, 14.0)
    assert [w.text for w in cut.words] == seamless_fixtures.TURNS[2][3].split()
    assert cut.words[0].start == pytest.approx(0.8) and cut.vad == [(pytest.approx(0.8), pytest.approx(3.6))]
    (tmp_path / "w.tsv").write_text("0.5\t0.9\thello\n1.0\t1.4\tthere\n\n3.0\t3.2\tfriend\n")
    tsv = read_transcript(tmp_path / "w.tsv")
    assert [[w.text for w in s] for s in tsv.segments] == [["hello", "there"], ["friend"]]


@pytest.mark.parametrize(
    "text, needle",
    [
        ('{"metadata:vad": []}', "no 'metadata:transcript' key"),
        ('{"metadata:transcript": [{"start": 0, "end": 1, "words": [{"word": "a", "start": -1, "end": 0}]}]}',
         "metadata:transcript[0].words[0].start: a time must be"),
        ('{"metadata:transcript": [], "metadata:vad": [{"start": 2, "end": 1}]}', "metadata:vad[0]: ends"),
        ('{"metadata:transcript": {"a": 1}}', "metadata:transcript: must be a list"),
        ("[" * 200_000 + "]" * 200_000, "JSON nested deeper than 8 levels"),
        ('{"metadata:transcript": [1e999]}', "must be an object"),
    ],
)  # fmt: skip
def test_bad_transcripts_are_one_line_naming_the_field(tmp_path, text, needle):
    path = tmp_path / "t.json"
    path.write_text(text)
    raised, peak = _peak(read_transcript, path)
    assert isinstance(raised, TranscriptError) and needle in str(raised) and "t.json" in str(raised)
    assert peak < FLAT


def test_a_huge_transcript_is_refused_from_its_size(tmp_path):
    path = tmp_path / "huge.json"
    with open(path, "wb") as f:
        f.write(json.dumps({"metadata:transcript": []}).encode())
        f.truncate(4 << 30)  # sparse: 4 GB that take no disk
    raised, peak = _peak(read_transcript, path)
    assert isinstance(raised, TranscriptError) and "huge.json: 4096.0 MB is larger than a transcript" in str(raised)
    assert peak < FLAT


@pytest.mark.parametrize("kind", ["fifo", "link to a device", "deep", "grows"])
def test_a_transcript_is_refused_as_every_user_json_is(tmp_path, monkeypatch, kind):
    """A transcript goes through moglow_eval.core.user_files like any other user JSON, so it meets the checks on the
    open descriptor and on a file that grows while read: the same one line as read_json's, and never a wait."""
    path = tmp_path / "t.json"
    if kind == "fifo":
        os.mkfifo(path)  # no writer: opening it to read would wait for ever
    elif kind == "link to a device":
        path.symlink_to("/dev/zero")  # a regular name, an endless device behind it
    elif kind == "deep":
        path.write_text('{"metadata:transcript": ' + "[" * 9 + "]" * 9 + "}")
    else:
        # /proc reports a size of 0 and then reads more: a file that grows between the check and the read
        monkeypatch.setattr(transcripts, "MAX_BYTES", 16)
        path.symlink_to("/proc/self/environ")
    with pytest.raises(TranscriptError) as got:
        read_transcript(path)
    with pytest.raises(UserError) as expected:
        user_files.read_json(path, transcripts.MAX_BYTES, what="transcript")
    assert str(got.value) == str(expected.value) and "\n" not in str(got.value)
    needle = {"fifo": "not a regular transcript", "link to a device": "not a regular transcript"}
    needle |= {"deep": "JSON nested deeper than 8 levels", "grows": "grew past 16 bytes while it was read"}
    assert str(got.value).startswith(f"{path}: {needle[kind]}"), got.value


@pytest.mark.full  # a study built: the full tier
def test_a_study_refuses_a_clip_with_invalid_frames_naming_them(conversation, tmp_path, capsys):
    """Seamless files straight into a study of one person: an item whose span crosses invalid frames is one line
    naming the file and the frames, and no stimulus set is written; cut shorter, it builds."""
    import shutil

    from helpers.cli import fails_with

    from generation.make_stimuli import main as make_stimuli

    for sub in ("real", "sys"):
        (tmp_path / sub).mkdir()
        for k, participant in enumerate(seamless_fixtures.PARTICIPANTS):
            shutil.copy(conversation.files[participant]["motion"], tmp_path / sub / f"item{k}.npz")
    (tmp_path / "study.toml").write_text(
        f'reference = "real"\nn_training = 0\n[conditions]\nreal = "real"\nSYS = "sys"\n[catch]\nn = 1\n'
        f'[skeleton]\nsmpl_model = "{conversation.model}"\n' + NO_GESTURE_MEASURES
    )
    a, b = conversation.invalid[0]
    argv = ["--study", str(tmp_path / "study.toml"), "--out", str(tmp_path / "o"), "--quiet", "--size", "64"]
    line = fails_with(make_stimuli, [*argv, "--length-s", "14"], capsys, f"item0.npz: frames {a}-{b} (at 30 fps)")
    assert "marked invalid" in line and not (tmp_path / "o").exists()
    assert make_stimuli([*argv, "--length-s", "4"]) == 0
