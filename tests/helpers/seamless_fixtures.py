"""A conversation in Seamless Interaction's layout, written by the tests: two participants of one interaction.

`write_conversation(folder)` writes, for each participant `V00_S0001_I00000001_P0299A` and `..._P0301B`:
- `.npz`: SMPL-H parameters under the `smplh:*` keys (no betas), the first participant's pose arrays flat
  ([T, 63], [T, 45]) and the second's per joint ([T, 21, 3], [T, 15, 3]), an `smplh:is_valid` mask with invalid
  frames (NaN parameters inside them), and members of no interest (`movement:*`, `boxes_and_keypoints:*`). Each
  person is stored in their own camera's frame: the first Y up at the origin, the second Y down (a camera's
  axes), metres away and facing the same way as the first, so only a placement that turns them puts them face to
  face. Each gestures with both arms while speaking and moves little while listening;
- `.wav`: 48 kHz 16-bit mono, that person's "voice": a harmonic tone at its own pitch (VOICE_HZ), syllable-like
  bursts, only while that person speaks, so a test can tell the two voices apart by their spectrum;
- `.json`: `metadata:transcript` (segments with start, end, transcript and timed words) and `metadata:vad`.

The turns (TURNS) alternate: the first participant speaks, the second answers while the first listens, and so on.
The body model is the synthetic SMPL-H of tests/helpers/smpl_fixtures.py (the real one is licensed).
"""

import json
import wave
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from . import smpl_fixtures

INTERACTION = "V00_S0001_I00000001"
PARTICIPANTS = ("P0299A", "P0301B")
FPS = 30.0
RATE = 48_000
VOICE_HZ = (140.0, 235.0)  # each voice's fundamental, the first participant's first
# (speaker index, start s, end s, words): who speaks when, in a conversation of 26 s.
TURNS = (
    (0, 0.6, 4.4, "so the plan is to cross the old bridge before noon"),
    (1, 5.0, 10.2, "that sounds fine but the river is high this week and the road is closed"),
    (0, 10.8, 13.6, "then we wait for the morning"),
    (1, 14.2, 19.6, "or we take the long way round through the hills and the little village"),
    (0, 20.2, 24.8, "the bridge is safer if we leave early enough"),
)
SECONDS = 26.0
INVALID = ((380, 395),)  # frames of the first participant marked invalid (12.7-13.2 s, inside its third turn)


@dataclass
class Conversation:
    folder: Path
    model: Path  # the SMPL-H body model (synthetic)
    files: dict = field(default_factory=dict)  # participant -> {"motion", "audio", "transcript"}: Path
    turns: tuple = TURNS
    invalid: tuple = INVALID


def stem(participant, interaction=INTERACTION):
    return f"{interaction}_{participant}"


def speaking(who, t, turns=TURNS):
    """[T] bool: whether participant index `who` speaks at each time t [T]."""
    on = np.zeros(len(t), bool)
    for speaker, a, b, _ in turns:
        if speaker == who:
            on |= (t >= a) & (t < b)
    return on


def pose_arrays(who, frames, turns=TURNS, fps=FPS):
    """(global_orient [T, 3], body_pose [T, 21, 3], left and right hand [T, 15, 3], translation [T, 3]) of one
    participant, in a shared world frame (Y up), facing +Z at the origin: arms down, gesturing while speaking."""
    t = np.arange(frames) / fps
    talk = speaking(who, t, turns).astype(float)
    talk = np.convolve(talk, np.ones(9) / 9, mode="same")  # gestures fade in and out over 0.3 s
    phase = 2 * np.pi * (1.3 + 0.4 * who) * t
    body = np.zeros((frames, 21, 3))
    # The joints' body_pose rows are the SMPL joint index less one (the pelvis is global_orient).
    body[:, 15, 2] = -1.2 + 0.5 * talk * np.sin(phase)  # left shoulder: down from the T-pose, raised to gesture
    body[:, 16, 2] = 1.2 - 0.5 * talk * np.sin(phase + 1.0)
    body[:, 17, 1] = -0.9 * talk * (0.6 + 0.4 * np.sin(phase))  # elbows bend while speaking
    body[:, 18, 1] = 0.9 * talk * (0.6 + 0.4 * np.sin(phase + 0.7))
    body[:, 14, 0] = 0.05 * np.sin(2 * np.pi * 0.2 * t)  # the head nods a little all along
    hands = np.zeros((frames, 15, 3))
    hands[:, :, 2] = 0.3 * talk[:, None]
    orient = np.zeros((frames, 3))
    orient[:, 1] = 0.05 * np.sin(2 * np.pi * 0.1 * t)
    trans = np.stack([0.02 * np.sin(t), 0.93 + 0 * t, 0 * t], 1)
    return orient, body, hands, hands.copy(), trans


