"""Test data for studies of your own motion: a 70-joint skeleton with fingers and a face, made from real takes.

The Bandai-Namco actions (bow, bye, guide, ... ; ../shared/data/bandai-namco-actions) have 22 joints. Here each
take gets four joints per finger and eight face joints (70 in all), the fingers curling slowly, and is written:
- as BVH (the reference condition, `real/`), the extra joints with rotation channels;
- as a Z-up joint-position array in centimetres `.npy` with a skeleton JSON (a made-up system, `sys_a/`):
  the real motion smoothed and shifted by a few frames;
- as BVH again (`sys_b/`): the real rotations with noise added, so bones stay rigid but limbs tremble.
"""

import gzip
import json
from pathlib import Path

import numpy as np

from generation.data.motion_files import read_motion
from generation.motion.bvh import read_bvh

from . import paths

ACTIONS = paths.ACTIONS / "dataset-1" / "data"
FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")
FACE = ("Jaw", "Chin", "Nose", "Eye_L", "Eye_R", "Brow_L", "Brow_R", "Lid_L")  # 22 + 40 + 8 = 70 joints


def action_takes(n, pattern="*.bvh.gz"):
    """The first n action takes by name (a mix of kinds: sorted names interleave bow, bye, ... by style)."""
    takes = sorted(ACTIONS.glob(pattern), key=lambda p: (p.name.split("_")[2], p.name))
    return takes[:n]


def finger_skeleton(bvh):
    """(names, parents, offsets, channels) of the 70-joint skeleton built on a Bandai-Namco take's 22."""
    names, parents = list(bvh.names), list(bvh.parents)
    offsets, channels = [o.copy() for o in bvh.offsets], [list(c) for c in bvh.channels]
    rot = ["Zrotation", "Xrotation", "Yrotation"]
    for suffix, sign in (("L", 1.0), ("R", -1.0)):
        hand = names.index(f"Hand_{suffix}")
        for f, finger in enumerate(FINGERS):
            parent = hand
            for k in range(4):
                names.append(f"{finger}{k + 1}_{suffix}")
                parents.append(parent)
                spread = (f - 2) * 1.8 if k == 0 else 0.0
                offsets.append(np.array([sign * (3.5 if k == 0 else 2.6 - 0.4 * k), 0.0, spread]))
                channels.append(rot)
                parent = len(names) - 1
    head = names.index("Head")
    for j, face in enumerate(FACE):
        names.append(face)
        parents.append(head)
        offsets.append(np.array([4.0 + (j % 4), 6.0, (j - 3.5) * 1.2]))
        channels.append(rot)
    return names, parents, offsets, channels


def _dfs(parents):
    children = {}
    for j, p in enumerate(parents):
        children.setdefault(p, []).append(j)
    order, stack = [], list(reversed(children.get(-1, [])))
    while stack:
        j = stack.pop()
        order.append(j)
        stack += list(reversed(children.get(j, [])))
    return order, children


