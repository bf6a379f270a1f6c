"""A small two-person study with speech on both tracks, for `python -m analysis.demo --design dyadic` (and
`semantic`): real actions as the agent and its interlocutor, two made-up systems, words spoken and timed.

    python -m generation.own_study.demo_dyad --out DIR [--items 8] [--design dyadic] [--seed 0]

Writes DIR/study.toml and its folders (CONTRACTS §10), each item a pair of takes of
../shared/data/bandai-namco-actions at least MIN_SECONDS long:
- `real/` (the agent) and `interlocutor/` (the other person): the takes, copied as they are;
- `smooth/` and `tremble/`: the agent's joint positions smoothed and 0.15 s late, or with 1.5 cm of noise, as
  `.npy` with `skeleton.json` (as generation.own_study.demo_study makes them);
- dyadic: `real_mismatched/`, `smooth_mismatched/` and `tremble_mismatched/`: each condition's "motion for a
  mismatched interlocutor", here its motion of another item's agent take;
- `interlocutor_audio/` and `agent_audio/`: the other person asks a question, the agent answers (DIALOGUES), each
  word spoken by Debian's espeak-ng in its own voice and laid end to end, so that every word's time is known;
- `interlocutor_transcript/` and `agent_transcript/`: those words and times in Seamless Interaction's layout;
- `sources.csv`: where each item came from, the keyword of its answer (semantic: highlighted) and, for dyadic,
  the item whose take gave the mismatched motion.

The takes have no sound of their own: the study shows the mechanics of the dyadic and semantic tests, not a real
conversation.
"""

import io
import json
import shutil
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np

from moglow_eval.core import cli
from moglow_eval.core.study import TWO_PERSON_DEMO_DESIGNS, TWO_PERSON_DEMO_ITEMS

from ..data.motion_files import read_motion
from ..data.transcripts import Transcript, Word, write_transcript
from .cuts import source_row, write_sources
from .demo_study import FPS, actions_dir

# (the interlocutor's question, the agent's answer, the answer's keyword)
DIALOGUES = (
    ("Where's the box?", "By the window, there.", "window"),
    ("Did you see it?", "What a goal!", "goal"),
    ("Which way out?", "Go left, then on.", "left"),
    ("How tall was it?", "Huge, really huge.", "huge"),
    ("You coming?", "No, going home.", "home"),
    ("How big?", "Long, this long.", "long"),
    ("Shall we go?", "Stop, wait here.", "stop"),
    ("Who won?", "I came first!", "first"),
    ("Is it far?", "Just around there.", "around"),
    ("Can I sit?", "Please, a seat.", "seat"),
)
MIN_SECONDS = 4.0  # a take long enough for a question and its answer
VOICES = {"interlocutor": ("-p", "72", "-s", "200"), "agent": ("-p", "38", "-s", "190")}
GAP_S = 0.06  # between two words


def _word_samples(word, voice):
    """A word spoken by espeak-ng: int16 samples at its rate, the silence around it trimmed."""
    raw = subprocess.run(["espeak-ng", "--stdout", *VOICES[voice], word], capture_output=True, check=True).stdout
    with wave.open(io.BytesIO(raw)) as w:
        rate, pcm = w.getframerate(), np.frombuffer(w.readframes(w.getnframes()), "<i2")
    loud = np.flatnonzero(np.abs(pcm.astype(np.int32)) > 300)
    return rate, pcm[loud[0] : loud[-1] + 1] if len(loud) else pcm


def speak(text, voice, start, seconds):
    """(int16 samples of `seconds` at espeak-ng's rate, [Word]): the words of `text` spoken from `start`, or
    earlier where they would run past `seconds` (no earlier than 0.2 s; the words that still do not fit are left
    out)."""
    spoken = [(token, *_word_samples(token, voice)) for token in text.split()]
    rate = spoken[0][1]
    length = sum(len(pcm) / rate + GAP_S for _, _, pcm in spoken)
    words, parts, t = [], [], max(min(start, seconds - 0.3 - length), 0.2)
    for token, rate, pcm in spoken:
        if t + len(pcm) / rate > seconds:
            break
        words.append(Word(round(t, 3), round(t + len(pcm) / rate, 3), token.strip(",.!?")))
        parts.append((int(round(t * rate)), pcm))
        t += len(pcm) / rate + GAP_S
    out = np.zeros(int(round(seconds * rate)), np.int16)
    for a, pcm in parts:
        out[a : a + len(pcm)] = pcm[: len(out) - a]
    return rate, out, words