def in_camera_frame(orient, trans, turn_x=np.pi, offset=(3.0, 1.2, -2.0)):
    """Orientation and translation of a body re-expressed in a camera's frame turned `turn_x` about X (pi: Y down)
    and moved by `offset`; the pose relative to the body is unchanged."""
    cam = Rotation.from_rotvec([turn_x, 0.0, 0.0])
    orient = (cam * Rotation.from_rotvec(orient)).as_rotvec()
    # smplx turns the body about its rest pelvis (the origin in the synthetic model): the translation turns alike.
    return orient, cam.apply(trans) + np.asarray(offset)


def voice(who, seconds=SECONDS, turns=TURNS, seed=0):
    """[N] float: a harmonic tone at the participant's pitch in syllable bursts while it speaks, else near silence."""
    rng = np.random.default_rng(seed + who)
    t = np.arange(int(seconds * RATE)) / RATE
    f0 = VOICE_HZ[who]
    tone = sum(np.sin(2 * np.pi * k * f0 * t) / k for k in range(1, 7))
    syllables = 0.35 + 0.65 * np.abs(np.sin(2 * np.pi * 2.2 * t))
    on = speaking(who, t, turns)
    return 0.25 * tone * syllables * on + rng.normal(0, 1e-4, len(t))


def words_of(turn):
    """[(word, start, end)] of a turn, its words spread evenly over it."""
    _, a, b, text = turn
    words = text.split()
    step = (b - a) / len(words)
    return [(w, round(a + k * step, 3), round(a + (k + 0.8) * step, 3)) for k, w in enumerate(words)]


def transcript_json(who, turns=TURNS):
    segments = []
    for turn in turns:
        if turn[0] != who:
            continue
        words = words_of(turn)
        segments.append(
            {
                "start": turn[1],
                "end": turn[2],
                "transcript": turn[3],
                "words": [dict(word=w, start=s, end=e, score=0.9) for w, s, e in words],
            }
        )
    vad = [dict(start=a, end=b) for speaker, a, b, _ in turns if speaker == who]
    return {"id": "x", "metadata:transcript": segments, "metadata:vad": vad, "metadata:other": {"ignored": True}}


def write_wav(path, samples, rate=RATE):
    pcm = (np.clip(samples, -1, 1) * 32767).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(pcm.tobytes())


def write_participant(folder, who, participant, frames, interaction, invalid, turns):
    """One participant's .npz, .wav and .json; returns their paths."""
    orient, body, left, right, trans = pose_arrays(who, frames, turns)
    if who == 1:  # the second person in their own camera's frame: Y down, metres away, facing as the first does
        orient, trans = in_camera_frame(orient, trans)
    valid = np.ones(frames, bool)
    for a, b in invalid if who == 0 else ():
        valid[a : b + 1] = False
        body[a : b + 1] = np.nan  # what a failed fit leaves: numbers no renderer may see
        trans[a : b + 1] = 0.0
    flat = who == 0
    arrays = {
        "smplh:global_orient": orient,
        "smplh:body_pose": body.reshape(frames, 63) if flat else body,
        "smplh:left_hand_pose": left.reshape(frames, 45) if flat else left,
        "smplh:right_hand_pose": right.reshape(frames, 45) if flat else right,
        "smplh:translation": trans,
        "smplh:is_valid": valid,
        "movement:expression": np.zeros((frames, 8), np.float32),
        "boxes_and_keypoints:box": np.zeros((frames, 4), np.float32),
    }
    base = folder / stem(participant, interaction)
    np.savez(base.with_suffix(".npz"), **{k: np.asarray(v, np.float32) for k, v in arrays.items()})
    write_wav(base.with_suffix(".wav"), voice(who, frames / FPS, turns))
    base.with_suffix(".json").write_text(json.dumps(transcript_json(who, turns)))
    return {
        "motion": base.with_suffix(".npz"),
        "audio": base.with_suffix(".wav"),
        "transcript": base.with_suffix(".json"),
    }


