"""Sound in the stimuli (issue 32): audio per item in every condition's video, in sync, loudness-normalised, and
still blind."""

import csv
import re
import subprocess
import wave

import imageio_ffmpeg
import numpy as np
import pytest
from helpers.own_study_data import NO_GESTURE_MEASURES, action_takes, make_study, speech

from generation.data.motion_files import read_motion
from generation.make_stimuli import main as make_stimuli
from rendering.audio import RATE, integrated_loudness, mux_audio, read_audio
from rendering.render import RenderOptions, render_clip

pytestmark = pytest.mark.full  # the full tier: studies built from the real actions in ../shared

FFMPEG = imageio_ffmpeg.get_ffmpeg_exe()


def _decoded_audio(mp4):
    """The MP4's audio as decoded by ffmpeg: mono float32 at RATE, from the file's time 0."""
    out = subprocess.run(
        [FFMPEG, "-v", "error", "-i", str(mp4), "-map", "0:a", "-ac", "1", "-ar", str(RATE), "-f", "f32le", "-"],
        capture_output=True,
        check=True,
    )
    return np.frombuffer(out.stdout, "<f4")


def _ffmpeg_loudness(mp4):
    err = subprocess.run(
        [FFMPEG, "-nostats", "-i", str(mp4), "-map", "0:a", "-af", "ebur128", "-f", "null", "-"],
        capture_output=True,
        text=True,
    ).stderr
    return float(re.findall(r"I:\s+(-?[\d.]+) LUFS", err)[-1])


