"""Where generated foot skating comes from: frame-to-frame noise or slow sliding, and which way the feet slide.

    python bench/skating_causes.py --data runs/dataset.npz [--model MG=generation/pretrained/mg.pt]
        [--model FL=generation/pretrained/fl.pt] [--cutoff 2 4 6]

Every test window is sampled once per model (seed 0; temperature 1, as make_stimuli samples, unless
--temperature). Each clip, NAT's included, is then low-passed along time (zero-phase 4th-order Butterworth on the
root-frame pose features) at each --cutoff in Hz, and foot skating and jerk (generation.metrics.objective, in world
coordinates) are measured again. The table gives medians over the windows as ratios to NAT's at the same cutoff.

How to read it: if a model's skating ratio falls to NAT's level once the high frequencies are gone, its feet
slide because each frame is sampled with independent noise (a density too wide around the next pose). If the
ratio stays high, the feet slide slowly and steadily: the stance foot is not tied to the floor at all.

A second table looks at the frames where a foot is in contact (objective.foot_contacts) while the root
moves at over 0.3 m/s. It gives the foot's world velocity along the root's direction of travel (signed: positive
means carried forward with the body, i.e. the leg sweeps back more slowly than the control moves the root) and
across it (unsigned), as medians, and their share of the root's speed. A third gives that share per 1-s stretch
of the clips: drift that grows along the clip builds up frame by frame as the model feeds on its own output.
"""

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np
import torch
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from generation.data.dataset import read_arrays, require  # noqa: E402
from generation.metrics.objective import foot_contacts, foot_skating, jerk  # noqa: E402
from generation.motion import skeleton  # noqa: E402
from generation.motion.features import to_world  # noqa: E402
from generation.sampling.pretrained import CHECKPOINTS  # noqa: E402
from generation.sampling.sample import load_model, sample_split  # noqa: E402
from moglow_eval.core.study import NATURAL as NAT  # noqa: E402


def low_pass(x, cutoff, fps):
    """x [T, D] along time; the clip itself when cutoff is 0."""
    if not cutoff:
        return x
    b, a = signal.butter(4, cutoff / (fps / 2))
    return signal.filtfilt(b, a, x, axis=0, padlen=min(len(x) - 1, 3 * max(len(a), len(b))))


def stance_drift(world, fps, moving=0.3):
    """Per contact frame pair of either foot while the root moves faster than `moving` (m/s): the foot's world
    velocity along the root's travel (signed), across it (unsigned), and the root's speed -> three arrays."""
    root = np.diff(world[:, 0, [0, 2]], axis=0) * fps
    speed = np.linalg.norm(root, axis=1)
    heading = root / np.maximum(speed[:, None], 1e-9)
    contact = foot_contacts(world)
    along, across, speeds = [], [], []
    for f, pair in enumerate(np.asarray(skeleton.FEET).reshape(-1, 2)):
        v = np.diff(world[:, pair][..., [0, 2]], axis=0).mean(axis=1) * fps
        m = contact[f] & (speed > moving)
        along.append((v[m] * heading[m]).sum(axis=1))
        across.append(np.abs(v[m, 0] * heading[m, 1] - v[m, 1] * heading[m, 0]))
        speeds.append(speed[m])
    return np.concatenate(along), np.concatenate(across), np.concatenate(speeds)


def pooled_drift(xs, c, fps, frames=slice(None)):
    """stance_drift over every clip of a system (only `frames` of each), pooled -> (along, across, speed)."""
    parts = [stance_drift(to_world(x[frames], ci[frames]), fps) for x, ci in zip(xs, c)]
    return tuple(np.concatenate(v) for v in zip(*parts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="prepared dataset .npz (test split)")
    ap.add_argument("--model", action="append", metavar="NAME=CHECKPOINT")
    ap.add_argument("--cutoff", type=float, nargs="+", default=[6.0, 4.0, 2.0], help="low-pass cutoffs (Hz)")
    ap.add_argument("--temperature", type=float, default=1.0, help="(make_stimuli's default is 1.0)")
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    models = a.model or [f"MG={CHECKPOINTS['mg']}", f"FL={CHECKPOINTS['fl']}"]
    d = read_arrays(a.data, ["test_x", "test_c", "fps"])
    require(d, ["test_x", "test_c", "fps"], a.data)
    c, fps = d["test_c"], float(d["fps"])
    systems = {NAT: d["test_x"]}
    for spec in models:
        name, _, ckpt = spec.partition("=")
        systems[name] = sample_split(load_model(ckpt), a.data, "test", temperature=a.temperature, seed=0)[0]
    cutoffs = [0.0] + a.cutoff
    med = {}
    for name, xs in systems.items():
        for f in cutoffs:
            worlds = [to_world(low_pass(xs[i], f, fps), c[i]) for i in range(len(c))]
            med[name, f] = (
                statistics.median(foot_skating(w, fps) for w in worlds),
                statistics.median(jerk(w, fps) for w in worlds),
            )
    label = lambda f: "raw" if not f else f"low-pass {f:g} Hz"  # noqa: E731
    print("| system | " + " | ".join(f"skating / NAT, {label(f)}" for f in cutoffs) + " | jerk / NAT, raw |")
    print("|---|" + "---|" * (len(cutoffs) + 1))
    nat = " | ".join(f"{med[NAT, f][0]:.3f}" for f in cutoffs)
    print(f"| NAT (m/s) | {nat} | {med[NAT, 0.0][1]:.0f} m/s^3 |")
    for name in list(systems)[1:]:
        cells = [f"{med[name, f][0] / med[NAT, f][0]:.1f}" for f in cutoffs]
        print(f"| {name} | " + " | ".join(cells) + f" | {med[name, 0.0][1] / med[NAT, 0.0][1]:.2f} |")

    print("\nfeet in contact while the root moves (> 0.3 m/s): medians over those frame pairs")
    print("| system | frame pairs | along travel (m/s) | across (m/s) | along / root speed | root speed (m/s) |")
    print("|---|---|---|---|---|---|")
    for name, xs in systems.items():
        along, across, speed = pooled_drift(xs, c, fps)
        print(
            f"| {name} | {len(along)} | {np.median(along):.3f} | {np.median(across):.3f} | "
            f"{np.median(along / speed):.3f} | {np.median(speed):.2f} |"
        )

    seconds = range(0, len(c[0]), int(fps))
    print("\nstance foot along travel / root speed, medians per second of the clips")
    print("| system | " + " | ".join(f"{t / fps:g}-{min(t + int(fps), len(c[0])) / fps:g} s" for t in seconds) + " |")
    print("|---|" + "---|" * len(seconds))
    for name, xs in systems.items():
        cells = []
        for t in seconds:
            along, _, speed = pooled_drift(xs, c, fps, slice(t, t + int(fps)))
            cells.append(f"{np.median(along / speed):.3f}")
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
