"""Items cut from long conversations: Seamless Interaction's recordings into the folders a study file reads.

    python -m generation.own_study.conversations FOLDER [FOLDER ...] --out ITEMS --mode listening [--length-s 8]
        [--margin-s 0.5] [--min-valid 0.9] [--per-interaction 2] [--agent ID] [--keywords FILE] [--mismatched]

The folders are searched for Seamless Interaction participant files (`V*_S*_I*_P*.npz`, with the `.wav` and `.json`
of the same name beside each); the two participants of an interaction share its `V*_S*_I*` prefix. Who is the
agent of an item is never taken from file order: the mode decides, by the voice activity (VAD, else the
transcript's segments) and the words (generation.own_study.cuts):
- `speaking`: the agent speaks (realism, speech alignment);
- `listening`: the other person speaks while the agent mostly listens (GENEA's dyadic test);
- `keyword`: around a keyword the agent says (`--keywords`: a CSV of interaction, participant, keyword).
`--agent` keeps only items whose agent is that participant (its id, `P0299A`, or its final letter, `A`).

Rules: every item is `--length-s` long, starts `--margin-s` before the speech it is cut around, and has valid
motion (smplh:is_valid) for both people over it and `--margin-s` beyond either end; an interaction whose
participants have less than `--min-valid` of their frames valid is passed over (logged); at most
`--per-interaction` items an interaction, the best first, no two overlapping in time.

Writes ITEMS/ (CONTRACTS §10, "Conversations"): `agent/ITEM.npz` and `interlocutor/ITEM.npz` (the span of each
person's file, in the same layout), `agent_audio/` and `interlocutor_audio/ITEM.wav` (each person's own voice,
48 kHz), `agent_transcript/` and `interlocutor_transcript/ITEM.json` (the words and VAD, times from the item's
start) and `sources.csv`, where each item came from. With `--mismatched`, also `mismatched_interlocutor/`,
`mismatched_interlocutor_audio/` and `mismatched_interlocutor_transcript/`: another item's interlocutor (another
interaction's where there is one), the inputs a system is given to make its motion for a mismatched
interlocutor in the dyadic design; `sources.csv`'s `mismatched` names that item. Everything is checked and
written in a folder beside ITEMS, which takes its name only when complete: a failed run leaves nothing.
"""

import logging
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from moglow_eval.core import cli

from ..data.seamless_files import parse_name, read_seamless, write_cut
from ..data.smpl_files import SmplError
from ..data.transcripts import TranscriptError, read_transcript, write_transcript
from .cuts import MODES, Speaker, choose_items, keyword_table, write_sources

log = logging.getLogger(__name__)
PEOPLE = ("agent", "interlocutor")


class ConversationError(cli.UserError):
    """A conversation folder that cannot be cut; the message names the file."""


def find_interactions(folders):
    """{interaction: {participant: npz path}} of the Seamless Interaction files under `folders`, each interaction
    with exactly two participants, each with its .wav and .json beside it."""
    found = {}
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise ConversationError(f"{folder}: no such folder")
        for path in sorted(folder.rglob("*.npz")):
            names = parse_name(path)
            if names is None:
                continue
            interaction, participant = names
            if participant in found.setdefault(interaction, {}):
                raise ConversationError(f"{path}: participant {participant} of {interaction} found twice")
            for ext in (".wav", ".json"):
                if not path.with_suffix(ext).is_file():
                    raise ConversationError(f"{path}: no {path.with_suffix(ext).name} beside it")
            found[interaction][participant] = path
    if not found:
        raise ConversationError(f"{', '.join(map(str, folders))}: no Seamless Interaction files (V*_S*_I*_P*.npz)")
    for interaction, people in found.items():
        if len(people) != 2:
            listed = ", ".join(p.name for p in people.values())
            raise ConversationError(f"{interaction}: {len(people)} participant(s) ({listed}); a conversation has two")
    return found


def read_speaker(participant, path):
    """A Speaker: the participant's validity mask (from the motion file), speech intervals and words; its sound
    checked to last as long as its motion, from the header."""
    from rendering.audio import audio_seconds
    from rendering.errors import RenderError

    try:
        motion = read_seamless(path)
        transcript = read_transcript(path.with_suffix(".json"))
        seconds = audio_seconds(path.with_suffix(".wav"))
    except (SmplError, TranscriptError, RenderError) as e:
        raise ConversationError(str(e)) from None
    need = len(motion.valid) / motion.fps
    if seconds is not None and seconds + 1 / motion.fps < need:
        raise ConversationError(
            f"{path.with_suffix('.wav')}: ends at {seconds:.2f} s, before its motion ({need:.2f} s)"
        )
    return Speaker(participant, path, motion.valid, motion.fps, transcript)


def _write_person(out, role, item, speaker, start_frame, frames, start_s, seconds):
    """One person's span of motion, sound and transcript into the item folders of `role`."""
    from rendering import audio
    from rendering.errors import RenderError

    write_cut(speaker.path, out / role / f"{item}.npz", start_frame, start_frame + frames)
    wav = speaker.path.with_suffix(".wav")
    try:
        samples = audio.read_audio(wav, seconds, start_s=start_s)
    except RenderError as e:
        raise ConversationError(str(e)) from None
    if len(samples) < int(seconds * audio.RATE) - 1:
        raise ConversationError(f"{wav}: ends before {start_s + seconds:.2f} s, where its motion goes on")
    audio.write_wav(out / f"{role}_audio" / f"{item}.wav", samples[: int(round(seconds * audio.RATE))])
    write_transcript(
        out / f"{role}_transcript" / f"{item}.json", speaker.transcript.cut(start_s, start_s + seconds), item
    )


