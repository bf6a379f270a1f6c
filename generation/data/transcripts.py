"""Word-timed transcripts and voice activity: Seamless Interaction's JSON and GENEA 2023's TSV, read within bounds.

- Seamless Interaction's `.json` beside each participant's motion: `metadata:transcript`, a list of segments
  (`start`, `end`, `transcript` and `words`, each word `word`, `start`, `end` and a `score`), and `metadata:vad`,
  a list of speech intervals (`start`, `end`), in seconds from the recording's start. Other keys are ignored.
- GENEA 2023's `.tsv`: a word a line, `start<TAB>end<TAB>word`, in seconds.

A transcript is a list of words in time order, grouped into segments (a TSV's words make one segment a pause
apart), and the speech intervals (the VAD's where the file has them, else the words' spans). Times may be cut
to a span and shifted (`Transcript.cut`) and written back in Seamless's layout, so an item cut from a
conversation carries its own transcript.

Bounds: the file is read as every user's file is (moglow_eval.core.user_files): only a regular file, refused from
its size over MAX_BYTES before it is read and cut off should it grow past it while read; JSON nested deeper than
user_files.MAX_JSON_DEPTH is one line before any parser recurses, and so is any value of the wrong type, a time
that is negative, not finite or beyond MAX_TIME_S, a word longer than MAX_WORD_CHARS, or more than MAX_WORDS
words. Each problem names the file and the field.
"""

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from moglow_eval.core import user_files
from moglow_eval.core.cli import UserError

MAX_BYTES = 32 << 20  # a transcript of hours of speech is a few MB
MAX_WORDS = 500_000
MAX_TIME_S = 1e6
MAX_WORD_CHARS = 100
TRANSCRIPT_KEY = "metadata:transcript"
VAD_KEY = "metadata:vad"
EXTENSIONS = (".json", ".tsv")
TSV_PAUSE_S = 1.0  # a pause that starts a new segment of a TSV transcript


class TranscriptError(UserError):
    """A transcript that cannot be read; the message names the file and the field."""


@dataclass(frozen=True)
class Word:
    start: float
    end: float
    text: str


@dataclass
class Transcript:
    segments: list  # [[Word, ...], ...] in time order
    vad: list = field(default_factory=list)  # [(start, end)] speech intervals, possibly empty
    path: str = ""

    @property
    def words(self):
        return [w for seg in self.segments for w in seg]

    def speech(self):
        """The speech intervals: the VAD's, else each segment's span."""
        if self.vad:
            return list(self.vad)
        return [(seg[0].start, seg[-1].end) for seg in self.segments if seg]

    def cut(self, start, stop):
        """The words whose middle falls in [start, stop) and the speech clipped to it, times from `start`."""
        segments = []
        for seg in self.segments:
            kept = [
                Word(max(w.start - start, 0.0), min(w.end, stop) - start, w.text)
                for w in seg
                if start <= (w.start + w.end) / 2 < stop
            ]
            if kept:
                segments.append(kept)
        vad = [(max(a, start) - start, min(b, stop) - start) for a, b in self.vad if b > start and a < stop]
        return Transcript(segments, vad, self.path)

    def to_json(self, ident=""):
        """Seamless Interaction's layout (`metadata:transcript`, `metadata:vad`), as a dict for json.dump."""
        return {
            "id": ident,
            TRANSCRIPT_KEY: [
                {
                    "start": round(seg[0].start, 3),
                    "end": round(seg[-1].end, 3),
                    "transcript": " ".join(w.text for w in seg),
                    "words": [dict(word=w.text, start=round(w.start, 3), end=round(w.end, 3)) for w in seg],
                }
                for seg in self.segments
            ],
            VAD_KEY: [dict(start=round(a, 3), end=round(b, 3)) for a, b in self.vad],
        }


def _text(path):
    """The file's text, read as every user's file is (moglow_eval.core.user_files: a regular file only, checked on
    the open descriptor, its size capped before and while it is read)."""
    return user_files.read_text(path, MAX_BYTES, TranscriptError, "transcript")


def _time(path, where, value):
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or not 0 <= value <= MAX_TIME_S:
        raise TranscriptError(f"{path}: {where}: a time must be seconds from 0 to {MAX_TIME_S:g}, got {value!r}")
    return float(value)


