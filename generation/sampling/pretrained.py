"""The models and held-out data shipped in the repository, so that the default stimulus set needs no training.

    python -m generation.sampling.pretrained --mg MG.pt --bad MG_EARLY.pt --fl FL.pt --data runs/dataset.npz

writes generation/pretrained/{mg,bad,fl}.pt (checkpoints of generation.training.train with their weights in float16:
half the size, and no visible change in the sampled motion, which sample.load_model runs in float32) and
heldout.npz: the valid and test windows with their tau real history frames, the standardisation and the
skeleton, which is all make_stimuli reads of a prepared dataset, and quality.json, the models' foot skating
and jerk against NAT's on part of the test split (`quality`), which the tests hold them to. The motion is from
the Bandai-Namco-Research-Motiondataset (Bandai Namco Research Inc.), licensed CC BY-NC 4.0: non-commercial use
only, with attribution.
"""

import json
import sys
from pathlib import Path

import numpy as np

from moglow_eval.core import cli, study

from ..data.dataset import HELD_OUT, WINDOW_KEYS, heldout_windows, read_arrays, require
from ..data.torch_files import load_torch_file

FOLDER = Path(__file__).resolve().parents[1] / "pretrained"
CHECKPOINTS = {"mg": FOLDER / "mg.pt", "fl": FOLDER / "fl.pt", "bad": FOLDER / "bad.pt"}
HELDOUT = FOLDER / "heldout.npz"
# The sampling temperature of each model in the stimuli (make_stimuli's default, and the quality guard's). MG's
# excess jerk is the spread its flow puts on each frame's step: at 0.5 every joint's jerk and its foot skating come
# close to real motion's while its FMD holds; FL's jerk does not change with the temperature, so FL keeps 1
# (bench/RESULTS.md#model-realism). The bad examples (the earliest MG checkpoint) keep the paper's temperature 1
# too: they are meant to look broken.
TEMPERATURE = {"MG": 0.5, "FL": 1.0, "BAD": 1.0}
MOTION_ENCODER = FOLDER / "motion_encoder.pt"  # generation.metrics.fmd, for the FMD
QUALITY = FOLDER / "quality.json"
QUALITY_STRIDE = 4  # every 4th test window: about 25 windows spread over all categories
ATTRIBUTION = (
    "Bandai-Namco-Research-Motiondataset, Bandai Namco Research Inc., CC BY-NC 4.0 "
    "(https://creativecommons.org/licenses/by-nc/4.0/); windows of held-out takes, re-expressed as "
    "21-joint root-frame features"
)
SHARED_KEYS = ("fps", "window", "joint_names", "parents", "x_mean", "x_std", "c_mean", "c_std", "tau")


def available():
    """Whether every shipped file is there (a checkout without them trains instead)."""
    return HELDOUT.is_file() and all(p.is_file() for p in CHECKPOINTS.values())


def export_checkpoint(src, dst):
    """A training checkpoint with float16 weights (integer buffers and flags unchanged)."""
    import torch  # here, not at module level: make_stimuli imports this module, and its render workers need no torch

    ck = load_torch_file(src)
    ck["state"] = {k: v.half() if v.is_floating_point() else v for k, v in ck["state"].items()}
    ck.setdefault("source", Path(src).as_posix())  # re-exporting a shipped file keeps the run it came from
    torch.save(ck, dst)


def export_heldout(dataset, dst):
    """The held-out splits of a prepared dataset (no training windows), with the attribution."""
    keys = [f"{s}_{k}" for s in HELD_OUT for k in WINDOW_KEYS]
    arrays = read_arrays(dataset, keys + list(SHARED_KEYS))
    require(arrays, keys, dataset)
    np.savez_compressed(dst, **arrays, attribution=np.str_(ATTRIBUTION))