def write_items(out, items, speakers, mismatched, progress):
    """Every item's folders and sources.csv into `out` (a fresh folder)."""
    roles = [*PEOPLE, *(["mismatched_interlocutor"] if mismatched else [])]
    for role in roles:
        for sub in ("", "_audio", "_transcript"):
            (out / f"{role}{sub}").mkdir()
    by_name = {c.item: c for c in items}
    rows = []
    for c in tqdm(items, desc="cut", unit="item", file=sys.stderr, disable=not progress):
        seconds = c.frames / c.fps
        for role, who in (("agent", c.agent), ("interlocutor", c.interlocutor)):
            _write_person(out, role, c.item, speakers[c.interaction][who], c.start_frame, c.frames, c.start, seconds)
        if mismatched:
            other = by_name[mismatched[c.item]]
            speaker = speakers[other.interaction][other.interlocutor]
            _write_person(
                out, "mismatched_interlocutor", c.item, speaker, other.start_frame, c.frames, other.start, seconds
            )
        rows.append(c.row(mismatched.get(c.item, "") if mismatched else ""))
    write_sources(out / "sources.csv", rows)


def mismatch_items(items, seed):
    """{item: another item}: whose interlocutor is the mismatched one, from another interaction where one exists
    (seeded)."""
    rng = np.random.default_rng(seed + 6007)
    out = {}
    for c in items:
        others = [o.item for o in items if o.interaction != c.interaction] or [o.item for o in items if o is not c]
        if not others:
            raise ConversationError("--mismatched needs at least two items: cut more (--per-interaction, folders)")
        out[c.item] = str(rng.choice(others))
    return out


def cut_conversations(folders, out, mode, length_s, margin_s=0.5, min_valid=0.9, per_interaction=2, agent=None,
                      keywords=None, mismatched=False, seed=0, force=False, progress=True):  # fmt: skip
    """Cut items from conversations into `out` (see the module's docstring); returns the items (cuts.Cut)."""
    out = Path(out)
    if out.exists() and not (out.is_dir() and not any(out.iterdir())):
        if not force:
            raise ConversationError(f"{out}: already exists; give --force to replace it")
        # --force replaces a folder of items this command wrote, never another (`--out .`, the recordings' own)
        if not out.is_dir() or not (out / "sources.csv").is_file():
            raise ConversationError(f"--out {out}: not a folder of items this command wrote (no sources.csv), so "
                                    "--force does not replace it: give another --out")  # fmt: skip
        inside = next((f for f in folders if Path(f).resolve().is_relative_to(out.resolve())), None)
        if inside is not None:
            raise ConversationError(f"--out {out}: holds the recordings' folder {inside}, which --force would remove")
    found = find_interactions(folders)
    wanted = keyword_table(keywords) if mode == "keyword" else None
    if mode == "keyword" and wanted is None:
        raise ConversationError("--mode keyword needs --keywords FILE (interaction, participant, keyword)")
    speakers, items = {}, []
    for interaction, people in tqdm(sorted(found.items()), desc="read", unit="interaction", file=sys.stderr,
                                    disable=not progress):  # fmt: skip
        pair = {p: read_speaker(p, path) for p, path in sorted(people.items())}
        share = {p: float(s.valid.mean()) for p, s in pair.items()}
        if min(share.values()) < min_valid:
            worst = min(share, key=share.get)
            log.warning(f"{interaction}: passed over: {worst} has {share[worst]:.0%} of its frames valid (--min-valid)")
            continue
        speakers[interaction] = pair
        items += choose_items(interaction, pair, mode, length_s, margin_s, per_interaction, agent, wanted)
    if not items:
        raise ConversationError(f"no item of {length_s:g} s in {mode} mode in {len(found)} interaction(s)")
    pairs = mismatch_items(items, seed) if mismatched else {}
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        write_items(tmp, items, speakers, pairs, progress)
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return items


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.own_study.conversations", description=__doc__.split("\n")[0])
    ap.add_argument("folders", nargs="+", help="folders holding Seamless Interaction files (searched recursively)")
    ap.add_argument("--out", required=True, help="the item folders to write")
    ap.add_argument("--mode", choices=MODES, required=True, help="who the agent is and what the item is cut around")
    ap.add_argument("--length-s", type=cli.number(float, 1, 120), default=8.0, help="item length in s (default 8)")
    ap.add_argument("--margin-s", type=cli.number(float, 0, 10), default=0.5, help="lead-in and valid margin (0.5 s)")
    ap.add_argument("--min-valid", type=cli.number(float, 0, 1), default=0.9, help="least share of valid frames (0.9)")
    ap.add_argument("--per-interaction", type=cli.number(int, 1, 1000), default=2, help="most items each (default 2)")
    ap.add_argument("--agent", help="only items whose agent is this participant (id, or its final letter)")
    ap.add_argument("--keywords", help="keyword mode: a CSV of interaction, participant, keyword")
    ap.add_argument("--mismatched", action="store_true", help="also write a mismatched interlocutor per item")
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    ap.add_argument("--force", action="store_true", help="replace an existing --out folder")
    ap.add_argument("--quiet", action="store_true", help="no progress bars")
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.folder_to_write(args.out, "the items' folder")
    cli.log_to_stderr(args.quiet)
    items = cut_conversations(
        args.folders, args.out, args.mode, args.length_s, args.margin_s, args.min_valid, args.per_interaction,
        args.agent, args.keywords, args.mismatched, args.seed, args.force, not args.quiet,
    )  # fmt: skip
    print(f"wrote {len(items)} items to {args.out} (where each came from: {Path(args.out) / 'sources.csv'})")
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
