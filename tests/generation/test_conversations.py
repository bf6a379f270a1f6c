"""Items cut from conversations (`python -m generation.own_study.conversations`): listening, speaking and keyword
items from a Seamless-Interaction-layout conversation the test writes (tests/helpers/seamless_fixtures.py), who is
the agent told by the voices and never by file order, invalid frames kept out with their margins, at most N items
an interaction and none overlapping, the sources table, the mismatched interlocutors, and bad input as one line
with nothing left behind. The fast tier."""

import csv
import json
import shutil

import numpy as np
import pytest
from helpers import seamless_fixtures
from helpers.cli import fails_with

from generation.data.seamless_files import read_seamless
from generation.own_study.conversations import main as conversations
from generation.own_study.cuts import LISTEN_SHARE, LISTENER_MOST, SPEAK_SHARE, share
from rendering.audio import RATE, read_audio

FIRST, SECOND = seamless_fixtures.PARTICIPANTS
OTHER = "V00_S0001_I00000002"


@pytest.fixture(scope="module")
def raw(tmp_path_factory):
    """Two interactions: the fixture's, and one whose participants are named the other way round in file order
    (the second interaction's first speaker sorts last)."""
    root = tmp_path_factory.mktemp("conversations")
    conv = seamless_fixtures.write_conversation(root / "raw" / "a")
    seamless_fixtures.write_conversation(
        root / "raw" / "b", interaction=OTHER, participants=("P0777Z", "P0100Q"), model=False
    )
    return conv


def _cut(raw, tmp_path, *flags):
    out = tmp_path / "items"
    assert conversations([str(raw.folder.parent), "--out", str(out), "--quiet", "--length-s", "4", *flags]) == 0
    with open(out / "sources.csv", newline="") as f:
        return out, list(csv.DictReader(f))


def _speech(who, turns=seamless_fixtures.TURNS):
    return [(a, b) for speaker, a, b, _ in turns if speaker == who]


def _index(interaction, participant):
    names = seamless_fixtures.PARTICIPANTS if interaction == seamless_fixtures.INTERACTION else ("P0777Z", "P0100Q")
    return names.index(participant)


def test_listening_items_are_where_the_other_speaks_and_the_agent_listens(raw, tmp_path):
    out, rows = _cut(raw, tmp_path, "--mode", "listening", "--per-interaction", "3")
    assert rows and {r["mode"] for r in rows} == {"listening"}
    for r in rows:
        a, b = float(r["start"]), float(r["end"])
        assert b - a == pytest.approx(4.0)
        agent, other = _index(r["interaction"], r["agent"]), _index(r["interaction"], r["interlocutor"])
        assert {agent, other} == {0, 1}
        assert share(_speech(other), a, b) >= LISTEN_SHARE and share(_speech(agent), a, b) <= LISTENER_MOST
    # who is the agent follows the voices, not the file order: the second interaction's first speaker sorts last
    agents = {(r["interaction"], r["agent"]) for r in rows}
    assert (seamless_fixtures.INTERACTION, FIRST) in agents and (OTHER, "P0777Z") in agents


def test_speaking_items_keep_out_invalid_frames_with_their_margins(raw, tmp_path):
    out, rows = _cut(raw, tmp_path, "--mode", "speaking", "--per-interaction", "5", "--margin-s", "0.5")
    a, b = raw.invalid[0]
    bad = (a / 30.0 - 0.5, (b + 1) / 30.0 + 0.5)
    for r in rows:
        start, end = float(r["start"]), float(r["end"])
        assert share(_speech(_index(r["interaction"], r["agent"])), start, end) >= SPEAK_SHARE
        if r["interaction"] == seamless_fixtures.INTERACTION:
            assert end <= bad[0] or start >= bad[1], r  # the first speaker's third turn crosses the invalid frames
    spans = {}
    for r in rows:
        spans.setdefault(r["interaction"], []).append((float(r["start"]), float(r["end"])))
    for interaction, items in spans.items():
        items.sort()
        assert len(items) <= 5 and all(x[1] <= y[0] for x, y in zip(items, items[1:]))  # none overlapping
    assert not any(r["start"] == "10.300" and r["interaction"] == seamless_fixtures.INTERACTION for r in rows)


def test_item_files_are_the_span_of_each_person(raw, tmp_path):
    out, rows = _cut(raw, tmp_path, "--mode", "listening", "--per-interaction", "1")
    r = next(r for r in rows if r["interaction"] == seamless_fixtures.INTERACTION)
    item, start = r["item"], float(r["start"])
    first = int(round(start * 30))
    cut = read_seamless(out / "agent" / f"{item}.npz")
    whole = read_seamless(raw.files[r["agent"]]["motion"])
    assert np.array_equal(cut.poses, whole.poses[first : first + 120]) and cut.valid.all()
    sound = read_audio(out / "interlocutor_audio" / f"{item}.wav")
    source = read_audio(raw.files[r["interlocutor"]]["audio"], 4.0, start_s=start)
    assert len(sound) == 4 * RATE and np.abs(sound - source).max() < 1e-3
    words = json.loads((out / "interlocutor_transcript" / f"{item}.json").read_text())["metadata:transcript"]
    assert words and all(0 <= w["start"] <= w["end"] <= 4.0 for seg in words for w in seg["words"])


def test_keyword_items_hold_the_word_inside_their_margins(raw, tmp_path):
    table = tmp_path / "keywords.csv"
    table.write_text(f"interaction,participant,keyword\n{seamless_fixtures.INTERACTION},{FIRST},Bridge\n")
    out, rows = _cut(raw, tmp_path, "--mode", "keyword", "--keywords", str(table), "--per-interaction", "5")
    assert len(rows) == 2 and all(r["keyword"] == "bridge" and r["agent"] == FIRST for r in rows)
    for r in rows:
        assert 0.5 <= float(r["keyword_start"]) < float(r["keyword_end"]) <= 3.5