def write_conversation(
    folder,
    interaction=INTERACTION,
    participants=PARTICIPANTS,
    seconds=SECONDS,
    invalid=INVALID,
    turns=TURNS,
    model=True,
):
    """Write one interaction's two participants into `folder` (and, with `model`, the synthetic SMPL-H body model
    as `folder/../models/SMPLH_NEUTRAL.npz`); returns a Conversation with every path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model_path = folder.parent / "models" / "SMPLH_NEUTRAL.npz"
    if model:
        model_path.parent.mkdir(exist_ok=True)
        smpl_fixtures.write_model(model_path, "smplh")
    frames = int(round(seconds * FPS))
    conv = Conversation(folder, model_path, turns=turns, invalid=invalid)
    for who, participant in enumerate(participants):
        conv.files[participant] = write_participant(folder, who, participant, frames, interaction, invalid, turns)
    return conv


# ---------------------------------------------------------------- a whole study
SYSTEMS = {"JITTERY": 0.08, "CALM": 0.02}  # made-up systems: the real agent's body pose plus noise of this sd (rad)


def _system_file(src, dst, sd, seed):
    arrays = dict(np.load(src))
    rng = np.random.default_rng(seed)
    pose = arrays["smplh:body_pose"]
    arrays["smplh:body_pose"] = (pose + rng.normal(0, sd, pose.shape)).astype(pose.dtype)
    np.savez(dst, **arrays)


def write_study(root, design="dyadic", length_s=4.0, stereo=False, per_interaction=2, style="stick"):
    """A two-person study from two conversations in Seamless Interaction's layout, cut by the cutter
    (generation.own_study.conversations) and written as a study file; returns its path.

    design "dyadic": `listening` items with mismatched interlocutors; each made-up system (SYSTEMS) gives the real
    agent's poses with noise for its own item, and for the item its mismatched interlocutor came from as its
    motion "for a mismatched interlocutor" (`[mismatched]`). design "semantic": `keyword` items around "bridge",
    the keyword highlighted (`[captions] keywords` is the cutter's sources.csv). Both show the real interlocutor,
    both voices (mono, or `stereo`) and both people's captions, drawn in `style`; the body model is the synthetic
    SMPL-H."""
    import csv

    from generation.own_study.conversations import cut_conversations

    root = Path(root)
    conv = write_conversation(root / "raw" / "a")
    write_conversation(root / "raw" / "b", interaction="V00_S0001_I00000002", model=False)
    mode = "listening" if design == "dyadic" else "keyword"
    keywords = None
    if mode == "keyword":
        keywords = root / "keywords.csv"
        keywords.write_text("interaction,keyword\nV00_S0001_I00000001,bridge\nV00_S0001_I00000002,bridge\n")
    cut_conversations([root / "raw"], root / "items", mode, length_s, per_interaction=per_interaction,
                      keywords=keywords, mismatched=design == "dyadic", progress=False)  # fmt: skip
    with open(root / "items" / "sources.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for k, (name, sd) in enumerate(SYSTEMS.items()):
        for sub in (name.lower(), *([f"{name.lower()}_mismatched"] if design == "dyadic" else [])):
            (root / sub).mkdir()
        for r in rows:
            agent = root / "items" / "agent"
            _system_file(agent / f"{r['item']}.npz", root / name.lower() / f"{r['item']}.npz", sd, k)
            if design == "dyadic":
                mismatched = root / f"{name.lower()}_mismatched" / f"{r['item']}.npz"
                _system_file(agent / f"{r['mismatched']}.npz", mismatched, sd, k + 10)
    systems = "\n".join(f'{name} = "{name.lower()}"' for name in SYSTEMS)
    table = "\n".join(f'{name} = "{name.lower()}_mismatched"' for name in SYSTEMS)
    text = f"""reference = "real"
design = "{design}"
seed = 1
n_training = 1
sources = "items/sources.csv"
[conditions]
real = "items/agent"
{systems}
{"[mismatched]" + chr(10) + table if design == "dyadic" else ""}
[interlocutor]
folder = "items/interlocutor"
[catch]
make = ["jitter", "freeze", "swap"]
n = 3
[skeleton]
smpl_model = "{conv.model}"
[audio]
folder = "items/agent_audio"
interlocutor = "items/interlocutor_audio"
channels = "{"stereo" if stereo else "mono"}"
[captions]
folder = "items/agent_transcript"
interlocutor = "items/interlocutor_transcript"
{'keywords = "items/sources.csv"' if design == "semantic" else ""}
[render]
style = "{style}"
"""
    (root / "study.toml").write_text(text)
    return root / "study.toml"


# The two-person sets the study and browser tests share (tests/conftest.py: dyadic_set, semantic_set), in solid
# bodies (a stick's one-pixel lines come out of the encoder too unlike from video to video to compare the
# interlocutor by its pixels): dyadic in 2-s items; semantic in 4-s items, long enough around the agent's keyword
# for the interlocutor to speak too, each voice on its person's side.
SET_SIZE = 192


def build_two_person_set(root, design):
    """`write_study` for `design` in `root`, built by make_stimuli into root/out at SET_SIZE."""
    from generation.make_stimuli import main as make_stimuli

    semantic = design == "semantic"
    study = write_study(root, design, length_s=4.0 if semantic else 2.0, style="solid", stereo=semantic)
    argv = [
        "--study",
        str(study),
        "--out",
        str(Path(root) / "out"),
        "--size",
        str(SET_SIZE),
        "--quiet",
        "--workers",
        "1",
    ]
    if make_stimuli(argv) != 0:
        raise RuntimeError(f"make_stimuli failed on the {design} set in {root}")