def _write_wav(path, samples, rate=RATE):
    pcm = (np.clip(samples, -1, 1) * 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(rate)
        w.writeframes(pcm.tobytes())


def test_click_at_a_known_frame_is_heard_at_that_frame(tmp_path):
    m = read_motion(action_takes(1)[0], fps=20.0)
    joints = m.joints[:60]
    clip = dict(joints=joints, parents=m.parents, joint_names=m.names, fps=20.0)
    frame = 23
    samples = np.zeros(int(3.5 * RATE), np.float32)
    at = int(frame / 20.0 * RATE)
    samples[at : at + 48] = 0.9  # a 1-ms click
    video = tmp_path / "clip.mp4"
    render_clip(clip, video, RenderOptions(size=96))
    mux_audio(video, samples[:, None], 0.0, len(joints) / 20.0)
    heard = np.argmax(np.abs(_decoded_audio(video))) / RATE
    assert abs(heard - frame / 20.0) <= 1 / 20.0


@pytest.fixture(scope="module")
def sound_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("sound")
    # The gesture measures are not this module's subject: no gesture encoder to train.
    study = make_study(root / "in", n_items=4, n_catch=2, audio=True, extra_toml=NO_GESTURE_MEASURES)
    assert make_stimuli(["--study", str(study), "--out", str(root / "out"), "--size", "96", "--quiet"]) == 0
    with open(root / "out" / "manifest.csv", newline="") as f:
        return root / "out", list(csv.DictReader(f))


def test_every_video_carries_its_items_sound_the_same_in_every_condition(sound_study):
    out, manifest = sound_study
    streams = {}
    for r in manifest:
        md5 = subprocess.run(
            [FFMPEG, "-v", "error", "-i", str(out / r["video"]), "-map", "0:a", "-c", "copy", "-f", "md5", "-"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        streams.setdefault(r["item"], set()).add(md5)
    assert all(len(v) == 1 for v in streams.values())  # nothing in the audio differs by condition or role
    assert len({next(iter(v)) for v in streams.values()}) == 4  # each item its own


def test_set_stays_blind_with_sound(sound_study):
    """Every video of an item (every condition and role: test, catch copies, BAD, mismatched) is one byte size,
    with the same boxes and frame sizes (rendering.blinding), and every file of the set has one time stamp. Items
    differ in length and sound, so their sizes differ: a size names an item, never a condition or a role."""
    from rendering.blinding import check_one_size

    out, manifest = sound_study
    by_item = {}
    for r in manifest:
        by_item.setdefault(r["item"], []).append(out / r["video"])
    for videos in by_item.values():
        check_one_size(videos)  # raises naming the video whose sizes differ
    assert len({(out / r["video"]).stat().st_mtime for r in manifest}) == 1


def test_loudness_is_normalised_to_the_target(sound_study):
    out, manifest = sound_study
    for r in manifest[:6]:
        assert abs(_ffmpeg_loudness(out / r["video"]) - (-23.0)) <= 1.0


def test_our_loudness_meter_agrees_with_ffmpegs(tmp_path):
    wav = speech(tmp_path / "s.wav", "one two three four five", 3.0)
    err = subprocess.run(
        [FFMPEG, "-nostats", "-i", str(wav), "-af", "ebur128", "-f", "null", "-"], capture_output=True, text=True
    ).stderr
    assert integrated_loudness(read_audio(wav)) == pytest.approx(
        float(re.findall(r"I:\s+(-?[\d.]+) LUFS", err)[-1]), abs=0.15
    )


# ---------------------------------------------------------------- bad audio
def _fails(study, tmp_path, capsys, needle):
    rc = make_stimuli(["--study", str(study), "--out", str(tmp_path / "out"), "--size", "64", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1].startswith("error: ") and needle in err[-1], err
    assert not (tmp_path / "out" / "manifest.csv").exists()


def test_audio_shorter_than_its_clip(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0, audio=True)
    _write_wav(study.parent / "audio" / "item01.wav", 0.1 * np.sin(np.arange(RATE) * 0.05))  # 1 s
    _fails(study, tmp_path, capsys, "item01.wav: the audio is 1.00 s, shorter than the item's clips")


def test_unreadable_audio(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0, audio=True)
    (study.parent / "audio" / "item01.wav").write_bytes(b"RIFF\x10\x00\x00\x00WAVEjunkjunkjunk")
    _fails(study, tmp_path, capsys, "item01.wav")


def test_silent_audio_where_speech_is_needed(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0, audio=True)
    _write_wav(study.parent / "audio" / "item01.wav", np.zeros(20 * RATE))
    _fails(study, tmp_path, capsys, "item01.wav: silent over the clip")


def test_sample_rate_of_zero(tmp_path, capsys):
    study = make_study(tmp_path / "s", n_items=2, n_catch=0, audio=True)
    path = study.parent / "audio" / "item01.wav"
    raw = bytearray(path.read_bytes())
    raw[24:28] = (0).to_bytes(4, "little")  # the fmt chunk's sample rate
    path.write_bytes(bytes(raw))
    _fails(study, tmp_path, capsys, "item01.wav: the sample rate is 0")


@pytest.mark.full  # a whole study through the demo; the app side of sound: rating_app/test_sound, test_browser_sound
def test_demo_runs_the_appropriateness_design_with_sound(tmp_path):
    """`python -m analysis.demo --design appropriateness`: a study with synthesised speech (own_study.demo_study)
    -> stimuli with sound and mismatched clips -> the app with its sound check -> the simulated crowd -> pairs.csv
    -> the MAS report."""
    import json
    import subprocess
    import sys

    out = tmp_path / "demo"
    # A small study of small videos: the sound, the crowd and the report are checked here, not the pictures.
    cmd = [sys.executable, "-m", "analysis.demo", "--out", str(out), "--design", "appropriateness", "--size", "128"]
    cmd += ["--items", "6"]
    r = subprocess.run([*cmd, "--raters", "60", "--ratings-per-clip", "6"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    stats = json.loads((out / "report" / "stats.json").read_text())
    # the reference under the study file's own name ("real"), from the export's reference_name
    assert stats["design"] == "appropriateness" and set(stats["mas"]) == {"real", "SMOOTH", "TREMBLE"}
    assert stats["mas"]["real"]["mas"] > 0 and stats["mas"]["real"]["ci_low"] > 0  # real motion fits its speech
    with open(out / "pairs.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {r["matched"] for r in rows if r["role"] == "test"} == {"a", "b"}
    assert all(r["mismatched_item"] and r["mismatched_item"] != r["item"] for r in rows if r["role"] == "test")
