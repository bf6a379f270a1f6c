"""The made-up challenge of `python -m analysis.challenge_demo`: test inputs, three teams' submissions and two
tasks' study files, from real takes.

    python -m generation.challenge.demo_inputs --out DIR [--items 6] [--seconds 4] [--seed 0]

Writes into DIR (docs/challenge.md walks the steps they stand for):
- `inputs/speech/ITEM.wav`: the released inputs, a sentence per item spoken by Debian's espeak-ng, as long as the
  item's motion (the intake takes each item's length from it);
- `reference/ITEM.npz`: the organiser's real motion, each item a stretch of a take of
  ../shared/data/bandai-namco-actions (bows, waves, guides...) at 30 fps;
- `submissions/`, one folder per team, as each first submits:
  - `TEAM_A/ITEM.npz`: a deterministic system, each take's joints smoothed and 0.15 s late;
  - `TEAM_B/ITEM.npz`: a deterministic system whose first submission is broken: one item missing, one exported at
    25 fps, one with NaN frames;
  - `TEAM_C/ITEM/1.npz .. 5.npz`: a stochastic system, five samples per item, the real joints shaken as a whole
    (every bone keeps its length) by a tremor whose size differs from sample to sample;
- `resubmissions/TEAM_B/`: team B's fixed folder, the real joints with a small tremor;
- `realism.toml` (acr, each rater shown a sample of TEAM_C drawn for them) and `speech.toml` (appropriateness,
  with the speech, one sample of TEAM_C drawn per item), whose conditions are the reference and the teams'
  folders under `submissions/`, and `tasks.json`, {task: the design that serves it}.

The data set has no sound of its own, so the speech is unrelated to the motion (as in own_study.demo_study): the
demo shows a challenge's mechanics, not a real speech-gesture pairing.
"""

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from moglow_eval.core import cli
from moglow_eval.core.clip import save_clip

from ..data.motion_files import read_motion
from ..own_study.demo_study import SENTENCES, actions_dir, speak
from ..own_study.study_people import STIMULUS_DESIGNS

FPS = 30.0
TEAMS = ("TEAM_A", "TEAM_B", "TEAM_C")
SAMPLES = 5
TREMOR_M = (0.002, 0.004, 0.007, 0.011, 0.016)  # TEAM_C's samples: the tremor's size, metres, shuffled per item
# The two tasks: their design, how TEAM_C's samples are drawn, and whether the videos carry the speech.
TASKS = {"realism": ("acr", "rater", False), "speech": ("appropriateness", "item", True)}
AUDIO = '\n[audio]\nfolder = "inputs/speech"\nloudness = -23\n'


def _takes(n, frames):
    """(names, parents, [joints [frames, J, 3]]) of n takes of one skeleton, each at least `frames` long."""
    source = actions_dir()
    if source is None:
        raise cli.UserError("../shared/data/bandai-namco-actions not found beside the checkout: the demo needs it")
    kept, names, parents = [], None, None
    for take in sorted(source.glob("*.bvh.gz"), key=lambda p: (p.name.split("_")[2], p.name)):
        m = read_motion(take, FPS)
        if len(m.joints) < frames or (names is not None and m.names != names):
            continue
        names, parents = m.names, m.parents
        kept.append(m.joints[:frames].astype(np.float64))
        if len(kept) == n:
            return names, parents, kept
    raise cli.UserError(f"{source}: fewer than {n} takes of {frames / FPS:g} s with one skeleton")


def _smooth_late(j, parents):
    """Each joint's path smoothed and 0.15 s late, every bone then put back to its real length (averaging positions
    shortens a turning bone, which the intake would refuse)."""
    kernel = np.ones(7) / 7
    smooth = np.apply_along_axis(lambda v: np.convolve(np.pad(v, 3, mode="edge"), kernel, "valid"), 0, j)
    late = int(0.15 * FPS)
    smooth = np.concatenate([np.repeat(smooth[:1], late, 0), smooth[:-late]])
    out = smooth.copy()
    for c, p in enumerate(parents):  # parents come before their children
        if p < 0:
            continue
        length = np.median(np.linalg.norm(j[:, c] - j[:, p], axis=-1))
        bone = smooth[:, c] - smooth[:, p]
        norm = np.linalg.norm(bone, axis=-1, keepdims=True)
        out[:, c] = out[:, p] + bone / np.maximum(norm, 1e-9) * length
    return out


