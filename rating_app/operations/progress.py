"""The dashboard's figures (/admin, progress.json): per clip or unit and per condition from the study's design
(designs/), and per rater (answers, catch failures, suspicious flags) and the latest playback events here.
"""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from moglow_eval.core import study

from ..designs import get
from ..designs.export_cells import rater_flags
from ..media import fetched
from ..store.db import Event, Rater, Trial, TrialClip


def progress(engine: Engine, target: int, design: str | None = None, units=None) -> dict:
    """Counts for the dashboard of a study of `design` (None: acr) with `units`."""
    with Session(engine.execution_options(read_only=True)) as s:
        p = get(design).progress(s, target, units or {})
        n_trials = dict(
            s.execute(
                select(Trial.rater_pk, func.count())
                .where(Trial.phase == "rating", (Trial.released.is_(False)) | Trial.answered_at.is_not(None))
                .group_by(Trial.rater_pk)
            ).all()
        )
        sent = _bytes_sent(s)
        raters = []
        for r in s.scalars(select(Rater).order_by(Rater.id)):
            nv, pv = p["no_video"].get(r.rater_id, 0), p["partial_video"].get(r.rater_id, 0)
            raters.append(
                {
                    "rater_id": r.rater_id,
                    "external_id": r.external_id or "",
                    "started": r.created_at,
                    "last_seen": r.last_seen,
                    "completed": r.completed_at is not None,
                    "expired": r.expired_at is not None,
                    "rated": p["answers"].get(r.rater_id, 0),
                    "of": n_trials.get(r.id, 0),
                    "catch_failures": p["fails"].get(r.rater_id, 0),
                    "excluded": study.excluded(p["fails"].get(r.rater_id, 0)),
                    "early_answers": r.n_early,
                    "ratings_without_video": nv,
                    "ratings_partial_video": pv,
                    "flags": rater_flags(r.n_early, nv, pv),
                    "bytes_sent": sent.get(r.id, 0),
                }
            )
        events = s.execute(select(Event.created_at, Event.kind, Event.detail).order_by(Event.id.desc()).limit(50)).all()
    return _summary(target, p["per_clip"], p["per_condition"], raters, events)


def _bytes_sent(s) -> dict:
    """{rater pk: the video bytes the server sent to that session} (each trial's and trial clip's ranges)."""
    out: dict = {}
    trials = select(Trial.rater_pk, Trial.video_ranges).where(Trial.video_ranges.is_not(None))
    clips = select(Trial.rater_pk, TrialClip.video_ranges).join(Trial, TrialClip.trial_pk == Trial.id)
    for rater_pk, text in [*s.execute(trials), *s.execute(clips.where(TrialClip.video_ranges.is_not(None)))]:
        out[rater_pk] = out.get(rater_pk, 0) + sum(b - a for a, b in fetched.parse(text))
    return out


def _median(values):
    values = sorted(values)
    if not values:
        return None
    mid = len(values) // 2
    return values[mid] if len(values) % 2 else (values[mid - 1] + values[mid]) // 2


def _summary(target, per_clip, per_cond, raters, events):
    tests = [r for r in per_clip if r["role"] == "test"]
    return {
        "target": target,
        "test_clips": len(tests),
        "clips_complete": sum(r["ratings"] >= target for r in tests),
        "ratings_test": sum(r["ratings"] for r in tests),
        "ratings_needed": target * len(tests),
        "full": bool(tests) and all(r["ratings"] >= target for r in tests),
        "per_clip": per_clip,
        "per_condition": per_cond,
        "raters": raters,
        "raters_completed": sum(r["completed"] for r in raters),
        "raters_failed_catch": sum(r["catch_failures"] > 0 for r in raters),
        "raters_excluded": sum(r["excluded"] for r in raters),
        "raters_suspicious": sum(bool(r["flags"]) for r in raters),
        "raters_expired": sum(r["expired"] for r in raters),
        # what a rater downloads: the median over finished sessions of the video bytes sent to each
        "bytes_per_session": _median([r["bytes_sent"] for r in raters if r["completed"]]),
        "events": [{"at": a, "kind": k, "detail": d} for a, k, d in events],
    }
