"""What the gesture measures add to a study's build, and why the FGD's encoder reads velocities.

1. Build time: the two-person demo study (generation.own_study.demo_dyad: real action takes, two made-up systems,
   a voice for each person) built by `python -m generation.make_stimuli --study` in a fresh process, with its
   study file as it is (a gesture study: every measure) and with `[metrics] gesture = false` (the same build
   without them), in turn, each into a fresh folder (so no build reuses another's videos) and each gesture build
   with an empty encoder cache (so it trains), the order of the two alternating between repeats; a third build with
   the cache filled gives the time without the training. Whole builds on a shared machine vary by more than the
   measures cost, so the measures' own time (the build's summary states it) is given too, per clip and over the
   same run's build without them.
2. `--inputs`: the FGD's separation on real gestures (../shared/data/bandai-namco-actions, 30 takes of 22 joints)
   with the encoder reading positions alone, velocities alone, or positions, velocities and accelerations (shipped):
   the FGD of catch clips (jitter, freeze, swap) of a held-out half against the other half, over the held-out half's
   own FGD (the floor), for several training seeds.

    python bench/bench_gesture_measures.py [--items 8] [--repeat 2] [--size 128] [--inputs]
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from generation.metrics import gesture_fgd, joint_groups  # noqa: E402
from generation.own_study import demo_dyad  # noqa: E402


def build(study, out, size, cache):
    """(seconds of one build of `study` into `out` in a fresh process, with the encoder cache at `cache`; the seconds
    the gesture measures took, as its summary says, or 0)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(cache)}
    cmd = [sys.executable, "-m", "generation.make_stimuli", "--study", str(study), "--out", str(out)]
    t0 = time.perf_counter()
    done = subprocess.run(
        [*cmd, "--size", str(size), "--quiet"], check=True, cwd=ROOT, env=env, capture_output=True, text=True
    )
    seconds = time.perf_counter() - t0
    found = re.search(r"gesture measures per condition \(gesture.csv; measured in ([\d.]+) s\)", done.stdout)
    return seconds, float(found[1]) if found else 0.0


def build_times(args):
    loads = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        study = demo_dyad.build(tmp / "in", args.items, "dyadic", 0)
        off = study.with_name("study_off.toml")
        off.write_text(study.read_text() + "\n[metrics]\ngesture = false\n")
        runs = {"without": [], "with": [], "cached": []}
        for r in range(args.repeat):
            cache = tmp / f"cache{r}"
            order = [("without", off), ("with", study)]  # "with" trains: its cache is empty
            for name, spec in order if r % 2 == 0 else order[::-1]:
                runs[name].append(build(spec, tmp / f"{name}{r}", args.size, cache))
                loads.append(os.getloadavg()[0])
            runs["cached"].append(build(study, tmp / f"cached{r}", args.size, cache))
            loads.append(os.getloadavg()[0])
        clips = sum(1 for _ in open(tmp / "with0" / "manifest.csv")) - 1
    total = {k: np.array([t for t, _ in v]) for k, v in runs.items()}
    step = {k: np.array([m for _, m in v]) for k, v in runs.items()}
    print(f"load average (1 min) after each build {min(loads):.2f}-{max(loads):.2f}; {clips} clips, {args.size} px")
    for name in runs:
        builds, measures = (" ".join(f"{x:.1f}" for x in v[name]) for v in (total, step))
        print(f"  {name:<8} build {builds} s; measures {measures} s")
    print(f"  build with/without: {' '.join(f'{x:.3f}' for x in total['with'] / total['without'])}")
    print(f"  the measures' own time over the build without them: "
          f"{' '.join(f'{x:.3f}' for x in step['with'] / total['without'])} training, "
          f"{' '.join(f'{x:.3f}' for x in step['cached'] / total['without'])} cached")  # fmt: skip
    print(f"  the measures per clip: {' '.join(f'{x / clips:.3f}' for x in step['with'])} s training, "
          f"{' '.join(f'{x / clips:.3f}' for x in step['cached'])} s cached; the build without them "
          f"{' '.join(f'{x / clips:.3f}' for x in total['without'])} s a clip")  # fmt: skip


def encoder_inputs(args):
    from generation.data.motion_files import read_motion
    from generation.stimuli.catch_kinds import make_catch

    source = demo_dyad.actions_dir()
    takes = sorted(source.glob("*.bvh.gz"), key=lambda p: (p.name.split("_")[2], p.name))
    motions = [m for m in (read_motion(p, 30.0) for p in takes[:34]) if len(m.names) == 22][:30]
    parents = motions[0].parents
    train, held = [m.joints for m in motions[0::2]], [m.joints for m in motions[1::2]]
    shipped = gesture_fgd.pose_rows

    def rows(kind):
        def pick(joints, parents, fps):
            full = shipped(joints, parents, fps)
            d = joints.shape[1] * 3
            return {"positions": full[:, :d], "velocities": full[:, d : 2 * d], "all three": full}[kind]

        return pick

    print(f"load average {os.getloadavg()[0]:.2f}; FGD of catch clips over the held-out half's own (the floor)")
    for kind in ("positions", "velocities", "all three"):
        gesture_fgd.pose_rows = rows(kind)
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            enc = gesture_fgd.GestureEncoder.train(train, parents, 30.0, seed=seed, cache=False)
            seconds = time.perf_counter() - t0
            ref = np.concatenate([enc.features(j) for j in train])
            floor = gesture_fgd.fgd(np.concatenate([enc.features(j) for j in held]), ref)
            ratios = {
                k: gesture_fgd.fgd(np.concatenate([enc.features(make_catch(j, k, i)) for i, j in enumerate(held)]), ref)
                / floor
                for k in ("jitter", "freeze", "swap")
            }
            noisy = [j + np.random.default_rng(seed).normal(0, 0.01, j.shape) for j in held]
            ratios["1 cm noise"] = gesture_fgd.fgd(np.concatenate([enc.features(j) for j in noisy]), ref) / floor
            text = ", ".join(f"{k} {v:.2f}" for k, v in ratios.items())
            print(f"  {kind:<11} seed {seed}: floor {floor:.0f}; {text}; trained in {seconds:.1f} s")
    gesture_fgd.pose_rows = shipped
    print(f"({len(train)} + {len(held)} takes, {joint_groups.root_index(parents)} the root)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--items", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--inputs", action="store_true", help="the encoder's inputs instead of the build time")
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    encoder_inputs(args) if args.inputs else build_times(args)


if __name__ == "__main__":
    main()
