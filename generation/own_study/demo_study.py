"""A small study of your own motion with sound, for `python -m analysis.demo --sound` (and `--design
appropriateness`): real non-locomotion mocap as the reference, two made-up systems, synthesised speech.

    python -m generation.own_study.demo_study --out DIR [--items 12] [--appropriateness]

Writes DIR/study.toml and its folders (CONTRACTS §10):
- `real/`: takes of ../shared/data/bandai-namco-actions (bows, waves, guides, punches...), copied as they are;
- `smooth/`: each take's joint positions smoothed and 0.15 s late, as `.npy` with `skeleton.json`;
- `tremble/`: each take's joint positions with independent noise of 1.5 cm per joint and frame, as `.npy`;
- `audio/`: a sentence per item spoken by Debian's espeak-ng, with silence up to the take's length.

The data set has no sound of its own, so the speech is unrelated to the motion: the study shows the mechanics of
a GENEA-style test (sound in the videos, the sound check, matched against mismatched motion), not a real
speech-gesture pairing.
"""

import json
import shutil
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np

from moglow_eval.core import cli
from moglow_eval.core.study import SPEECH_DEMO_ITEMS

from ..data.motion_files import read_motion
from ..data.prepare import default_data_dir

SENTENCES = (
    "Good morning, and welcome to the show.",
    "Please follow me this way, the room is on the left.",
    "I am so sorry, but I really have to go now.",
    "Look over there, can you see it?",
    "Thank you very much for coming today.",
    "Hello again, it is good to see you.",
    "This is the most important part of the story.",
    "Wait a moment, I will be right back.",
    "Over here, everyone, the bus is leaving.",
    "No, no, that is not what I meant at all.",
    "Let me show you how it works.",
    "Goodbye, and see you tomorrow.",
)
FPS = 30.0  # the .npy arrays' frame rate


def actions_dir():
    """../shared/data/bandai-namco-actions/dataset-1/data beside the checkout, or None."""
    loco = default_data_dir()
    folder = (loco.parent if loco else Path("../shared/data")) / "bandai-namco-actions" / "dataset-1" / "data"
    return folder if folder.is_dir() else None


def speak(path, text, seconds, exact=False):
    """`text` spoken by espeak-ng into the WAV `path`, padded with silence to `seconds` (and, `exact`, cut to it)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    raw = subprocess.run(["espeak-ng", "--stdout", "-s", "165", text], capture_output=True, check=True).stdout
    tmp = path.with_suffix(".tmp.wav")
    tmp.write_bytes(raw)
    with wave.open(str(tmp)) as w:
        rate, pcm = w.getframerate(), np.frombuffer(w.readframes(w.getnframes()), "<i2")
    tmp.unlink()
    pcm = np.concatenate([pcm, np.zeros(max(0, int(seconds * rate) - len(pcm)), "<i2")])
    if exact:
        pcm = pcm[: int(round(seconds * rate))]
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(pcm.tobytes())


def build(out, n_items=12, appropriateness=False, seed=0):
    """Write the demo study into `out`; returns the study file's path."""
    source = actions_dir()
    if source is None:
        raise cli.UserError(
            "../shared/data/bandai-namco-actions not found beside the checkout: the sound demo needs it"
        )
    if shutil.which("espeak-ng") is None:
        raise cli.UserError("the sound demo speaks with espeak-ng: install it (apt-get install espeak-ng)")
    out = Path(out)
    for sub in ("real", "smooth", "tremble", "audio"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    takes = sorted(source.glob("*.bvh.gz"), key=lambda p: (p.name.split("_")[2], p.name))
    kept, skeleton = 0, None
    for take in takes:
        if kept == n_items:
            break
        m = read_motion(take, FPS)
        if skeleton is not None and m.names != skeleton["names"]:
            continue  # a take with another joint set (an End Site of its own): one skeleton per study
        stem = f"item{kept:02d}"
        shutil.copyfile(take, out / "real" / f"{stem}.bvh.gz")
        j = m.joints.astype(np.float64)
        kernel = np.ones(7) / 7
        smooth = np.apply_along_axis(lambda v: np.convolve(np.pad(v, 3, mode="edge"), kernel, "valid"), 0, j)
        late = int(0.15 * FPS)
        smooth = np.concatenate([np.repeat(smooth[:1], late, 0), smooth[:-late]])
        np.save(out / "smooth" / f"{stem}.npy", smooth.astype(np.float32))
        np.save(out / "tremble" / f"{stem}.npy", (j + rng.normal(0, 0.015, j.shape)).astype(np.float32))
        speak(out / "audio" / f"{stem}.wav", SENTENCES[kept % len(SENTENCES)], m.seconds + 0.5)
        skeleton = dict(names=m.names, parents=[int(p) for p in m.parents])
        kept += 1
    (out / "skeleton.json").write_text(json.dumps(skeleton))
    design = 'design = "appropriateness"\n' if appropriateness else ""
    study = out / "study.toml"
    study.write_text(
        f"""# A demo study with sound (own_study.demo_study): real actions as the reference, two made-up systems.
reference = "real"
seed = {seed}
n_training = 2
{design}
[conditions]
real = "real"
SMOOTH = "smooth"
TREMBLE = "tremble"

[catch]
make = ["jitter", "freeze", "swap"]
n = 4

[skeleton]
file = "skeleton.json"
fps = {FPS:g}

[audio]
folder = "audio"
loudness = -23
"""
    )
    return study


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.own_study.demo_study", description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="folder for the study file and its folders")
    ap.add_argument("--items", type=cli.number(int, *SPEECH_DEMO_ITEMS), default=12, help="items (default 12)")
    ap.add_argument("--appropriateness", action="store_true", help="also make the mismatched clips")
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.folder_to_write(args.out, "the study's folder")
    print(build(args.out, args.items, args.appropriateness, args.seed))
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
