"""Which clips a rater gets, and when a slot is held.

Every rater sees all training clips (familiarisation) and all catch clips. A new session plans only its slots:
the training clips, one slot per catch clip and up to `clips_per_rater` test slots, in a random order. A test or
catch slot gets its clip when it is first served (GET next): the least-covered test clip still short of its
target that this rater has not had, ties broken at random (a catch slot: a catch clip the rater has not had).
A clip's cover = stored ratings + slots held, i.e. served and unanswered in a live session; db.Cover keeps both
counts per clip, updated in the same transactions as the trials they count. So a session holds at
most one slot, only once it has come that far, and only until it answers or expires: creating sessions, or
polling GET next, holds nothing. A slot for which no test clip is left is dropped (the session gets shorter).

Pairwise and parallel studies balance units instead of clips (designs.Unit: a pair of conditions of an item, or
an item's page) by the same rules: a slot gets the least-covered unit still short of its target that the rater
has not had, a unit's cover being its answered trials plus its held slots.

A session expires when it has not answered anything for `slot_timeout_s` (polling is not progress); its
unanswered slots are released and can never be answered, so no clip ever exceeds its target.
"""

from __future__ import annotations

import datetime as dt
import random

from sqlalchemy import func, select, update

from core import study

from .db import COVER_KEY, Clip, Cover, Lock, Rater, Trial
from .designs import training_groups


class StudyFull(Exception):
    pass


def lock_assign(conn) -> None:
    """Serialise assignment between workers (SQLite already holds the write lock: BEGIN IMMEDIATE)."""
    if conn.dialect.name != "sqlite":
        conn.execute(select(Lock).where(Lock.name == "assign").with_for_update())


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
            .where(*open_slot, Trial.kind == "test", COVER_KEY.is_not(None))
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


def plan_session(conn, rng: random.Random, target: int, clips_per_rater: int | None) -> list[tuple[str, str | None]]:
    """[(kind, clip_id or None)] in presentation order for a new session; raise StudyFull."""
    cov = coverage(conn)
    if not cov:
        raise StudyFull("the study has no test clips")
    short = _short_or_full(cov, target, "clip", "ratings", "rated")
    n_test = short if not clips_per_rater else min(clips_per_rater, short)
    n_catch = conn.execute(
        select(func.count()).select_from(Clip).where(Clip.role == "catch", Clip.condition == study.CATCH)
    ).scalar()
    training = list(conn.execute(select(Clip.clip_id).where(Clip.role == "training").order_by(Clip.clip_id)).scalars())
    rng.shuffle(training)
    rating = [("test", None)] * n_test + [("catch", None)] * n_catch
    rng.shuffle(rating)
    return [("training", c) for c in training] + rating


def claim(conn, keys, had, target: int, wait: bool, lock: bool = True):
    """The least-covered key among `keys` still short of `target` and not in `had`, ties at random, with its
    Cover row locked for this transaction; None when there is none. Without `wait`, rows that other servers are
    claiming at this moment are skipped (PostgreSQL's SKIP LOCKED), so concurrent servers claim different rows
    instead of queueing on one lock. The row's counts are checked again once it is locked, so no key is ever
    handed out beyond its target. Without `lock` the same query only looks (a catch slot runs it too, so that
    its timing matches a test slot's, but must not hold a row it does not use)."""
    cover = Cover.answered + Cover.held
    q = (
        select(Cover.key)
        .where(Cover.key.in_(keys), cover < target, Cover.key.not_in(had))
        .order_by(cover, func.random())
        .limit(1)
    )
    return conn.execute(q.with_for_update(skip_locked=not wait) if lock else q).scalar()


def assign_slot(conn, rng: random.Random, rater_pk: int, kind: str, target: int, wait=False) -> str | None:
    """The clip for a test or catch slot now being served, or None when none is left for this rater (None also
    when, without `wait`, the only ones left are being claimed by other servers: call again under
    `lock_assign` with `wait`). Both kinds run the same queries, so their timing does not tell them apart."""
    had = select(Trial.clip_id).where(Trial.rater_pk == rater_pk, Trial.clip_id.is_not(None))
    test = claim(conn, select(Clip.clip_id).where(Clip.role == "test"), had, target, wait, lock=kind == "test")
    if kind == "catch":
        catch = conn.execute(
            select(Clip.clip_id)
            .where(Clip.role == "catch", Clip.condition == study.CATCH, Clip.clip_id.not_in(had))
            .order_by(Clip.clip_id)
        ).scalars()
        left = list(catch)
        return rng.choice(left) if left else None
    return test


# ---------------------------------------------------------------------------------------- pairwise / parallel
def unit_coverage(conn, units) -> dict[str, tuple[int, int]]:
    """{unit key: (answered trials, held slots)} for every test unit of this manifest."""
    cov = _cover(conn)
    return {k: cov.get(k, (0, 0)) for k, u in units.items() if u.role == "test"}


def units_full(conn, units, target: int) -> bool:
    cov = unit_coverage(conn, units)
    return bool(cov) and all(d >= target for d, _ in cov.values())


def plan_units(conn, rng: random.Random, target: int, per_rater: int | None, design: str, clips, units):
    """[(kind, training clips or None)] in presentation order for a new pairwise or parallel session."""
    cov = unit_coverage(conn, units)
    short = _short_or_full(cov, target, "comparison", "answers", "answered")
    n_test = short if not per_rater else min(per_rater, short)
    n_catch = sum(u.role == "catch" for u in units.values())
    rating = [("test", None)] * n_test + [("catch", None)] * n_catch
    rng.shuffle(rating)
    return [("training", g) for g in training_groups(design, clips, rng)] + rating


def assign_unit(conn, rng: random.Random, rater_pk: int, kind: str, target: int, units, wait=False):
    """The Unit for a test or catch slot now being served, or None when none is left for this rater (as
    assign_slot, whose rules it follows); both kinds run the same queries."""
    had = select(Trial.unit).where(Trial.rater_pk == rater_pk, Trial.unit.is_not(None))
    test = claim(conn, [k for k, u in units.items() if u.role == "test"], had, target, wait, lock=kind == "test")
    if kind == "catch":
        taken = set(conn.execute(had).scalars())
        left = [u for k, u in sorted(units.items()) if u.role == "catch" and k not in taken]
        return rng.choice(left) if left else None
    return units[test] if test is not None else None
