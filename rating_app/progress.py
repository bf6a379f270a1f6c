"""The dashboard's figures (/admin, progress.json): per clip or unit and per condition from the study's design
(designs/), and per rater (answers, catch failures, suspicious flags) and the latest playback events here.
"""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from .db import Event, Rater, Trial
from .designs import get
from .export_cells import rater_flags


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
                    "early_answers": r.n_early,
                    "ratings_without_video": nv,
                    "ratings_partial_video": pv,
                    "flags": rater_flags(r.n_early, nv, pv),
                }
            )
        events = s.execute(select(Event.created_at, Event.kind, Event.detail).order_by(Event.id.desc()).limit(50)).all()
    return _summary(target, p["per_clip"], p["per_condition"], raters, events)


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
        "raters_suspicious": sum(bool(r["flags"]) for r in raters),
        "raters_expired": sum(r["expired"] for r in raters),
        "events": [{"at": a, "kind": k, "detail": d} for a, k, d in events],
    }
