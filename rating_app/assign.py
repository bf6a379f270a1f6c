"""Which clips a new rater gets.

Every rater sees all training clips (familiarisation) and all catch clips. Test clips are handed out so each
reaches its target count with as few raters as possible: a rater gets up to `clips_per_rater` of the clips
still short of their target (all of them by default), least-covered first, ties broken at random. A clip's
cover = stored ratings + slots held by raters still active; the slots of a session idle for longer than
`slot_timeout_s` are released. When no test clip needs a slot the study is full.
"""
from __future__ import annotations

import datetime as dt
import random

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from .db import Clip, Lock, Rater, Rating, Trial, is_sqlite, utcnow


class StudyFull(Exception):
    pass


def release_abandoned(s: Session, slot_timeout_s: float, now: dt.datetime) -> int:
    cutoff = now - dt.timedelta(seconds=slot_timeout_s)
    idle = select(Rater.id).where(Rater.completed_at.is_(None), Rater.last_seen < cutoff)
    res = s.execute(update(Trial).where(Trial.rater_pk.in_(idle), Trial.answered_at.is_(None),
                                        Trial.released.is_(False)).values(released=True))
    return res.rowcount or 0


def coverage(s: Session) -> dict[str, tuple[int, int]]:
    """{clip_id: (stored ratings, open slots)} for every test clip."""
    done = dict(s.execute(select(Rating.clip_id, func.count()).group_by(Rating.clip_id)).all())
    pending = dict(s.execute(
        select(Trial.clip_id, func.count())
        .where(Trial.phase == "rating", Trial.answered_at.is_(None), Trial.released.is_(False))
        .group_by(Trial.clip_id)).all())
    tests = s.scalars(select(Clip.clip_id).where(Clip.role == "test")).all()
    return {c: (done.get(c, 0), pending.get(c, 0)) for c in tests}


def is_full(s: Session, target: int) -> bool:
    """True when every test clip has its target of stored ratings (the study is over)."""
    cov = coverage(s)
    return bool(cov) and all(d >= target for d, _ in cov.values())


def plan_trials(s: Session, rng: random.Random, target: int, clips_per_rater: int | None,
                slot_timeout_s: float) -> list[tuple[str, str]]:
    """Return [(clip_id, phase)] in presentation order for a new rater; raise StudyFull."""
    if not is_sqlite(s.get_bind()):
        # PostgreSQL: serialise assignment between workers (SQLite already holds the write lock).
        s.execute(select(Lock).where(Lock.name == "assign").with_for_update())
    now = utcnow()
    release_abandoned(s, slot_timeout_s, now)
    cov = coverage(s)
    if not cov:
        raise StudyFull("the study has no test clips")
    short = [(d + p, rng.random(), c) for c, (d, p) in cov.items() if d + p < target]
    if not short:
        if all(d >= target for d, _ in cov.values()):
            raise StudyFull("study full: every clip has all its ratings. Thank you for your interest")
        raise StudyFull("study full for now: the remaining clips are being rated by others; "
                        "please try again later")
    short.sort()
    n = len(short) if not clips_per_rater else min(clips_per_rater, len(short))
    tests = [c for _, _, c in short[:n]]
    catch = list(s.scalars(select(Clip.clip_id).where(Clip.role == "catch").order_by(Clip.clip_id)))
    training = list(s.scalars(select(Clip.clip_id).where(Clip.role == "training").order_by(Clip.clip_id)))
    rng.shuffle(training)
    rating = tests + catch
    rng.shuffle(rating)
    return [(c, "training") for c in training] + [(c, "rating") for c in rating]
