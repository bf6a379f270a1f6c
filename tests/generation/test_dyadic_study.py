"""Dyadic and semantic stimulus sets (CONTRACTS §10), built from a conversation in Seamless Interaction's layout that
the test writes and cuts (tests/helpers/seamless_fixtures.py: write_study): the appropriateness folder's shape
(a mismatched clip per system and item, marked by motion_item), two people in every video with the same
interlocutor, sound and byte size across a unit, both voices heard at -23 LUFS, captions on, the keyword
highlighted in both clips of a semantic unit; and bad study files as one line. The full tier."""

import csv
from pathlib import Path

import numpy as np
import pytest
from helpers import figure_pixels, seamless_fixtures
from helpers.cli import fails_with
from helpers.own_study_data import NO_GESTURE_MEASURES
from helpers.voices import decoded_audio, ffmpeg_loudness, voice_energy

from generation.make_stimuli import main as make_stimuli
from rendering.audio import RATE
from rendering.blinding import check_one_size

pytestmark = pytest.mark.full  # two-person sets built and rendered: the full tier (the fast tier stays short)
SIZE = seamless_fixtures.SET_SIZE


def _unit(manifest, item, condition):
    """(matched row, mismatched row) of a test unit."""
    rows = [r for r in manifest if r["item"] == item and r["condition"] == condition and r["role"] == "test"]
    return next(r for r in rows if not r["motion_item"]), next(r for r in rows if r["motion_item"])


def test_a_dyadic_set_has_the_appropriateness_shape(dyadic_set):
    out, manifest, sources = dyadic_set
    tests = {r["item"] for r in manifest if r["role"] == "test"}
    assert tests and all(r["audio"] == "1" for r in manifest)
    for item in tests:
        for cond in seamless_fixtures.SYSTEMS:
            matched, mismatched = _unit(manifest, item, cond)
            assert mismatched["motion_item"] == sources[item]["mismatched"]  # whose interlocutor it was made for
        nat = [r for r in manifest if r["item"] == item and r["condition"] == "NAT" and r["role"] == "test"]
        assert len(nat) == 1 and not nat[0]["motion_item"]  # the study gives no mismatched motion of the real agent
    with open(out / "sources.csv", newline="") as f:
        kept = list(csv.DictReader(f))
    assert {r["item"] for r in kept} == {r["item"] for r in manifest} and "interaction" in kept[0]
    for item in {r["item"] for r in manifest}:
        check_one_size(out / r["video"] for r in manifest if r["item"] == item)