def _write_voice(out, role, item, text, voice, start, seconds):
    rate, pcm, words = speak(text, voice, start, seconds)
    with wave.open(str(out / f"{role}_audio" / f"{item}.wav"), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(pcm.tobytes())
    write_transcript(out / f"{role}_transcript" / f"{item}.json", Transcript([words] if words else [], []), item)
    return words


def _systems(joints, rng):
    """{folder: joints} of the two made-up systems' motion of a take's joints (as demo_study makes them)."""
    kernel = np.ones(7) / 7
    smooth = np.apply_along_axis(lambda v: np.convolve(np.pad(v, 3, mode="edge"), kernel, "valid"), 0, joints)
    late = int(0.15 * FPS)
    smooth = np.concatenate([np.repeat(smooth[:1], late, 0), smooth[:-late]])
    return {"smooth": smooth, "tremble": joints + rng.normal(0, 0.015, joints.shape)}


def _takes(n_items):
    """[(path, Motion)] of 2 n_items long takes of one skeleton, in a mix of kinds."""
    source = actions_dir()
    if source is None:
        raise cli.UserError("../shared/data/bandai-namco-actions not found beside the checkout: the demo needs it")
    chosen, names = [], None
    for take in sorted(source.glob("*.bvh.gz"), key=lambda p: (p.name.split("_")[2], p.name)):
        m = read_motion(take, FPS)
        if m.seconds >= MIN_SECONDS and (names is None or m.names == names):
            chosen.append((take, m))
            names = m.names
        if len(chosen) == 2 * n_items:
            return chosen
    raise cli.UserError(f"{source}: only {len(chosen)} takes of {MIN_SECONDS:g} s or more; ask for fewer --items")


def build(out, n_items=8, design="dyadic", seed=0):
    """Write the two-person demo study into `out`; returns the study file's path."""
    if shutil.which("espeak-ng") is None:
        raise cli.UserError("the demo speaks with espeak-ng: install it (apt-get install espeak-ng)")
    out = Path(out)
    takes = _takes(n_items)
    agents, others = takes[0::2], takes[1::2]
    folders = ["real", "interlocutor", "smooth", "tremble", "agent_audio", "interlocutor_audio", "agent_transcript",
               "interlocutor_transcript"]  # fmt: skip
    if design == "dyadic":
        folders += ["real_mismatched", "smooth_mismatched", "tremble_mismatched"]
    for sub in folders:
        (out / sub).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    made = [_systems(m.joints.astype(np.float64), rng) for _, m in agents]
    rows = []
    for k, ((take, m), (other, o)) in enumerate(zip(agents, others)):
        item, seconds = f"item{k:02d}", min(m.seconds, o.seconds)
        shutil.copyfile(take, out / "real" / f"{item}.bvh.gz")
        shutil.copyfile(other, out / "interlocutor" / f"{item}.bvh.gz")
        for name, joints in made[k].items():
            np.save(out / name / f"{item}.npy", joints.astype(np.float32))
        question, answer, keyword = DIALOGUES[k % len(DIALOGUES)]
        asked = _write_voice(out, "interlocutor", item, question, "interlocutor", 0.3, seconds)
        said = _write_voice(
            out, "agent", item, answer, "agent", (asked[-1].end if asked else 0.3) + 0.25, seconds + 0.5
        )
        key = next((w for w in said if w.text.lower() == keyword), None)
        partner = (k + 1) % len(agents)  # the mismatched motion: each condition's of the next item's agent take
        if design == "dyadic":
            shutil.copyfile(agents[partner][0], out / "real_mismatched" / f"{item}.bvh.gz")
            for name, joints in made[partner].items():
                np.save(out / f"{name}_mismatched" / f"{item}.npy", joints.astype(np.float32))
        people = (take.name.split(".")[0], other.name.split(".")[0])
        rows.append(source_row(item, "demo", f"demo{k:02d}", people, (0.0, seconds), keyword if key else "",
                               (key.start, key.end) if key else (),
                               f"item{partner:02d}" if design == "dyadic" else ""))  # fmt: skip
    write_sources(out / "sources.csv", rows)
    (out / "skeleton.json").write_text(
        json.dumps(dict(names=agents[0][1].names, parents=[int(p) for p in agents[0][1].parents]))
    )
    return _study_file(out, design, seed)


def _study_file(out, design, seed):
    mismatched = (
        '\n[mismatched]\nreal = "real_mismatched"\nSMOOTH = "smooth_mismatched"\nTREMBLE = "tremble_mismatched"\n'
    )
    keywords = 'keywords = "sources.csv"\n' if design == "semantic" else ""
    study = out / "study.toml"
    study.write_text(
        f"""# A two-person demo study (own_study.demo_dyad): real actions as the agent and its interlocutor, two made-up
# systems, spoken words on both tracks.
reference = "real"
design = "{design}"
seed = {seed}
n_training = 1
sources = "sources.csv"

[conditions]
real = "real"
SMOOTH = "smooth"
TREMBLE = "tremble"
{mismatched if design == "dyadic" else ""}
[interlocutor]
folder = "interlocutor"

[catch]
make = ["jitter", "freeze", "swap"]
n = 2

[skeleton]
file = "skeleton.json"
fps = {FPS:g}

[audio]
folder = "agent_audio"
interlocutor = "interlocutor_audio"
loudness = -23

[captions]
folder = "agent_transcript"
interlocutor = "interlocutor_transcript"
{keywords}"""
    )
    return study


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.own_study.demo_dyad", description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="folder for the study file and its folders")
    ap.add_argument("--items", type=cli.number(int, *TWO_PERSON_DEMO_ITEMS), default=8, help="items (default 8)")
    ap.add_argument("--design", choices=TWO_PERSON_DEMO_DESIGNS, default="dyadic", help="the test (default dyadic)")
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.folder_to_write(args.out, "the study's folder")
    print(build(args.out, args.items, args.design, args.seed))
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