def quality(stride=QUALITY_STRIDE, seed=0, precision="float32", models=study.GENERATED):
    """Foot skating and jerk of the shipped MG and FL over NAT's, medians over every `stride`-th test window
    of the shipped held-out set (at TEMPERATURE, the hips on the root and on the actor's bones, as make_stimuli ships
    them: invariants.fit_to_actor), their late stepping:
    the median over those windows of its ratio to NAT's on the same window (higher is better), the worst joint's
    mean jerk over NAT's, the rigidity of their bones: the largest bone-length std within a window (mm) and
    the largest error of a bone's mean length against the actor's (a fraction), and their Fréchet motion distance
    over NAT's on the same windows (a drifted posture shows there: bench/RESULTS.md#fl-posture), and
    the share of windows whose posture over their second half keeps their own take's style (metrics.style_retention,
    against the category averages of every held-out take). Recorded in quality.json at export and recomputed by the
    tests, which fail if the models fall back (quality_failures). `precision`: MG's sampler's (precision.py asks
    whether bfloat16 keeps the figures); `models`: which of MG and FL to measure."""
    from ..metrics.fmd import MotionEncoder
    from ..metrics.objective import foot_skating, jerk, joint_jerk, late_stepping, style_retention
    from ..motion import invariants, rigid
    from ..motion.features import to_world
    from .sample import load_model, sample_windows

    d = read_arrays(HELDOUT, ["test_x", "test_c", "test_hist", "test_hist_c", "test_labels", "test_take", "fps"])
    keys = ("x", "c", "hist", "hist_c", "labels", "take")
    x, c, hist, hist_c, labels, takes = (d[f"test_{k}"][::stride] for k in keys)
    styles = heldout_windows(HELDOUT, ("x", "take", "labels"))  # every held-out take: the category averages
    encoder = MotionEncoder.load(MOTION_ENCODER)
    floor = encoder.fmd(x, labels)
    fps = float(d["fps"])
    out = {}
    samples = {study.NATURAL: x}
    for name in models:
        model = load_model(CHECKPOINTS[name.lower()], "cpu")
        sampled = sample_windows(model, c, hist, hist_c, TEMPERATURE[name], seed=seed, precision=precision)
        samples[name] = invariants.fit_to_actor(sampled, hist)  # as make_stimuli ships them
    per_joint = {}
    for name, xs in samples.items():
        world = to_world(xs, c)  # [B, T, J, 3]
        out[name] = {
            "foot_skating": float(np.median([foot_skating(w, fps) for w in world])),
            "jerk": float(np.median([jerk(w, fps) for w in world])),
        }
        per_joint[name] = joint_jerk(world, fps).mean(axis=0)  # [J], over the windows
    nat = out[study.NATURAL]
    ratios = {name: {k: v / nat[k] for k, v in m.items()} for name, m in out.items() if name != study.NATURAL}
    steps = {name: np.array([late_stepping(x, fps) for x in xs]) for name, xs in samples.items()}
    actor = rigid.bone_lengths(hist)[:, None]  # [B, 1, bones]
    for name in ratios:
        ratios[name]["late_stepping"] = float(np.median(steps[name] / np.maximum(steps[study.NATURAL], 1e-6)))
        ratios[name]["joint_jerk_max"] = float((per_joint[name] / per_joint[study.NATURAL]).max())
        bones = rigid.frame_bone_lengths(samples[name].astype(np.float64))  # [B, T, bones]
        ratios[name]["bone_std_mm_max"] = float(bones.std(axis=1).max() * 1000)
        ratios[name]["bone_length_error_max"] = float(np.abs(bones.mean(axis=1, keepdims=True) / actor - 1).max())
        ratios[name]["fmd_over_floor"] = float(encoder.fmd(samples[name], labels) / floor)
        kept = style_retention(samples[name], x, takes, labels, start=x.shape[1] // 2, reference=styles)
        ratios[name]["style_retention"] = kept[0]
    return ratios


# The guard on quality()'s figures: no worse than recorded in quality.json, with 10% slack for another machine's (or
# precision's) rounding, and the stimuli's absolute targets. (figure, "max" or "min", bound, relative to the record?)
GUARD = (
    ("foot_skating", "max", 1.1, True),
    ("jerk", "max", 1.1, True),
    ("late_stepping", "min", 1 / 1.1, True),  # a gait that dies out: stepping falls where skating and jerk may not
    ("fmd_over_floor", "max", 1.1, True),  # the posture stays the data's (FL without its posture term drifted)
    ("joint_jerk_max", "max", 1.2, False),  # every joint's mean jerk within this ratio of NAT's
    ("bone_std_mm_max", "max", 1.0, False),  # the actor's rigid bones: length std within a window, mm
    ("bone_length_error_max", "max", 0.01, False),  # and each bone's mean within 1% of the actor's
)
STYLE_GUARD = ("MG", "style_retention", 1 / 1.1)  # MG keeps the style of the history it continues (FL has none)


def quality_failures(now, recorded=None):
    """Each figure of `now` (quality()'s, for any of MG and FL) that breaks the guard, as 'MODEL figure value
    against bound'; [] when all hold. `recorded`: quality.json's figures (default: read it)."""
    recorded = json.loads(QUALITY.read_text()) if recorded is None else recorded
    failures = []
    for model, figures in now.items():
        rules = [*GUARD, *([(STYLE_GUARD[1], "min", STYLE_GUARD[2], True)] if model == STYLE_GUARD[0] else [])]
        for name, side, bound, relative in rules:
            limit = bound * recorded[model][name] if relative else bound
            if (figures[name] > limit) if side == "max" else (figures[name] < limit):
                failures.append(f"{model} {name} {figures[name]:.4g} against {side} {limit:.4g}")
    return failures


def measure_speed(frames=150, warmup=5, streams=30, early=True):
    """{precision: median ms per frame, "ratio": median of float32's time over bfloat16's, frame by frame} of the
    shipped MG sampling `streams` held-out windows (the default job's batch), the two precisions taking turns frame
    by frame so that other work on the machine slows both alike. For precision.pick.

    Where bfloat16 has no fast products (a CPU without AVX512-BF16 or AMX emulates them), it is many times slower:
    the measurement stops (`early`) once EARLY_FRAMES frames show it at under EARLY_RATIO of float32's speed, a
    verdict the remaining frames cannot turn (they would take most of a minute)."""
    import time

    import torch  # as export_checkpoint: only when measuring

    from ..models.mg_stream import MGStream
    from .sample import load_model

    model = load_model(CHECKPOINTS["mg"], "cpu")
    d = read_arrays(HELDOUT, ["test_hist", "test_hist_c", "test_c"])
    n = min(streams, len(d["test_hist"]))
    hist = model.standardize_x(torch.as_tensor(d["test_hist"][:n])[:, -model.tau :])
    hist_c = model.standardize_c(torch.as_tensor(d["test_hist_c"][:n])[:, -model.tau :])
    control = model.standardize_c(torch.as_tensor(d["test_c"][:n]))
    times = {"float32": [], "bfloat16": []}
    with torch.inference_mode():
        gen = {p: torch.Generator().manual_seed(0) for p in times}
        runs = {p: MGStream(model, hist, hist_c, TEMPERATURE["MG"], gen[p], precision=p) for p in times}
        for t in range(warmup + frames):
            for p in sorted(runs, reverse=t % 2 == 1):  # each goes first every other frame: no order effect
                stream = runs[p]
                start = time.perf_counter()
                stream.step(control[:, t % control.shape[1]])
                if t >= warmup:
                    times[p].append((time.perf_counter() - start) * 1000)
            if early and len(times["bfloat16"]) == EARLY_FRAMES and _ratio(times) < EARLY_RATIO:
                break
    # A burst of other work slows the two frames of one turn alike: the median of their ratios is steadier on a
    # shared host than the ratio of the two medians.
    return {**{p: float(np.median(v)) for p, v in times.items()}, "ratio": _ratio(times)}


# The early stop of measure_speed: bfloat16 under half float32's speed over this many frames is not worth the rest
# (precision.MIN_GAIN is the gain asked of it the other way).
EARLY_FRAMES, EARLY_RATIO = 20, 0.5


def _ratio(times):
    """The median over frames of float32's time over bfloat16's (see measure_speed)."""
    return float(np.median(np.array(times["float32"]) / np.array(times["bfloat16"])))


def bfloat16_guard_failures():
    """The quality guard's failures with MG sampled in bfloat16 (FL samples as always)."""
    return quality_failures(quality(precision="bfloat16", models=("MG",)))


def sampler_precision(device, override=None):
    """MG's sampler's precision for make_stimuli: `override`, else picked once per CPU on the shipped MG
    (precision.pick)."""
    from .precision import pick

    return pick(device, override, measure_speed, bfloat16_guard_failures)


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m generation.sampling.pretrained", description=__doc__.split("\n")[0])
    for kind in CHECKPOINTS:
        ap.add_argument(f"--{kind}", required=True, help=f"checkpoint to ship as {CHECKPOINTS[kind].name}")
    ap.add_argument("--data", required=True, help="the prepared dataset the models were trained on")
    return ap


def _main(argv):
    a = build_parser().parse_args(argv)
    FOLDER.mkdir(exist_ok=True)
    for kind, dst in CHECKPOINTS.items():
        export_checkpoint(getattr(a, kind), dst)
    export_heldout(a.data, HELDOUT)
    QUALITY.write_text(json.dumps(quality(), indent=1) + "\n")
    total = sum(p.stat().st_size for p in [*CHECKPOINTS.values(), HELDOUT])
    print(f"wrote {FOLDER}: {', '.join(p.name for p in [*CHECKPOINTS.values(), HELDOUT])} ({total / 1e6:.1f} MB)")


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