def write_bvh(path, names, parents, offsets, channels, motion, frame_time):
    """A BVH file (gzip when the name ends in .gz) of the joints in `names`; motion [T, C] columns in joint
    order (each joint's channels in turn), rewritten here in the hierarchy's depth-first order."""
    order, children = _dfs(parents)
    first = np.concatenate([[0], np.cumsum([len(c) for c in channels])[:-1]])
    lines = ["HIERARCHY"]

    def joint(j, depth):
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if parents[j] < 0 else 'JOINT'} {names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {' '.join(f'{v:.6f}' for v in offsets[j])}")
        lines.append(f"{pad}  CHANNELS {len(channels[j])} {' '.join(channels[j])}")
        for c in children.get(j, []):
            joint(c, depth + 1)
        if not children.get(j):
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET 0 0 0", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    joint(order[0], 0)
    cols = np.concatenate([np.arange(first[j], first[j] + len(channels[j])) for j in order])
    lines += ["MOTION", f"Frames: {len(motion)}", f"Frame Time: {frame_time:.8f}"]
    lines += [" ".join(f"{v:.5f}" for v in row) for row in motion[:, cols]]
    text = ("\n".join(lines) + "\n").encode()
    Path(path).write_bytes(gzip.compress(text, 1) if str(path).endswith(".gz") else text)


def finger_take(take, rng, noise_deg=0.0):
    """(names, parents, offsets, channels, motion, frame_time) of a take with fingers curling, `noise_deg` of
    rotation noise on every body joint's channels."""
    bvh = read_bvh(take)
    names, parents, offsets, channels = finger_skeleton(bvh)
    t = np.arange(bvh.n_frames) * bvh.frame_time
    n_extra = len(names) - len(bvh.names)
    phase = rng.uniform(0, 2 * np.pi, n_extra)
    curl = 25 + 20 * np.sin(2 * np.pi * 0.7 * t[:, None] + phase)  # degrees about the finger's Z
    extra = np.stack([curl, np.zeros_like(curl), np.zeros_like(curl)], axis=-1).reshape(len(t), -1)
    body = bvh.motion.copy()
    if noise_deg:
        rot_cols = [
            bvh.channel_columns()[j] + k
            for j, ch in enumerate(bvh.channels)
            for k, c in enumerate(ch)
            if c.endswith("rotation") and j > 1
        ]
        body[:, rot_cols] += rng.normal(0, noise_deg, (len(t), len(rot_cols)))
    return names, parents, offsets, channels, np.hstack([body, extra]), bvh.frame_time


def speech(path, text, seconds, rate=22050):
    """A WAV of `text` spoken by Debian's espeak-ng, then silence up to `seconds`; FLAC when `path` ends so."""
    import subprocess
    import wave

    raw = subprocess.run(["espeak-ng", "--stdout", "-s", "190", text], capture_output=True, check=True).stdout
    with wave.open(__import__("io").BytesIO(raw)) as w:
        rate, pcm = w.getframerate(), np.frombuffer(w.readframes(w.getnframes()), "<i2")
    pcm = np.concatenate([pcm, np.zeros(max(0, int(seconds * rate) - len(pcm)), "<i2")])
    wav = Path(path).with_suffix(".wav")
    with wave.open(str(wav), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(rate)
        w.writeframes(pcm.tobytes())
    if str(path).endswith(".flac"):
        import imageio_ffmpeg

        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", "-i", str(wav), str(path)], check=True)
        wav.unlink()
    return Path(path)


NUMBERS = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")


# A study file's table that turns the gesture measures off, for a test whose subject they are not: a study with
# speech, an SMPL-family body or a speech-gesture skeleton measures them by default (docs/metrics.md), and so trains
# an encoder on its reference, seconds of CPU wherever the user's encoder cache does not hold it yet.
NO_GESTURE_MEASURES = "[metrics]\ngesture = false\n"


def make_study(root, n_items=8, n_catch=3, fps=20, extra_toml="", audio=False, samples=0):
    """A study from folders at `root`: real/ (70-joint BVH), sys_a/ (.npy, Z-up cm, + skeleton.json), sys_b/
    (BVH), and study.toml; with `audio`, audio/ITEM.wav (one .flac) of synthesised speech and an [audio] table;
    with `samples`, sys_b is a stochastic system: sys_b/ITEM/1.bvh ... each with noise of its own.
    Returns the study file's path."""
    root = Path(root)
    for sub in ("real", "sys_a", "sys_b"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    skeleton = None
    for k, take in enumerate(action_takes(n_items)):
        stem = f"item{k:02d}"
        names, parents, offsets, channels, motion, dt = finger_take(take, rng)
        write_bvh(root / "real" / f"{stem}.bvh.gz", names, parents, offsets, channels, motion, dt)
        for sample in range(1, samples + 1) if samples else [None]:
            *_, noisy, _ = finger_take(take, rng, noise_deg=1.0 * (sample or 1))
            where = root / "sys_b" / (f"{stem}.bvh" if sample is None else f"{stem}/{sample}.bvh")
            where.parent.mkdir(exist_ok=True)
            write_bvh(where, names, parents, offsets, channels, noisy, dt)
        m = read_motion(root / "real" / f"{stem}.bvh.gz", fps=30.0, units="cm")
        j = m.joints.astype(np.float64)
        kernel = np.ones(5) / 5
        smooth = np.apply_along_axis(lambda v: np.convolve(np.pad(v, 2, mode="edge"), kernel, "valid"), 0, j)
        smooth = np.concatenate([smooth[3:], np.repeat(smooth[-1:], 3, 0)])  # 0.1 s late
        zup_cm = np.stack([smooth[..., 0], -smooth[..., 2], smooth[..., 1]], axis=-1) * 100
        np.save(root / "sys_a" / f"{stem}.npy", zup_cm.astype(np.float32))
        skeleton = dict(names=m.names, parents=[None if p < 0 else m.names[p] for p in m.parents])
        if audio:
            (root / "audio").mkdir(exist_ok=True)
            words = " ".join(NUMBERS[int(d)] for d in f"{k + 1:02d}") + ", here is the motion"
            speech(root / "audio" / f"{stem}.{'flac' if k == 0 else 'wav'}", words, m.seconds + 1.0)
    (root / "skeleton.json").write_text(json.dumps(skeleton))
    study = root / "study.toml"
    study.write_text(
        f"""reference = "real"
seed = 1
n_training = 1
fps = {fps}

[conditions]
real = "real"
SYS_A = "sys_a"
SYS_B = "sys_b"

[catch]
make = ["jitter", "freeze", "swap"]
n = {n_catch}

[skeleton]
file = "skeleton.json"
fps = 30
{extra_toml}{"[audio]" + chr(10) + 'folder = "audio"' + chr(10) if audio else ""}"""
    )
    return study
