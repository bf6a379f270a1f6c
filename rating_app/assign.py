"""Which clips a rater gets, and when a slot is held.

Every rater sees all training clips (familiarisation). A new session plans only its slots: the training clips,
`catch_per_rater` catch slots (at most the pool of catch clips) and up to `clips_per_rater` test slots, in a random
order. A test or catch slot gets its clip when it is first served (GET next): the least-covered clip of its role
that this rater has not had, ties broken at random, a test clip only while short of its target (catch clips have
none). So each catch clip reaches about catch_per_rater / pool of the raters, as each test clip reaches about
clips_per_rater / test clips: with a pool sized to match, a clip that two sessions share is no more likely a catch
clip than any other (CONTRACTS §5). A clip's cover = answers + slots held, i.e. served and unanswered in a live
session; db.Cover keeps both counts per test and catch clip, updated in the same transactions as the trials they
count. So a session holds at most one slot, only once it has come that far, and only until it answers or expires:
creating sessions, or polling GET next, holds nothing. A slot for which no test clip is left is dropped (the session
gets shorter).

Pairwise and parallel studies balance units instead of clips (designs.Unit: a pair of conditions of an item, or
an item's page) by the same rules: a slot gets the least-covered unit still short of its target that the rater
has not had, a unit's cover being its answered trials plus its held slots.

A session expires when it has not answered anything for `slot_timeout_s` (polling is not progress); its
unanswered slots are released and can never be answered, so no clip ever exceeds its target.
"""

from __future__ import annotations

import datetime as dt
import random

from sqlalchemy import bindparam, func, or_, select, update

from core import study

from .db import COVER_KEY, COVERED_KINDS, Clip, Cover, Lock, Rater, Trial
from .designs import training_groups


class StudyFull(Exception):
    pass


def lock_assign(conn) -> None:
    """Serialise assignment between workers (SQLite already holds the write lock: BEGIN IMMEDIATE)."""
    if conn.dialect.name != "sqlite":
        conn.execute(select(Lock).where(Lock.name == "assign").with_for_update())


NO_TARGET = 2**31 - 1  # catch clips and units are handed out least-covered first, without a target


def expire_idle(conn, slot_timeout_s: float, now: dt.datetime, rater_pk: int | None = None) -> list[int]:
    """Mark sessions without an answer for `slot_timeout_s` as expired and release their unanswered slots.

    The UPDATE on the rater row is what an answer takes first too, so an answer and the expiry of its session
    never both succeed."""
    cutoff = now - dt.timedelta(seconds=slot_timeout_s)
    idle = (Rater.completed_at.is_(None), Rater.expired_at.is_(None), Rater.last_progress < cutoff)
    stmt = update(Rater).where(*idle)
    if rater_pk is not None:
        stmt = stmt.where(Rater.id == rater_pk)
    elif conn.dialect.name != "sqlite":
        # A session whose row another transaction holds is busy, not idle: skip it rather than wait for it,
        # which could close a cycle with a server that holds that row and waits for the assignment lock.
        stmt = stmt.where(Rater.id.in_(select(Rater.id).where(*idle).with_for_update(skip_locked=True)))
    ids = list(conn.execute(stmt.values(expired_at=now).returning(Rater.id)).scalars())
    if ids:
        open_slot = (Trial.rater_pk.in_(ids), Trial.answered_at.is_(None), Trial.released.is_(False))
        held = conn.execute(
            select(COVER_KEY, func.count())
            .where(*open_slot, Trial.kind.in_(COVERED_KINDS), COVER_KEY.is_not(None))
            .group_by(COVER_KEY)
        ).all()
        conn.execute(update(Trial).where(*open_slot).values(released=True))
        for k, n in sorted(held):  # one order for every transaction that updates several rows
            conn.execute(update(Cover).where(Cover.key == k).values(held=Cover.held - n))
    return ids


def _cover(conn, *where) -> dict[str, tuple[int, int]]:
    """{key: (answered, held)} from the Cover rows."""
    return {k: (a, h) for k, a, h in conn.execute(select(Cover.key, Cover.answered, Cover.held).where(*where))}


def hold(conn, key: str) -> None:
    """A slot for `key` was just assigned (in the assigning transaction)."""
    conn.execute(update(Cover).where(Cover.key == key).values(held=Cover.held + 1))


def answer(conn, key: str) -> None:
    """A held slot for `key` was just answered (in the answering transaction)."""
    conn.execute(update(Cover).where(Cover.key == key).values(held=Cover.held - 1, answered=Cover.answered + 1))


def coverage(conn) -> dict[str, tuple[int, int]]:
    """{clip_id: (stored ratings, held slots)} for every test clip (of this manifest: rows are never deleted)."""
    return _cover(conn, Cover.key.in_(select(Clip.clip_id).where(Clip.role == "test")))


def is_full(conn, target: int) -> bool:
    """True when every test clip has its target of stored ratings (the study is over)."""
    cov = coverage(conn)
    return bool(cov) and all(d >= target for d, _ in cov.values())