def _tremor(j, rng, size):
    """The whole body shaken by a smooth random tremor of `size` metres: every bone keeps its length."""
    steps = rng.normal(0, size, (len(j) + 4, 3))
    shake = np.stack([np.convolve(steps[:, a], np.ones(5) / 5, "valid") for a in range(3)], axis=1)
    return j + shake[: len(j), None, :] * np.sqrt(5)


def _resampled(j, fps):
    """Joints at another frame rate (linear), as a team that exported at the wrong rate would give them."""
    t = np.arange(len(j)) / FPS
    t_new = np.arange(int(round(len(j) * fps / FPS))) / fps
    flat = j.reshape(len(j), -1)
    return np.stack([np.interp(t_new, t, flat[:, c]) for c in range(flat.shape[1])], axis=1).reshape(
        len(t_new), *j.shape[1:]
    )


def build(out, n_items=6, seconds=4.0, seed=0):
    """Write the demo challenge's inputs, submissions and study files into `out`; returns `out`."""
    if shutil.which("espeak-ng") is None:
        raise cli.UserError("the challenge demo speaks with espeak-ng: install it (apt-get install espeak-ng)")
    out = Path(out)
    frames = int(round(seconds * FPS))
    names, parents, takes = _takes(n_items, frames)
    rng = np.random.default_rng(seed)
    save = lambda path, joints, fps=FPS: save_clip(path, joints, parents, names, fps)  # noqa: E731
    for k, j in enumerate(takes):
        item = f"item{k:02d}"
        speak(out / "inputs" / "speech" / f"{item}.wav", SENTENCES[k % len(SENTENCES)], frames / FPS, exact=True)
        save(out / "reference" / f"{item}.npz", j)
        save(out / "submissions" / "TEAM_A" / f"{item}.npz", _smooth_late(j, parents))
        broken = out / "submissions" / "TEAM_B" / f"{item}.npz"
        if k == 1:
            pass  # missing
        elif k == 2:
            save(broken, _resampled(j, 25.0), 25.0)
        elif k == 3:
            bad = _tremor(j, rng, 0.003)
            bad[10:14] = np.nan
            np.savez_compressed(broken, joints=bad.astype(np.float32), parents=parents, joint_names=np.asarray(names),
                                fps=np.float64(FPS))  # fmt: skip
        else:
            save(broken, _tremor(j, rng, 0.003))
        save(out / "resubmissions" / "TEAM_B" / f"{item}.npz", _tremor(j, rng, 0.003))
        for s, size in enumerate(rng.permutation(TREMOR_M)):
            save(out / "submissions" / "TEAM_C" / item / f"{s + 1}.npz", _tremor(j, rng, size))
    for task, (design, draw, audio) in TASKS.items():
        (out / f"{task}.toml").write_text(
            f"""# The demo challenge's {task} task (generation.challenge.demo_inputs): the reference and three teams.
reference = "real"
seed = {seed + 7}
n_training = 1
length_s = {min(seconds, 3.0):g}
{f'design = "{design}"' if design in STIMULUS_DESIGNS else ""}
[conditions]
real = "reference"
TEAM_A = "submissions/TEAM_A"
TEAM_B = "submissions/TEAM_B"
TEAM_C = "submissions/TEAM_C"

[catch]
make = ["jitter", "freeze", "swap"]
n = 2

[samples]
draw = "{draw}"
{AUDIO if audio else ""}"""
        )
    # Which design serves each task: the study files name only the designs whose stimuli differ (appropriateness).
    (out / "tasks.json").write_text(json.dumps({task: design for task, (design, _, _) in TASKS.items()}) + "\n")
    return out


def build_parser():
    ap = cli.ArgumentParser(prog="python -m generation.challenge.demo_inputs", description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="folder for the inputs, the submissions and the study files")
    ap.add_argument("--items", type=cli.number(int, 4, 40), default=6, help="test items (default 6)")
    ap.add_argument("--seconds", type=cli.number(float, 2, 20), default=4.0, help="each item's length (default 4)")
    ap.add_argument("--seed", type=cli.number(int, 0), default=0)
    return ap


def _main(argv):
    args = build_parser().parse_args(argv)
    cli.folder_to_write(args.out, "the challenge's folder")
    out = Path(args.out)
    if out.exists() and any(out.iterdir()):
        raise cli.UserError(f"--out {out}: not empty; give a new folder")
    print(build(out, args.items, args.seconds, args.seed))
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
