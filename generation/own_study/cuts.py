"""Where to cut items in a conversation: by who speaks (VAD, else the transcript's segments), the words and the
valid frames of both people (generation.own_study.conversations, the command, writes them).

Each mode proposes a start per speech event and scores it:
- `speaking`: an item starting `margin` before each of the agent's speech intervals; it needs the agent speaking
  at least SPEAK_SHARE of it; scored by the agent's share less the other's;
- `listening`: an item starting `margin` before each of the other person's speech intervals; it needs the other
  speaking at least LISTEN_SHARE and the agent at most LISTENER_MOST; scored by the other's share less the
  agent's;
- `keyword`: an item centred on each time the agent says a keyword, moved so that the word lies at least
  `margin` inside it; scored by how close to the centre the word stays.
A proposal is kept only where both people's motion is valid over the item and `margin` beyond either end, inside
the recording. The best are taken first, at most N an interaction, none overlapping another in time.
"""

import math
import re
from dataclasses import dataclass

import numpy as np

from moglow_eval.core.cli import UserError
from moglow_eval.core.tables import read_csv

from ..stimuli.files import write_csv

MODES = ("speaking", "listening", "keyword")
SPEAK_SHARE = 0.5  # speaking: the least share of the item the agent speaks
LISTEN_SHARE = 0.5  # listening: the least share of the item the other person speaks
LISTENER_MOST = 0.2  # listening: the most share of the item the agent speaks (backchannels, a short answer)


@dataclass
class Speaker:
    participant: str
    path: object  # the motion file; its .wav and .json beside it
    valid: np.ndarray  # [T] bool
    fps: float
    transcript: object  # generation.data.transcripts.Transcript


@dataclass
class Cut:
    item: str
    mode: str
    interaction: str
    agent: str
    interlocutor: str
    start: float  # seconds into the recording (start_frame / fps)
    start_frame: int
    frames: int
    fps: float
    score: float
    keyword: str = ""
    keyword_span: tuple = ()  # (start, end) s into the item

    @property
    def end(self):
        return self.start + self.frames / self.fps

    def row(self, mismatched=""):
        """The item's row of sources.csv."""
        return source_row(
            self.item, self.mode, self.interaction, (self.agent, self.interlocutor), (self.start, self.end),
            self.keyword, self.keyword_span, mismatched,
        )  # fmt: skip


# sources.csv (CONTRACTS §10): where each item was cut from, its keyword and span, and the item whose interlocutor
# is its mismatched one. The cutter and the two-person demo both write it through write_sources.
SOURCE_COLUMNS = (
    "item", "mode", "interaction", "agent", "interlocutor", "start", "end", "keyword", "keyword_start",
    "keyword_end", "mismatched",
)  # fmt: skip


def source_row(item, mode, interaction, people, span, keyword="", keyword_span=(), mismatched=""):
    """An item's row of sources.csv: `people` (agent, interlocutor) as named in the recording, `span` (start, end)
    and `keyword_span` (start, end; empty for none) in seconds, written to the millisecond."""
    times = [f"{t:.3f}" for t in span]
    key = [f"{t:.3f}" for t in keyword_span] or ["", ""]
    return dict(zip(SOURCE_COLUMNS, (item, mode, interaction, *people, *times, keyword, *key, mismatched)))


def write_sources(path, rows):
    """sources.csv at `path`, rows from source_row."""
    write_csv(path, SOURCE_COLUMNS, rows)


def share(intervals, a, b):
    """The share of [a, b) covered by `intervals` [(start, end)] (assumed not to overlap one another)."""
    return sum(max(0.0, min(e, b) - max(s, a)) for s, e in intervals) / (b - a)


def plain(word):
    """A word for matching: lower case, without punctuation around it."""
    return re.sub(r"^\W+|\W+$", "", word.lower())


def keyword_table(path):
    """{(interaction, participant): {keywords}} from a CSV with columns interaction, keyword and optionally
    participant (empty or absent: either participant); None for no path."""
    if path is None:
        return None
    path, df = read_csv(path, UserError)
    missing = [c for c in ("interaction", "keyword") if c not in df.columns]
    if missing:
        raise UserError(f"{path}: missing column {missing[0]} (expected interaction, participant, keyword)")
    out = {}
    for line, row in df.iterrows():
        word = plain(row["keyword"])
        if not word:
            raise UserError(f"{path}:{line}: empty keyword")
        out.setdefault((row["interaction"].strip(), row.get("participant", "").strip()), set()).add(word)
    return out


def _proposals(mode, agent, other, length, margin, wanted):
    """[(start s, score, keyword, (word start, word end) s from the recording's start)] of one agent."""
    mine, theirs = agent.transcript.speech(), other.transcript.speech()
    out = []
    if mode == "keyword":
        for w in agent.transcript.words:
            if plain(w.text) not in wanted:
                continue
            lo, hi = w.end + margin - length, w.start - margin  # the word at least `margin` inside the item
            if lo > hi:
                continue
            mid = (w.start + w.end) / 2
            start = min(max(mid - length / 2, lo), hi)
            # the keyword as the user's file names it (sources.csv, the semantic design's highlight), not "glacier."
            out.append((start, 1.0 - abs(start + length / 2 - mid) / length, plain(w.text), (w.start, w.end)))
        return out
    events = mine if mode == "speaking" else theirs
    for a, _ in events:
        start = a - margin
        me, you = share(mine, start, start + length), share(theirs, start, start + length)
        if mode == "speaking" and me >= SPEAK_SHARE:
            out.append((start, me - you, "", ()))
        elif mode == "listening" and you >= LISTEN_SHARE and me <= LISTENER_MOST:
            out.append((start, you - me, "", ()))
    return out


def _valid_span(speakers, start, frames, margin):
    """Whether every speaker's motion is valid over frames [start - margin, start + frames + margin)."""
    a, b = start - margin, start + frames + margin
    return all(a >= 0 and b <= len(s.valid) and bool(s.valid[a:b].all()) for s in speakers)


def _is_agent(participant, wanted):
    return wanted is None or participant == wanted or (len(wanted) == 1 and participant.endswith(wanted))


def choose_items(interaction, pair, mode, length, margin, most, agent=None, keywords=None):
    """The items of one interaction (Cut, in time order): the best proposals of each participant as the agent,
    where both people's motion is valid, at most `most`, none overlapping another."""
    proposals = []
    for me, speaker in pair.items():
        if not _is_agent(me, agent):
            continue
        other_id, other = next((p, s) for p, s in pair.items() if p != me)
        wanted = None
        if mode == "keyword":
            wanted = keywords.get((interaction, me), set()) | keywords.get((interaction, ""), set())
            if not wanted:
                continue
        fps = speaker.fps
        frames, pad = int(round(length * fps)), int(math.ceil(margin * fps))
        for start, score, word, span in _proposals(mode, speaker, other, length, margin, wanted):
            first = int(round(start * fps))
            if _valid_span((speaker, other), first, frames, pad):
                item = f"{interaction}_{me}_{int(round(first / fps * 1000)):07d}"
                where = tuple(t - first / fps for t in span)
                proposals.append(Cut(item, mode, interaction, me, other_id, first / fps, first, frames, fps, score,
                                     word, where))  # fmt: skip
    taken = []
    for c in sorted(proposals, key=lambda c: (-c.score, c.start, c.agent)):
        if len(taken) < most and all(c.end <= t.start or c.start >= t.end for t in taken):
            taken.append(c)
    return sorted(taken, key=lambda c: c.start)
