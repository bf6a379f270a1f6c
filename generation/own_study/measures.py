"""Which measures a study of your own motion gets, and the gesture measures' files (CONTRACTS §4, docs/metrics.md).

A gesture study is one with speech (`[audio]`), an SMPL-family body (`[skeleton] smpl_model`) or a speech-gesture data
set's skeleton (generation.data.skeleton_families: GENEA's, ZeroEGGS's and BEAT's), unless `[metrics] gesture` says
otherwise. It gets the gesture measures (generation.metrics.gesture) as extra columns of metrics.csv and gesture.csv
beside it (a row per condition), and drops the locomotion metrics (foot skating; the control metrics, which no study
of your own motion has), written nan. Every study of your own motion writes measures.csv: each metrics.csv column's
status (`measured`, `partly`, `skipped`), how many clips have a value, why the others have none, and its settings.
"""

import logging
import time

import numpy as np

from moglow_eval.core import study
from moglow_eval.core.skeleton_names import body_skeleton
from rendering.audio import RATE

from ..data.skeleton_families import family
from ..stimuli.files import write_csv
from .speech import read_voices

log = logging.getLogger(__name__)
GESTURE_COLUMNS = ["condition", "n_clips", *study.GESTURE_METRIC_NAMES]
NO_CONTROL = "a study of your own motion has no control signal"
WHY_NONE = {"foot_skating": "no feet found by name ([skeleton] feet names them)"}


def gesture_study(spec, names):
    """(whether the study gets the gesture measures, why: a phrase)."""
    if spec.gesture is not True and spec.gesture is not False:
        why = [
            *(["it has speech"] if spec.audio_folder else []),
            *(["an SMPL-family body"] if spec.smpl_model else []),
            *(f"a {fam.name} skeleton" for fam in [family(names)] if fam is not None and fam.gesture),
        ]
        if why:
            return True, "a gesture study: " + ", ".join(why)
        return False, "not a gesture study (no speech, and neither an SMPL-family nor a speech-gesture skeleton)"
    return spec.gesture, f"[metrics] gesture = {str(spec.gesture).lower()} in the study file"


def study_measures(spec, clips, row_clips, metrics_rows, skeleton, lengths, out):
    """Add the gesture measures to `metrics_rows` (one per styled clip; `row_clips[i]` the index in `clips` of row
    i's StudyClip) where the study is a gesture study, and write measures.csv (and gesture.csv) into `out`.
    Returns (the extra metrics.csv columns, the summary's text or None)."""
    t0 = time.perf_counter()
    names, parents = skeleton
    on, why = gesture_study(spec, names)
    if not on:
        write_csv(out / study.MEASURES_FILE, study.MEASURES_COLUMNS, _rows(metrics_rows, {}, why, {}, {}))
        return [], None
    from ..metrics import gesture  # brings torch (the FGD's encoder): a study without the measures does not wait for it

    for row in metrics_rows:
        row["foot_skating"] = float("nan")
    agent, other = read_voices(spec, lengths)
    voices = gesture.Voices(RATE, agent, other)
    # Measured on the body: "about the root" is about the hips, not a root marker left at the scene's origin.
    keep, names, parents = body_skeleton(names, parents)
    applies = gesture.plan(names, bool(agent), bool(other))
    measured = [
        gesture.Clip(c.condition, c.role, c.item, not c.motion_item, np.asarray(c.joints, np.float64)[:, keep])
        for c in clips
    ]
    result = gesture.measure(measured, names, np.asarray(parents), spec.fps, voices, applies, seed=spec.seed)
    for row, k in zip(metrics_rows, row_clips):
        row.update(result.clips[k])
    write_csv(out / study.GESTURE_FILE, GESTURE_COLUMNS, [_numbers(r) for r in result.conditions])
    skipped = {**applies, **{m: why for m in study.LOCOMOTION_METRICS}}
    rows = _rows(metrics_rows, skipped, why, result.reasons, gesture.SETTINGS)
    write_csv(out / study.MEASURES_FILE, study.MEASURES_COLUMNS, rows)
    return list(study.GESTURE_METRIC_NAMES), gesture_text(result.conditions, time.perf_counter() - t0)


def _numbers(row):
    return {k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()}


def _rows(metrics_rows, skipped, why, reasons, settings):
    """measures.csv's rows: every metric of the rows, its status, count, reasons and `settings` (by measure)."""
    names = [*study.METRIC_NAMES, *(study.GESTURE_METRIC_NAMES if skipped else [])]
    out = []
    for name in names:
        n = sum(np.isfinite(float(r.get(name, np.nan))) for r in metrics_rows)
        if skipped.get(name) or (name in study.LOCOMOTION_METRICS[1:]):
            reason, status = skipped.get(name) or NO_CONTROL, study.MEASURE_STATUS[2]
        else:
            detail = "; ".join(f"{k} clips: {w}" for w, k in sorted(reasons.get(name, {}).items()))
            status = study.MEASURE_STATUS[0 if n == len(metrics_rows) else (1 if n else 2)]
            none = WHY_NONE.get(name, "not defined for every clip (docs/metrics.md)")
            reason = detail or ("" if n == len(metrics_rows) else none)
        out.append(dict(measure=name, status=status, clips=n, reason=reason, settings=settings.get(name, "")))
    if not skipped:  # a study without the gesture measures says so of each
        out += [
            dict(measure=name, status=study.MEASURE_STATUS[2], clips=0, reason=why, settings="")
            for name in study.GESTURE_METRIC_NAMES
        ]
    return out


def gesture_text(rows, seconds):
    """gesture.csv's table as text, for the build's summary, with the seconds the measures took."""
    import pandas as pd  # here: as generation.stimuli.files.summary_text, pandas only for the summary

    df = pd.DataFrame(rows).set_index("condition")
    shown = [c for c in df.columns if c == "n_clips" or df[c].notna().any()]
    table = df[shown].to_string(float_format=lambda v: f"{v:.3g}")
    return f"gesture measures per condition (gesture.csv; measured in {seconds:.1f} s):\n{table}"
