"""What an item says: its sound (one voice, or two mixed), its captions and its keyword, and where it came from.

- Sound (`prepare_audio`): each item's ITEM.wav or ITEM.flac from `[audio] folder` (the agent, or the one person),
  and with `[audio] interlocutor` the other person's voice beside it; every track at least as long as the item's
  clips. One voice is normalised to the study's loudness; two are mixed (rendering.audio.mix_voices: each levelled,
  a listener's silence kept, the mix normalised), mono, or stereo with each voice on its person's side of the
  screen. The mix must not be silent. The samples are written once per item and muxed into every video of it.
- Captions (`item_captions`): the words of `[captions] folder` (and `interlocutor`), ITEM.json in Seamless
  Interaction's layout or ITEM.tsv, times from the clip's start, as phrases at the video's size
  (rendering.captions); a keyword (`[captions] keywords`: a table of item, keyword and optionally keyword_start,
  keyword_end, seconds from the item's start) highlighted where the agent says it.
- Sources (`read_sources`): the table of where each item came from (`sources`: the cutter's sources.csv), its
  rows for the study's items kept beside the stimuli.
Every problem is one StimuliError naming the file, before anything is written.
"""

import numpy as np

from moglow_eval.core.cli import UserError
from moglow_eval.core.tables import read_csv

from ..data.transcripts import EXTENSIONS as TRANSCRIPT_EXTENSIONS
from ..data.transcripts import TranscriptError, read_transcript
from ..stimuli.files import StimuliError
from . import designs
from .cuts import plain
from .inputs import seconds_text

AUDIO_EXTENSIONS = (".wav", ".flac")


def _item_files(folder, extensions):
    """{stem: path} of the files with one of `extensions` in `folder`."""
    return {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in extensions and p.is_file()}


def _track(path, need, fps):
    """An item's span of one voice: float32 [N, channels] at rendering.audio.RATE, `need` seconds of it."""
    from rendering import audio
    from rendering.errors import RenderError

    try:
        samples = audio.read_audio(path, max_seconds=need + 1.0)  # no more is played: no more is decoded
    except RenderError as e:
        raise StimuliError(str(e)) from None
    have = len(samples) / audio.RATE
    if have + 0.5 / fps < need:
        raise StimuliError(f"{path}: the audio is {seconds_text(have)}, shorter than the item's clips ({need:.2f} s)")
    span = samples[: int(round(need * audio.RATE))].astype(np.float32)
    return np.concatenate([span, np.zeros((int(round(need * audio.RATE)) - len(span), span.shape[1]), np.float32)])


def prepare_audio(spec, lengths, folder, pans=None):
    """{item: path of its samples (.npy, float32 at rendering.audio.RATE)} for a study with [audio]: `lengths`
    {item: frames}; `pans` {item: (agent's, interlocutor's) place on screen, -1 left .. 1 right} for stereo.
    StimuliError naming the file for a missing, short, unreadable or silent one."""
    from rendering import audio

    if spec.audio_folder is None:
        return {}
    folders = [spec.audio_folder, *([spec.interlocutor_audio] if spec.interlocutor_audio else [])]
    files = [_item_files(f, AUDIO_EXTENSIONS) for f in folders]
    out = {}
    for item, frames in lengths.items():
        need = frames / spec.fps
        tracks = []
        for where, found in zip(folders, files):
            if item not in found:
                raise StimuliError(f"{where}: no audio for item {item} (expected {item}.wav or {item}.flac)")
            tracks.append(_track(found[item], need, spec.fps))
        if len(tracks) == 1 and not spec.stereo:
            sound = tracks[0]
            if audio.rms_dbfs(sound) < audio.SILENCE_DBFS:
                raise StimuliError(
                    f"{files[0][item]}: silent over the clip's {need:.2f} s, where the study needs speech"
                )
            sound = audio.normalise(sound, spec.loudness)
        else:
            side = (pans or {}).get(item, (0.0, 0.0))  # one person, or no screen sides: centred
            sound = audio.mix_voices(tracks, spec.loudness, [audio.PAN * np.sign(p) for p in side[: len(tracks)]]
                                     if spec.stereo else None)  # fmt: skip
            if audio.rms_dbfs(sound) < audio.SILENCE_DBFS:
                raise StimuliError(f"{', '.join(str(f[item]) for f in files)}: silent over the item's {need:.2f} s")
        out[item] = folder / f"{item}.npy"
        np.save(out[item], sound)
    return out