def test_mismatched_interlocutors_come_from_another_interaction(raw, tmp_path):
    out, rows = _cut(raw, tmp_path, "--mode", "listening", "--mismatched")
    by_item = {r["item"]: r for r in rows}
    for r in rows:
        other = by_item[r["mismatched"]]
        assert other["interaction"] != r["interaction"]
        mine = read_seamless(out / "mismatched_interlocutor" / f"{r['item']}.npz")
        theirs = read_seamless(out / "interlocutor" / f"{other['item']}.npz")
        assert np.array_equal(mine.poses, theirs.poses)


def test_an_interaction_with_too_few_valid_frames_is_passed_over(raw, tmp_path, capsys):
    only = tmp_path / "only"
    shutil.copytree(raw.folder, only)
    argv = [str(only), "--out", str(tmp_path / "o"), "--mode", "listening", "--min-valid", "0.99", "--quiet"]
    assert conversations(argv) == 2 and not (tmp_path / "o").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"{seamless_fixtures.INTERACTION}: passed over: {FIRST} has 98% of its frames valid (--min-valid)",
        "error: no item of 8 s in listening mode in 1 interaction(s)",
    ]


@pytest.mark.parametrize(
    "damage, needle",
    [
        (lambda f: f.with_suffix(".wav").unlink(), "no V00_S0001_I00000001_P0299A.wav beside it"),
        (lambda f: f.unlink(), "1 participant(s)"),
        (lambda f: f.with_suffix(".json").write_text("[" * 100_000), "JSON nested deeper than"),
        (lambda f: f.with_suffix(".json").write_text('{"metadata:transcript": 3}'), "transcript: must be a list"),
        (lambda f: seamless_fixtures.write_wav(f.with_suffix(".wav"), np.zeros(RATE)), "ends at 1.00 s, before its"),
    ],
)  # fmt: skip
def test_bad_conversations_are_one_line_and_leave_nothing(raw, tmp_path, capsys, damage, needle):
    folder = tmp_path / "raw"
    shutil.copytree(raw.folder, folder)
    damage(folder / f"{seamless_fixtures.stem(FIRST)}.npz")
    argv = [str(folder), "--out", str(tmp_path / "o"), "--mode", "listening", "--quiet"]
    fails_with(conversations, argv, capsys, needle)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["raw"]  # no items folder, no half-written one beside it


def test_an_existing_item_folder_is_replaced_only_with_force(raw, tmp_path, capsys):
    (tmp_path / "items").mkdir()
    (tmp_path / "items" / "keep.txt").write_text("mine")
    argv = [str(raw.folder), "--out", str(tmp_path / "items"), "--mode", "listening", "--quiet"]
    fails_with(conversations, argv, capsys, "already exists; give --force")
    # a folder this command did not write is not its to remove, --force or not (it removed `--out .` whole)
    fails_with(conversations, [*argv, "--force"], capsys, "not a folder of items this command wrote")
    assert (tmp_path / "items" / "keep.txt").read_text() == "mine"
    ours = [str(raw.folder), "--out", str(tmp_path / "ours"), "--mode", "listening", "--quiet"]
    assert conversations(ours) == 0
    (tmp_path / "ours" / "stale.txt").write_text("an earlier cut's")
    fails_with(conversations, ours, capsys, "already exists; give --force")
    assert conversations([*ours, "--force"]) == 0 and not (tmp_path / "ours" / "stale.txt").exists()
    # nor the folder that holds the recordings, though it has a sources.csv
    shutil.copytree(raw.folder, tmp_path / "ours" / "raw")
    inner = [str(tmp_path / "ours" / "raw"), "--out", str(tmp_path / "ours"), "--mode", "listening", "--quiet"]
    fails_with(conversations, [*inner, "--force"], capsys, "holds the recordings' folder")
    assert (tmp_path / "ours" / "raw").is_dir()


def test_a_keyword_said_with_punctuation_is_written_as_the_keyword_file_names_it():
    """Issue 65: a word said at a sentence's end ("glacier.") matched the keyword file's "glacier" but went into
    sources.csv with its full stop."""
    from types import SimpleNamespace

    from generation.data.transcripts import Transcript, Word
    from generation.own_study.cuts import _proposals

    said = Transcript([[Word(3.0, 3.2, "the"), Word(3.2, 3.8, "Glacier.")]])
    agent, other = SimpleNamespace(transcript=said), SimpleNamespace(transcript=Transcript([]))
    ((_, _, keyword, span),) = _proposals("keyword", agent, other, 4.0, 0.5, {"glacier"})
    assert keyword == "glacier" and span == (3.2, 3.8)


def test_a_transcripts_control_characters_never_reach_the_captions(tmp_path):
    """Issue 65: a word with a NUL and a terminal escape stopped the build with raqm_layout's traceback."""
    import json

    import numpy as np

    from generation.data.transcripts import TRANSCRIPT_KEY, read_transcript
    from rendering.captions import CaptionLayer, phrases

    word = dict(word="a\x00b\x1b[31m", start=0.1, end=0.5, score=1.0)
    path = tmp_path / "t.json"
    path.write_text(json.dumps({TRANSCRIPT_KEY: [dict(start=0.1, end=0.5, transcript="x", words=[word])]}))
    assert [w.text for w in read_transcript(path).words] == ["ab"]
    size = 96
    layer = CaptionLayer(phrases([(0.1, 0.5, "a\x00b\x1b[31m\u202e", False)], size), size)
    frame = np.zeros(size * size * 3 // 2, np.uint8)  # a yuv420p frame, flat
    layer.apply(frame, 0.2)  # drawn, no traceback
    assert frame.any()