def _short_or_full(cov, target, unit, answers, answered):
    """How many units are still short of their target, counting held slots; StudyFull when none is: for good
    when every unit has all its answers, for now when the rest are held by other sessions."""
    short = sum(d + h < target for d, h in cov.values())
    if not short:
        if all(d >= target for d, _ in cov.values()):
            raise StudyFull(f"study full: every {unit} has all its {answers}. Thank you for your interest")
        raise StudyFull(
            f"study full for now: the remaining {unit}s are being {answered} by others; please try again later"
        )
    return short


def n_catch_slots(pool: int, catch_per_rater: int | None) -> int:
    """Catch trials per session: `catch_per_rater` (None or 0: every one), at most the pool, so every rater gets
    as many as every other."""
    return pool if not catch_per_rater else min(catch_per_rater, pool)


def _slots(rng, n_test: int, n_catch: int) -> list[tuple[str, None]]:
    rating = [("test", None)] * n_test + [("catch", None)] * n_catch
    rng.shuffle(rating)
    return rating


# The clips a slot of each kind draws from in an acr study: test clips, or the bad examples among the catch clips
# (never a catch item's other clips, CONTRACTS §8). One statement for both kinds, so that their timing matches.
_ROLE_CLIPS = select(Clip.clip_id).where(
    Clip.role == bindparam("role"), or_(Clip.role != "catch", Clip.condition == study.CATCH)
)


def plan_session(
    conn, rng: random.Random, target: int, clips_per_rater: int | None, catch_per_rater: int | None = None
) -> list[tuple[str, str | None]]:
    """[(kind, clip_id or None)] in presentation order for a new session; raise StudyFull."""
    cov = coverage(conn)
    if not cov:
        raise StudyFull("the study has no test clips")
    short = _short_or_full(cov, target, "clip", "ratings", "rated")
    n_test = short if not clips_per_rater else min(clips_per_rater, short)
    pool = conn.execute(
        select(func.count()).select_from(Clip).where(Clip.role == "catch", Clip.condition == study.CATCH)
    ).scalar()
    training = list(conn.execute(select(Clip.clip_id).where(Clip.role == "training").order_by(Clip.clip_id)).scalars())
    rng.shuffle(training)
    return [("training", c) for c in training] + _slots(rng, n_test, n_catch_slots(pool, catch_per_rater))


def claim(conn, keys, had, target: int, wait: bool):
    """The least-covered key among `keys` still short of `target` and not in `had`, ties at random, with its
    Cover row locked for this transaction; None when there is none. Without `wait`, rows that other servers are
    claiming at this moment are skipped (PostgreSQL's SKIP LOCKED), so concurrent servers claim different rows
    instead of queueing on one lock. The row's counts are checked again once it is locked, so no key is ever
    handed out beyond its target."""
    cover = Cover.answered + Cover.held
    q = (
        select(Cover.key)
        .where(Cover.key.in_(keys), cover < target, Cover.key.not_in(had))
        .order_by(cover, func.random())
        .limit(1)
    )
    return conn.execute(q.with_for_update(skip_locked=not wait)).scalar()


def assign_slot(conn, rng: random.Random, rater_pk: int, kind: str, target: int, wait=False) -> str | None:
    """The clip for a test or catch slot now being served, or None when none is left for this rater (None also
    when, without `wait`, the only ones left are being claimed by other servers: call again under
    `lock_assign` with `wait`). Both kinds run the same statements, so their timing does not tell them apart."""
    had = select(Trial.clip_id).where(Trial.rater_pk == rater_pk, Trial.clip_id.is_not(None))
    keys = _ROLE_CLIPS.params(role=kind)
    return claim(conn, keys, had, target if kind == "test" else NO_TARGET, wait)


# ---------------------------------------------------------------------------------------- pairwise / parallel
def unit_coverage(conn, units) -> dict[str, tuple[int, int]]:
    """{unit key: (answered trials, held slots)} for every test unit of this manifest."""
    cov = _cover(conn)
    return {k: cov.get(k, (0, 0)) for k, u in units.items() if u.role == "test"}


def units_full(conn, units, target: int) -> bool:
    cov = unit_coverage(conn, units)
    return bool(cov) and all(d >= target for d, _ in cov.values())


def plan_units(
    conn, rng: random.Random, target: int, per_rater: int | None, design: str, clips, units, catch_per_rater=None
):
    """[(kind, training clips or None)] in presentation order for a new pairwise or parallel session."""
    cov = unit_coverage(conn, units)
    short = _short_or_full(cov, target, "comparison", "answers", "answered")
    n_test = short if not per_rater else min(per_rater, short)
    pool = sum(u.role == "catch" for u in units.values())
    training = [("training", g) for g in training_groups(design, clips, rng)]
    return training + _slots(rng, n_test, n_catch_slots(pool, catch_per_rater))


def assign_unit(conn, rng: random.Random, rater_pk: int, kind: str, target: int, units, wait=False):
    """The Unit for a test or catch slot now being served, or None when none is left for this rater (as
    assign_slot, whose rules it follows); both kinds run the same statements."""
    had = select(Trial.unit).where(Trial.rater_pk == rater_pk, Trial.unit.is_not(None))
    keys = sorted(k for k, u in units.items() if u.role == kind)
    key = claim(conn, keys, had, target if kind == "test" else NO_TARGET, wait)
    return units[key] if key is not None else None
