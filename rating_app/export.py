"""ratings.csv (CONTRACTS §6) and progress figures, straight from the database.

Every text cell that a spreadsheet would take for a formula (starting with = + - @, a tab or a carriage
return) is written with a leading apostrophe, so opening the export can never run anything a rater typed.
The `flags` column marks ratings to look at before trusting them (FLAGS). Pairwise and parallel studies export
their own files (design_export.py); `export_csv` picks the one for the design stored in the database.
"""

from __future__ import annotations

import csv
import io

from sqlalchemy import func, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from core.study import CATCH, acr_catch_failed

from .db import Clip, Event, Rater, Rating, Trial, study_design

COLUMNS = (
    "rater_id",
    "clip_id",
    "condition",
    "rating",
    "role",
    "item",
    "trial_index",
    "watched_ms",
    "submitted_at",
    "external_id",
    "study_id",
    "rater_completed",
    "flags",
)
FLAGS = {
    "no_video": "the server never sent this trial's video before the answer",
    "partial_video": "the server had sent only part of this trial's video before the answer (e.g. one byte)",
    "too_fast": "the session had answers refused as arriving before the clip could have played to the end",
}
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def cell(value):
    """A CSV cell that no spreadsheet evaluates."""
    if isinstance(value, str) and value.startswith(FORMULA_START):
        return "'" + value
    return value


def row_flags(rating_flags: str, n_early: int) -> str:
    flags = set(filter(None, (rating_flags or "").split(";")))
    if n_early:
        flags.add("too_fast")
    return ";".join(sorted(flags))


def rater_flags(n_early, n_no_video, n_partial) -> list[str]:
    """What makes a rater suspicious on the dashboard: answers refused as too early, answers without the video
    or with only part of it."""
    return [f for f, bad in (("too_fast", n_early), ("no_video", n_no_video), ("partial_video", n_partial)) if bad]


def iter_rows(s: Session):
    q = (
        select(
            Rater.rater_id,
            Rating.clip_id,
            Clip.condition,
            Rating.rating,
            Clip.role,
            Clip.item,
            Trial.index,
            Rating.watched_ms,
            Rating.submitted_at,
            Rater.external_id,
            Rater.study_id,
            Rater.completed_at,
            Rating.flags,
            Rater.n_early,
        )
        .join(Trial, Trial.id == Rating.trial_pk)
        .join(Rater, Rater.id == Rating.rater_pk)
        .join(Clip, Clip.clip_id == Rating.clip_id)
        .order_by(Rater.id, Trial.index)
    )
    for (
        rater_id,
        clip_id,
        cond,
        rating,
        role,
        item,
        idx,
        watched,
        at,
        ext,
        study,
        completed,
        flags,
        n_early,
    ) in s.execute(q):
        yield {
            "rater_id": rater_id,
            "clip_id": clip_id,
            "condition": cond,
            "rating": rating,
            "role": role,
            "item": item,
            "trial_index": idx,
            "watched_ms": "" if watched is None else watched,
            "submitted_at": at.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
            "external_id": ext or "",
            "study_id": study or "",
            "rater_completed": int(completed is not None),
            "flags": row_flags(flags, n_early),
        }


def export_csv(engine: Engine, out=None) -> str | int:
    """Write the study's export (ratings.csv, or pairs.csv for pairwise) to the file object `out` (returns the row
    count) or return it as a string."""
    from .design_export import FIT_COLUMNS, PAGE_COLUMNS, PAIR_COLUMNS, iter_fit_rows, iter_page_rows, iter_pair_rows

    buf = out if out is not None else io.StringIO()
    n = 0
    with Session(engine.execution_options(read_only=True)) as s:
        design = study_design(s) or "acr"
        columns, rows = {
            "acr": (COLUMNS, iter_rows),
            "pairwise": (PAIR_COLUMNS, iter_pair_rows),
            "parallel": (PAGE_COLUMNS, iter_page_rows),
            "appropriateness": (FIT_COLUMNS, iter_fit_rows),
        }[design]
        w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
        w.writeheader()
        for row in rows(s):
            w.writerow({k: cell(v) for k, v in row.items()})
            n += 1
    return n if out is not None else buf.getvalue()