def read_voices(spec, lengths):
    """(agent's, interlocutor's) {item: mono float32 samples at rendering.audio.RATE} for the gesture measures: each
    voice's own track over the item, as the study's sound reads it (the interlocutor's {} without one); ({}, {})
    for a study without [audio]."""
    if spec.audio_folder is None:
        return {}, {}
    folders = [spec.audio_folder, *([spec.interlocutor_audio] if spec.interlocutor_audio else [])]
    out = ({}, {})
    for where, voices in zip(folders, out):
        found = _item_files(where, AUDIO_EXTENSIONS)
        for item, frames in lengths.items():
            if item not in found:
                raise StimuliError(f"{where}: no audio for item {item} (expected {item}.wav or {item}.flac)")
            voices[item] = _track(found[item], frames / spec.fps, spec.fps).mean(axis=1)
    return out


# ---------------------------------------------------------------- captions
def read_keywords(spec):
    """{item: (keyword, (start, end) or None)} from `[captions] keywords`; {} without one."""
    if spec.keywords is None:
        return {}
    path, df = read_csv(spec.keywords, StimuliError)
    missing = [c for c in ("item", "keyword") if c not in df.columns]
    if missing:
        raise StimuliError(
            f"{path}: missing column {missing[0]} (expected item, keyword[, keyword_start, keyword_end])"
        )
    out = {}
    for line, row in df.iterrows():
        word = plain(row["keyword"])
        if not word:
            continue
        span = None
        if row.get("keyword_start", "") and row.get("keyword_end", ""):
            try:
                span = (float(row["keyword_start"]), float(row["keyword_end"]))
            except ValueError:
                raise StimuliError(f"{path}:{line}: keyword_start and keyword_end must be seconds") from None
        out[row["item"].strip()] = (word, span)
    return out


def _words(folder, item):
    """The words [(start, end, text)] of an item's transcript in `folder`; StimuliError naming the folder."""
    for ext in TRANSCRIPT_EXTENSIONS:
        path = folder / f"{item}{ext}"
        if path.is_file():
            try:
                return [(w.start, w.end, w.text) for w in read_transcript(path).words]
            except TranscriptError as e:
                raise StimuliError(str(e)) from None
    raise StimuliError(f"{folder}: no transcript for item {item} (expected {item}.json or {item}.tsv)")


def _highlighted(words, keyword):
    """The words [(start, end, text, highlighted)]: the keyword's, where the agent says it (at its time, when the
    table gives one)."""
    if keyword is None:
        return [(*w, False) for w in words]
    word, span = keyword
    out = []
    for start, end, text in words:
        at = span is None or (start < span[1] and end > span[0])
        out.append((start, end, text, plain(text) == word and at))
    return out


def item_captions(spec, lengths, size):
    """{item: tuple of rendering.captions.Phrase} for a study with [captions]; {} without. Words past the item's
    clips are left out; for a design that highlights one (semantic), every item needs its keyword and the keyword
    in its words."""
    from rendering.captions import phrases

    if spec.captions is None:
        return {}
    keywords = read_keywords(spec)
    highlights = designs.get(spec.design).highlights_keyword  # semantic: every item says its keyword
    out = {}
    for item, frames in lengths.items():
        seconds = frames / spec.fps
        words = [w for w in _words(spec.captions, item) if w[0] < seconds]
        marked = _highlighted(words, keywords.get(item))
        if highlights and not any(m[3] for m in marked):
            what = keywords.get(item, ("no keyword",))[0]
            raise StimuliError(
                f"{spec.keywords}: item {item}: its keyword ({what}) is not among its words in {spec.captions}"
            )
        shown = list(phrases(marked, size, 0))
        if spec.interlocutor_captions is not None:
            theirs = [(*w, False) for w in _words(spec.interlocutor_captions, item) if w[0] < seconds]
            shown += phrases(theirs, size, 1)
        out[item] = tuple(shown)
    return out


# ---------------------------------------------------------------- sources
def read_sources(spec, items):
    """(columns, rows) of the `sources` table for the study's items (every column kept); (None, []) without one."""
    if spec.sources is None:
        return None, []
    try:
        path, df = read_csv(spec.sources, StimuliError)
    except UserError as e:
        raise StimuliError(str(e)) from None
    if "item" not in df.columns:
        raise StimuliError(f"{path}: missing column item (the table of where each item came from)")
    rows = [dict(row) for _, row in df.iterrows() if row["item"].strip() in items]
    return list(df.columns), rows
