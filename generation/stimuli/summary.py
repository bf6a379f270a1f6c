"""What the main job prints when it is done (make_stimuli): the metrics per condition, the Fréchet motion distance
(with what a condition under NAT's floor means), the classifier two-sample test and what tells each condition
apart, a warning when the BAD clips are not plainly bad, and what was written."""

import logging
from pathlib import Path

import numpy as np

from moglow_eval.core import study

from ..metrics import c2st
from ..metrics.c2st_features import feature_text
from ..sampling import pretrained
from .files import summary_text

log = logging.getLogger(__name__)


def print_summary(out, manifest, metrics_rows, fmd, c2st_rows, seconds):
    """The run's results on stdout: metrics per condition, the FMD, the C2ST (`c2st_rows`: c2st.csv's and
    c2st_features.csv's rows), and what was written."""
    n = {r: sum(m["role"] == r for m in manifest) for r in study.ROLES}
    print(
        f"\nobjective metrics, mean (sd) per condition: foot_skating m/s, bone_length_std m, jerk m/s^3, "
        f"control_error m, control_following m, acceleration m/s^2\n{summary_text(metrics_rows)}"
    )
    if fmd:
        print(
            "\nFréchet motion distance of the test clips to training motion of their categories "
            "(NAT's is the floor): " + ", ".join(f"{r['condition']} {r['fmd']}" for r in fmd)
        )
        below = below_floor(fmd)
        if below:
            print(
                f"  {' and '.join(below)} below the floor: real held-out motion is not training motion either, and "
                "a few dozen windows give the distance some noise, so a model that keeps close to the training "
                "motion can score under NAT; read it as 'as close as real motion', not 'more real than real'"
            )
    print("\n" + c2st.c2st_text(c2st_rows[0]))
    print(feature_text(c2st_rows[1]))
    _warn_if_bad_not_bad(metrics_rows)
    print(
        f"\nwrote {Path(out) / 'manifest.csv'}: {len(manifest)} clips ({n['test']} test, {n['catch']} catch, "
        f"{n['training']} training) in {seconds:.0f} s"
    )


def below_floor(fmd):
    """The conditions whose FMD is under NAT's (the floor), from condition_fmd's rows."""
    values = {r["condition"]: float(r["fmd"]) for r in fmd}
    floor = values.get(study.NATURAL)
    return [] if floor is None else [c for c, v in values.items() if c != study.NATURAL and v < floor]


def condition_fmd(poses, encoder=pretrained.MOTION_ENCODER):
    """[{condition, n_windows, fmd}] for root-frame test windows {condition: [(x [T, 63], category), ...]};
    [] (with a note) when the shipped motion encoder is missing."""
    if not Path(encoder).is_file():
        log.warning(f"note: no motion encoder at {encoder}; skipping the Fréchet motion distance")
        return []
    # lazy: torch, which make_stimuli loads only to sample and its render workers never
    from ..metrics.fmd import MotionEncoder

    enc = MotionEncoder.load(encoder)
    return [
        dict(condition=cond, n_windows=len(w), fmd=f"{enc.fmd(np.stack([x for x, _ in w]), [k for _, k in w]):.4g}")
        for cond, w in poses.items()
    ]


def _warn_if_bad_not_bad(rows):
    """BAD clips should be plainly worse than NAT; say so when no metric shows it."""

    def mean(cond, key):
        v = [r[key] for r in rows if r["condition"] == cond and np.isfinite(r[key])]
        return np.mean(v) if v else np.nan

    if not any(r["condition"] == study.CATCH for r in rows):
        return
    keys = ("jerk", "bone_length_std", "foot_skating")
    if not any(mean(study.CATCH, k) > 2 * mean(study.NATURAL, k) for k in keys):
        log.warning(
            "warning: the BAD clips are not clearly worse than NAT on jerk, bone length or foot skating; "
            "pass an earlier --bad-checkpoint"
        )


def blinding_warning(out, manifest):
    """A warning line when the videos' coded sizes (the only sizes that follow the content, CONTRACTS §4) tell the
    catch clips from the test clips beyond SIZE_AUC_BAND, further than chance puts them for the numbers of clips
    (rendering.blinding.chance_of_worst under CHANCE_P), naming the signal and what to change; None otherwise.
    A parser that sums each frame's coded NAL units could then find the catch trials, e.g. a `freeze` clip, whose
    still frames cost nearly nothing, among speakers who move little."""
    from rendering.blinding import CHANCE_P, SIZE_AUC_BAND, chance_of_worst, coded_sizes, worst_signal

    catch = coded_sizes(
        [Path(out) / m["video"] for m in manifest if m["condition"] == study.CATCH and m["role"] == "catch"]
    )
    test = coded_sizes([Path(out) / m["video"] for m in manifest if m["role"] == "test"])
    name, auc = worst_signal(catch, test)
    lo, hi = SIZE_AUC_BAND
    if name is None or lo <= auc <= hi:
        return None
    chance = chance_of_worst(catch, test)
    if chance >= CHANCE_P:
        return None  # as far out as a random split of these videos often is
    return (
        f"warning: the coded sizes tell the {len(catch)} catch clips from the {len(test)} test clips ({name}: AUC "
        f"{auc:.3f}, outside [{lo}, {hi}]; a random split of the videos is as far out in {chance:.1%} of draws): a "
        "parser could find the catch trials. Mix catch kinds whose encoded sizes fall on both sides of the test "
        'clips\' (e.g. [catch] make = ["jitter", "freeze", "swap"], or fewer freeze clips), or use your own catch '
        "folder"
    )