def test_both_videos_of_a_unit_show_the_same_interlocutor_and_sound(dyadic_set):
    out, manifest, _ = dyadic_set
    item = sorted(r["item"] for r in manifest if r["role"] == "test")[0]
    matched, mismatched = _unit(manifest, item, "JITTERY")
    a, b = (out / r["video"] for r in (matched, mismatched))
    assert a.stat().st_size == b.stat().st_size
    assert np.array_equal(decoded_audio(a), decoded_audio(b))
    fa, fb = figure_pixels.decode(a)[0], figure_pixels.decode(b)[0]
    # Where it stands: the same pixels less the encoder's noise at its edges, over the clip, since each video draws
    # its own random rate per frame and one frame of a thin figure can lose much of its edge to the colour test
    # (test_two_people's partner test says more).
    near = figure_pixels.partner_near(fa, fb, range(0, len(fa), 6))
    assert np.mean(near) > 0.9, near  # 0.96 seen; single frames down to 0.79
    for t in (len(fa) // 8, len(fa) // 2, 7 * len(fa) // 8):
        pa, pb = figure_pixels.partner(fa[t]), figure_pixels.partner(fb[t])
        assert figure_pixels.agent(fa[t]).sum() > 60 and pa.sum() > 60  # two figures
        both = pa & pb
        assert np.abs(fa[t][both].mean(0) - fb[t][both].mean(0)).max() < 4  # in the same colour


def test_both_voices_are_heard_at_the_target_loudness(dyadic_set):
    out, manifest, sources = dyadic_set
    row = next(r for r in manifest if r["role"] == "test" and r["condition"] == "NAT")
    sound = decoded_audio(out / row["video"])[:, 0]
    assert abs(ffmpeg_loudness(out / row["video"]) - (-23.0)) <= 1.0
    low, high = (voice_energy(sound, f0) for f0 in seamless_fixtures.VOICE_HZ)
    listener = voice_energy(np.random.default_rng(0).normal(0, 1e-3, len(sound)), seamless_fixtures.VOICE_HZ[0])
    assert high > 100 * listener  # the interlocutor, who speaks in a listening item
    item = row["item"]
    start, end = float(sources[item]["start"]), float(sources[item]["end"])
    speaking = [(a, b) for who, a, b, _ in seamless_fixtures.TURNS if who == 0 and a < end and b > start]
    if speaking:  # the agent's few words in the item are heard too, at speech level
        assert low > 0.01 * high


def test_captions_are_burned_in(dyadic_set):
    out, manifest, sources = dyadic_set
    row = next(r for r in manifest if r["role"] == "test" and r["condition"] == "JITTERY" and not r["motion_item"])
    frames = figure_pixels.decode(out / row["video"])[0]
    words = [(w["start"], w["end"]) for seg in _transcript(out, row["item"], "interlocutor") for w in seg["words"]]
    t = int(round((words[0][0] + 0.1) * 30))
    assert len(figure_pixels.caption_rows(frames[t])) > 0.04 * SIZE
    assert figure_pixels.caption_text(frames[t]).sum() > 40


def _transcript(out, item, who):
    import json

    path = Path(out).parent / "items" / f"{who}_transcript" / f"{item}.json"
    return json.loads(path.read_text())["metadata:transcript"]


def test_a_semantic_unit_shows_the_keyword_in_both_clips(semantic_set):
    out, manifest, sources = semantic_set
    item = sorted(r["item"] for r in manifest if r["role"] == "test")[0]
    matched, mismatched = _unit(manifest, item, "CALM")
    assert mismatched["motion_item"] != item and mismatched["motion_item"] in sources  # another item's motion
    t = int(round((float(sources[item]["keyword_start"]) + 0.05) * 30))
    for row in (matched, mismatched):
        frames = figure_pixels.decode(out / row["video"])[0]
        assert figure_pixels.highlight(frames[t]).sum() > 20 and figure_pixels.partner(frames[t]).sum() > 60
    plain = next(r for r in manifest if r["item"] == item and r["role"] == "test" and r["condition"] == "NAT")
    assert figure_pixels.highlight(figure_pixels.decode(out / plain["video"])[0][t]).sum() > 20


def test_stereo_puts_each_voice_on_its_persons_side(semantic_set):
    out, manifest, _ = semantic_set
    row = next(r for r in manifest if r["role"] == "test" and r["condition"] == "NAT")
    sound = decoded_audio(out / row["video"], channels=2)
    frames = figure_pixels.decode(out / row["video"])[0]
    partner_left = (
        np.nonzero(figure_pixels.partner(frames[0]))[1].mean() < np.nonzero(figure_pixels.agent(frames[0]))[1].mean()
    )
    theirs = [voice_energy(sound[:, c], seamless_fixtures.VOICE_HZ[1]) for c in (0, 1)]
    assert (theirs[0] > 2 * theirs[1]) == partner_left and (theirs[1] > 2 * theirs[0]) == (not partner_left)


# ---------------------------------------------------------------- bad study files
def _bad(tmp_path, capsys, edit, needle, design="dyadic"):
    study = seamless_fixtures.write_study(tmp_path, design)
    edit(study)
    argv = ["--study", str(study), "--out", str(tmp_path / "o"), "--size", "64", "--quiet"]
    fails_with(make_stimuli, argv, capsys, needle)
    assert not (tmp_path / "o").exists()


def _replace(old, new):
    def edit(study):
        study.write_text(study.read_text().replace(old, new))

    return edit


@pytest.mark.parametrize(
    "edit, needle",
    [
        (_replace('CALM = "calm_mismatched"', ""), "[mismatched] CALM: missing"),
        (_replace("[interlocutor]", "[other]"), "unknown key"),
        (_replace('folder = "items/interlocutor"\n', 'folder = "items/interlocutor"\nplacement = "near"\n'),
         "[interlocutor] placement: must be facing or recorded"),
        (_replace('channels = "mono"', 'channels = "surround"'), "[audio] channels: must be mono or stereo"),
        (_replace('folder = "items/interlocutor"\n', 'folder = "items/interlocutor"\ncolour = "green"\n'),
         '[interlocutor] colour: must be "#RRGGBB"'),
    ],
)  # fmt: skip
def test_bad_dyadic_study_files_are_one_line(tmp_path, capsys, edit, needle):
    _bad(tmp_path, capsys, edit, needle)


def test_a_missing_interlocutor_or_transcript_is_one_line(tmp_path, capsys):
    def remove(study):
        next((study.parent / "items" / "interlocutor").iterdir()).unlink()

    _bad(tmp_path / "a", capsys, remove, "no file for item")

    def remove_words(study):
        next((study.parent / "items" / "agent_transcript").iterdir()).unlink()

    _bad(tmp_path / "b", capsys, remove_words, "no transcript for item")


def test_a_semantic_item_whose_keyword_is_not_said_is_one_line(tmp_path, capsys):
    def unsay(study):
        for path in (study.parent / "items" / "agent_transcript").iterdir():
            path.write_text(path.read_text().replace('"bridge"', '"road"'))

    _bad(tmp_path, capsys, unsay, "its keyword (bridge) is not among its words", design="semantic")


def test_an_interlocutor_with_invalid_frames_is_refused_naming_them(tmp_path, capsys):
    def spoil(study):
        path = next((study.parent / "items" / "interlocutor").iterdir())
        arrays = dict(np.load(path))
        arrays["smplh:is_valid"][40:45] = False
        np.savez(path, **arrays)

    _bad(tmp_path, capsys, spoil, "frames 40-44 (at 30 fps) are marked invalid")


@pytest.mark.full  # the demo's takes are ../shared's Bandai-Namco actions
@pytest.mark.parametrize("design", ["dyadic", "semantic"])
def test_the_two_person_demo_builds_with_speech_on_both_tracks(tmp_path, design):
    from generation.own_study.demo_dyad import build

    study = build(tmp_path / "demo", n_items=2, design=design)  # a training item and a test item
    argv = ["--study", str(study), "--out", str(tmp_path / "out"), "--size", "192", "--quiet", "--workers", "1"]
    assert make_stimuli(argv) == 0
    with open(tmp_path / "out" / "manifest.csv", newline="") as f:
        manifest = list(csv.DictReader(f))
    tests = {r["item"] for r in manifest if r["role"] == "test"}
    for item in tests:  # every condition, the real agent's too, has its mismatched clip
        for cond in ("NAT", "SMOOTH", "TREMBLE"):
            assert _unit(manifest, item, cond)[1]["motion_item"] != item
    row = next(r for r in manifest if r["role"] == "test")
    sound = decoded_audio(tmp_path / "out" / row["video"])[:, 0]
    words = {who: json_words(tmp_path / "demo" / f"{who}_transcript" / f"{row['item']}.json")
             for who in ("agent", "interlocutor")}  # fmt: skip
    for who, spans in words.items():  # each voice is heard where its words are, and quiet before the first
        assert spans, who
        level = lambda a, b: np.sqrt(np.mean(sound[int(a * RATE) : int(b * RATE)] ** 2))  # noqa: E731
        assert level(*spans[0]) > 0.01
    assert abs(ffmpeg_loudness(tmp_path / "out" / row["video"]) - (-23.0)) <= 1.0


def json_words(path):
    import json

    return [(w["start"], w["end"]) for seg in json.loads(path.read_text())["metadata:transcript"] for w in seg["words"]]


def test_a_genea_2023_pair_of_bvh_files_builds(tmp_path):
    """GENEA 2023's layout: the main agent and its interlocutor as BVH (Talking With Hands' skeleton), a system's
    motion for each and for a mismatched interlocutor as BVH, the words as TSV: both people in every video, the
    captions on, the manifest in the dyadic shape."""
    from helpers.bvh_fixtures import SPEAKER, write_family

    folders = ("main", "inter", "sys", "sys_mis", "audio_main", "audio_inter", "tsv")
    for sub in folders:
        (tmp_path / sub).mkdir()
    for k in range(4):
        item = f"seg{k:02d}"
        for sub, seed in (("main", k), ("inter", 50 + k), ("sys", 100 + k), ("sys_mis", 150 + k)):
            write_family(tmp_path / sub / f"{item}.bvh", "genea", 90, 30.0, seed, turns=SPEAKER, degrees=8.0)
        for sub, who in (("audio_main", 0), ("audio_inter", 1)):
            seamless_fixtures.write_wav(tmp_path / sub / f"{item}.wav", seamless_fixtures.voice(who, 3.5))
        (tmp_path / "tsv" / f"{item}.tsv").write_text("0.6\t0.9\tso\n1.0\t1.4\tthe\n1.5\t2.0\tbridge\n")
    (tmp_path / "study.toml").write_text(
        'reference = "NA"\ndesign = "dyadic"\nn_training = 1\n[conditions]\nNA = "main"\nSYS = "sys"\n'
        '[mismatched]\nSYS = "sys_mis"\n[interlocutor]\nfolder = "inter"\n[catch]\nn = 1\n'
        '[audio]\nfolder = "audio_main"\ninterlocutor = "audio_inter"\n[captions]\nfolder = "tsv"\n'
        + NO_GESTURE_MEASURES  # the layout is the subject; the two-person demo's builds measure
    )
    argv = ["--study", str(tmp_path / "study.toml"), "--out", str(tmp_path / "out"), "--size", "192", "--quiet"]
    assert make_stimuli([*argv, "--workers", "1"]) == 0
    with open(tmp_path / "out" / "manifest.csv", newline="") as f:
        manifest = list(csv.DictReader(f))
    item = next(r["item"] for r in manifest if r["role"] == "test")
    matched, mismatched = _unit(manifest, item, "SYS")
    assert mismatched["motion_item"] == "?"  # the study file does not say whose interlocutor it had
    frames = figure_pixels.decode(tmp_path / "out" / matched["video"])[0]
    t = int(1.2 * 30)
    assert figure_pixels.agent(frames[t]).sum() > 60 and figure_pixels.partner(frames[t]).sum() > 60
    assert len(figure_pixels.caption_rows(frames[t])) > 0.04 * SIZE
