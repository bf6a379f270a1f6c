"""FL's posture against the mocap's (issue 34, item 3): what an FL checkpoint samples on every held-out window.

    python bench/fl_posture.py [--fl CKPT ...] [--temperature 1.0 ...] [--data runs/dataset.npz]

Each checkpoint samples the 192 held-out windows (valid + test, generation/pretrained/heldout.npz) once per
temperature; the samples go onto the actor's bones as make_stimuli ships them (generation.motion.rigid). Printed per
checkpoint and temperature:
- FMD over the floor: the Fréchet motion distance to training motion of the same categories, over NAT's of the same
  windows (generation.metrics.fmd);
- pose error: the largest distance of a joint's mean root-frame position from NAT's on the same windows (cm);
- hand height: the left hand's height over all frames, 5th, 50th and 95th percentile (cm), beside NAT's;
- posture spread: how far the windows' mean poses spread (summed standard deviation over the windows, per
  coordinate) over NAT's: below 1, FL gives every window more of one posture than the mocap does;
- the worst joint's mean jerk, the median foot skating and the worst category's late stepping, over NAT's.
With --data (the prepared dataset the model was trained on) it also prints the largest variance of the latents of
192 real training windows along any one direction. A model whose latents of real motion are standard normal gives
about 1; where real motion sits far out along a few directions, standard-normal samples never reach its postures.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from rigid_bones import per_window, summary  # noqa: E402  (bench/, beside this file)

from generation.data.dataset import heldout_windows, load_dataset, read_arrays  # noqa: E402
from generation.metrics.fmd import MotionEncoder  # noqa: E402
from generation.metrics.objective import joint_jerk  # noqa: E402
from generation.motion import rigid, skeleton  # noqa: E402
from generation.motion.features import to_world  # noqa: E402
from generation.sampling.pretrained import CHECKPOINTS, HELDOUT, MOTION_ENCODER  # noqa: E402
from generation.sampling.sample import load_model, sample_windows  # noqa: E402

HAND = skeleton.INDEX["Hand_L"]


def figures(s, x, c, labels, lengths, fps, encoder, floor, nat_jerk):
    """The printed figures of samples s [N, T, 63] against NAT x on the same windows (jerk, skating and late
    stepping as bench/rigid_bones.py computes them; nat_jerk: NAT's mean jerk per joint)."""
    motion = summary([per_window(s, c, x, lengths, fps)], nat_jerk, labels)
    offset = (s - x).reshape(-1, skeleton.N_JOINTS, 3).mean(0)
    hand = lambda p: np.percentile(p.reshape(-1, skeleton.N_JOINTS, 3)[:, HAND, 1] * 100, [5, 50, 95])  # noqa: E731
    return dict(
        fmd=encoder.fmd(s, labels) / floor,
        pose_cm=float(np.linalg.norm(offset, axis=1).max() * 100),
        spread=float(s.mean(axis=1).std(axis=0).sum() / x.mean(axis=1).std(axis=0).sum()),
        hand=hand(s),
        nat_hand=hand(x),
        jerk=motion["jerk_max"],
        jerk_joint=motion["jerk_worst"],
        skating=motion["skating"],
        late=motion["late_min"],
    )


@torch.no_grad()
def latent_spread(model, data, n=192):
    """Largest variance along one direction of the latents of n real training windows (not augmented)."""
    ds = load_dataset(data)
    aug = read_arrays(data, ["train_aug"])["train_aug"]
    rows = np.flatnonzero(aug == 0)[:: max(1, int((aug == 0).sum()) // n)][:n]
    split = ds.splits["train"]
    z, _ = model(split.x[rows], split.c[rows])
    z = z.double().numpy()
    s = np.linalg.svd(z - z.mean(0), compute_uv=False)
    return float(s[0] ** 2 / len(z))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fl", action="append", help="FL checkpoint (repeatable; default: the shipped one)")
    ap.add_argument("--temperature", type=float, action="append", help="repeatable; default 1.0")
    ap.add_argument("--data", help="the prepared dataset, for the latent spread of real training windows")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    x, c, hist, labels = heldout_windows(HELDOUT, ("x", "c", "hist", "labels"))
    fps, lengths = float(read_arrays(HELDOUT, ["fps"])["fps"]), rigid.bone_lengths(hist)
    encoder = MotionEncoder.load(MOTION_ENCODER)
    floor = encoder.fmd(x, labels)
    nat_jerk = joint_jerk(to_world(x, c), fps).mean(0)
    for ckpt in args.fl or [str(CHECKPOINTS["fl"])]:
        model = load_model(ckpt, "cpu")
        spread = f" | latent spread {latent_spread(model, args.data):.1f}" if args.data else ""
        print(f"{ckpt}{spread}")
        for t in args.temperature or [1.0]:
            s = rigid.fit_bones(sample_windows(model, c, temperature=t, seed=args.seed), lengths)
            f = figures(s, x, c, labels, lengths, fps, encoder, floor, nat_jerk)
            print(
                f"  temperature {t}: FMD/floor {f['fmd']:.2f} | pose error {f['pose_cm']:.1f} cm | hand height "
                f"{'/'.join(f'{v:.0f}' for v in f['hand'])} cm (NAT {'/'.join(f'{v:.0f}' for v in f['nat_hand'])})"
                f" | posture spread {f['spread']:.2f} | jerk max {f['jerk']:.2f} ({f['jerk_joint']}) | skating"
                f" {f['skating']:.2f} | late stepping min {f['late']:.2f}"
            )


if __name__ == "__main__":
    sys.exit(main())