def progress(engine: Engine, target: int, design: str = "acr", units=None) -> dict:
    """Counts for the dashboard: per clip (per unit in pairwise and parallel studies), per condition, per rater
    (with catch failures)."""
    if design != "acr":
        return _progress_units(engine, target, design, units)
    with Session(engine.execution_options(read_only=True)) as s:
        clips = s.execute(
            select(Clip.clip_id, Clip.condition, Clip.role, Clip.item)
            .where(Clip.role != "training", (Clip.role != "catch") | (Clip.condition == CATCH))
            .order_by(Clip.role, Clip.condition, Clip.clip_id)
        ).all()
        # One pass over the ratings: count and sum per clip (condition means come from the exact sums).
        stats = {
            c: (n, int(total))
            for c, n, total in s.execute(
                select(Rating.clip_id, func.count(), func.sum(Rating.rating)).group_by(Rating.clip_id)
            )
        }
        pending = dict(
            s.execute(
                select(Trial.clip_id, func.count())
                .where(
                    Trial.phase == "rating",
                    Trial.clip_id.is_not(None),
                    Trial.answered_at.is_(None),
                    Trial.released.is_(False),
                )
                .group_by(Trial.clip_id)
            ).all()
        )
        per_clip, per_cond = [], {}
        for c, cond, role, item in clips:
            n, total = stats.get(c, (0, 0))
            r = {
                "clip_id": c,
                "condition": cond,
                "role": role,
                "item": item,
                "ratings": n,
                "in_progress": pending.get(c, 0),
                "target": target if role == "test" else None,
                "mean": round(total / n, 2) if n else None,
            }
            per_clip.append(r)
            d = per_cond.setdefault(
                cond, {"condition": cond, "role": role, "clips": 0, "ratings": 0, "target": 0, "_sum": 0}
            )
            d["clips"] += 1
            d["ratings"] += n
            d["target"] += r["target"] or 0
            d["_sum"] += total
        for d in per_cond.values():
            d["mean"] = round(d.pop("_sum") / d["ratings"], 2) if d["ratings"] else None
        n_rated = dict(s.execute(select(Rating.rater_pk, func.count()).group_by(Rating.rater_pk)).all())
        fails = dict(
            s.execute(
                select(Rating.rater_pk, func.count())
                .join(Clip, Clip.clip_id == Rating.clip_id)
                .where(Clip.role == "catch", acr_catch_failed(Rating.rating))
                .group_by(Rating.rater_pk)
            ).all()
        )
        n_trials = dict(
            s.execute(
                select(Trial.rater_pk, func.count())
                .where(Trial.phase == "rating", (Trial.released.is_(False)) | Trial.answered_at.is_not(None))
                .group_by(Trial.rater_pk)
            ).all()
        )
        no_video, partial = (
            dict(
                s.execute(
                    select(Rating.rater_pk, func.count()).where(Rating.flags.contains(flag)).group_by(Rating.rater_pk)
                ).all()
            )
            for flag in ("no_video", "partial_video")
        )
        raters = []
        for r in s.scalars(select(Rater).order_by(Rater.id)):
            flags = rater_flags(r.n_early, no_video.get(r.id), partial.get(r.id))
            raters.append(
                {
                    "rater_id": r.rater_id,
                    "external_id": r.external_id or "",
                    "started": r.created_at,
                    "last_seen": r.last_seen,
                    "completed": r.completed_at is not None,
                    "expired": r.expired_at is not None,
                    "rated": n_rated.get(r.id, 0),
                    "of": n_trials.get(r.id, 0),
                    "catch_failures": fails.get(r.id, 0),
                    "early_answers": r.n_early,
                    "ratings_without_video": no_video.get(r.id, 0),
                    "ratings_partial_video": partial.get(r.id, 0),
                    "flags": flags,
                }
            )
        events = s.execute(select(Event.created_at, Event.kind, Event.detail).order_by(Event.id.desc()).limit(50)).all()
    return _summary(target, per_clip, per_cond, raters, events)


def _events(s):
    return s.execute(select(Event.created_at, Event.kind, Event.detail).order_by(Event.id.desc()).limit(50)).all()


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
        "per_condition": list(per_cond.values()) if isinstance(per_cond, dict) else per_cond,
        "raters": raters,
        "raters_completed": sum(r["completed"] for r in raters),
        "raters_failed_catch": sum(r["catch_failures"] > 0 for r in raters),
        "raters_suspicious": sum(bool(r["flags"]) for r in raters),
        "raters_expired": sum(r["expired"] for r in raters),
        "events": [{"at": a, "kind": k, "detail": d} for a, k, d in events],
    }


def _progress_units(engine: Engine, target: int, design: str, units) -> dict:
    from .design_export import progress_units

    with Session(engine.execution_options(read_only=True)) as s:
        p = progress_units(s, design, units or {}, target)
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
            flags = rater_flags(r.n_early, nv, pv)
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
                    "flags": flags,
                }
            )
        events = _events(s)
    return _summary(target, p["per_clip"], p["per_condition"], raters, events)