def _span(path, where, entry):
    if not isinstance(entry, dict):
        raise TranscriptError(f"{path}: {where}: must be an object with start and end, got {type(entry).__name__}")
    start, end = _time(path, f"{where}.start", entry.get("start")), _time(path, f"{where}.end", entry.get("end"))
    if end < start:
        raise TranscriptError(f"{path}: {where}: ends ({end:g} s) before it starts ({start:g} s)")
    return start, end


def _word(path, where, entry):
    start, end = _span(path, where, entry)
    text = entry.get("word")
    if not isinstance(text, str) or len(text) > MAX_WORD_CHARS:
        raise TranscriptError(f"{path}: {where}.word: must be text of at most {MAX_WORD_CHARS} characters")
    return Word(start, end, user_files.shown_text(text))  # a caption's word: no control character reaches the layout


def _list(path, where, value):
    if not isinstance(value, list):
        raise TranscriptError(f"{path}: {where}: must be a list, got {type(value).__name__}")
    return value


def read_seamless_json(path):
    """A Seamless Interaction participant's `.json` as a Transcript (its words and its VAD)."""
    data = user_files.read_json(path, MAX_BYTES, TranscriptError, "transcript")
    if not isinstance(data, dict):
        raise TranscriptError(f"{path}: must be a JSON object with '{TRANSCRIPT_KEY}', got {type(data).__name__}")
    if TRANSCRIPT_KEY not in data:
        raise TranscriptError(f"{path}: no '{TRANSCRIPT_KEY}' key (Seamless Interaction's word-timed transcript)")
    segments, count = [], 0
    for k, seg in enumerate(_list(path, TRANSCRIPT_KEY, data[TRANSCRIPT_KEY])):
        where = f"{TRANSCRIPT_KEY}[{k}]"
        _span(path, where, seg)
        words = [
            _word(path, f"{where}.words[{i}]", w)
            for i, w in enumerate(_list(path, f"{where}.words", seg.get("words", [])))
        ]
        count += len(words)
        if count > MAX_WORDS:
            raise TranscriptError(f"{path}: more than {MAX_WORDS} words")
        words = [w for w in words if w.text]
        if words:
            segments.append(sorted(words, key=lambda w: w.start))
    vad = [_span(path, f"{VAD_KEY}[{k}]", v) for k, v in enumerate(_list(path, VAD_KEY, data.get(VAD_KEY, [])))]
    return Transcript(sorted(segments, key=lambda s: s[0].start), sorted(vad), str(path))


def read_tsv(path):
    """A GENEA 2023 `.tsv` transcript (start, end, word a line) as a Transcript, segments a pause apart."""
    words = []
    for n, line in enumerate(_text(path).splitlines(), 1):
        if not line.strip():
            continue
        cells = line.split("\t")
        if len(cells) < 3:
            raise TranscriptError(f"{path}:{n}: expected start, end and word separated by tabs")
        try:
            start, end = float(cells[0]), float(cells[1])
        except ValueError:
            raise TranscriptError(
                f"{path}:{n}: start and end must be seconds, got {cells[0]!r}, {cells[1]!r}"
            ) from None
        words.append(_word(path, f"line {n}", dict(start=start, end=end, word="\t".join(cells[2:]))))
        if len(words) > MAX_WORDS:
            raise TranscriptError(f"{path}: more than {MAX_WORDS} words")
    words = sorted((w for w in words if w.text), key=lambda w: w.start)
    segments = []
    for w in words:
        if segments and w.start - segments[-1][-1].end < TSV_PAUSE_S:
            segments[-1].append(w)
        else:
            segments.append([w])
    return Transcript(segments, [], str(path))


def read_transcript(path):
    """A transcript file by its extension: Seamless Interaction's `.json` or GENEA 2023's `.tsv`."""
    if Path(path).suffix.lower() == ".tsv":
        return read_tsv(path)
    return read_seamless_json(path)


def write_transcript(path, transcript, ident=""):
    """Write a Transcript as JSON in Seamless Interaction's layout."""
    Path(path).write_text(json.dumps(transcript.to_json(ident), indent=1) + "\n", encoding="utf-8")
