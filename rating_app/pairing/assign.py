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

The other designs balance units instead of clips (designs.Unit: a pair of conditions of an item, or an item's
page) by the same rules: a slot gets the least-covered unit still short of its target that the rater has not had,
a unit's cover being its answered trials plus its held slots. What a design draws from is its own (designs/);
this module holds the rules they share.

A session expires when it has not answered anything for `slot_timeout_s` (polling is not progress); its
unanswered slots are released and can never be answered, so no clip ever exceeds its target.
"""

from __future__ import annotations

import datetime as dt
import functools

from sqlalchemy import bindparam, func, select, update

from ..store.db import COVER_KEY, COVERED_KINDS, Cover, Lock, Rater, Trial


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


def cover(conn, *where) -> dict[str, tuple[int, int]]:
    """{key: (answered, held)} from the Cover rows."""
    return {k: (a, h) for k, a, h in conn.execute(select(Cover.key, Cover.answered, Cover.held).where(*where))}


# The statements of every slot given and answered, built once: building one costs more of SQLAlchemy's CPU than
# running it does.
_ONE_COVER = Cover.key == bindparam("cover_key")
_HOLD = update(Cover).where(_ONE_COVER).values(held=Cover.held + 1)
_ANSWER = update(Cover).where(_ONE_COVER).values(held=Cover.held - 1, answered=Cover.answered + 1)
_COVERED = Cover.answered + Cover.held  # a key's cover


def hold(conn, key: str) -> None:
    """A slot for `key` was just assigned (in the assigning transaction)."""
    conn.execute(_HOLD, {"cover_key": key})


def answer(conn, key: str) -> None:
    """A held slot for `key` was just answered (in the answering transaction)."""
    conn.execute(_ANSWER, {"cover_key": key})


def short_or_full(cov, target, unit, answers, answered):
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


def slots(rng, n_test: int, n_catch: int) -> list[tuple[str, None]]:
    rating = [("test", None)] * n_test + [("catch", None)] * n_catch
    rng.shuffle(rating)
    return rating


def claim(conn, keys, had: str, rater_pk: int, target: int, wait: bool, params=None):
    """The least-covered key among `keys` still short of `target` and not in what the rater `rater_pk` has had
    (the Trial column named `had`), ties at random, with its Cover row locked for this transaction; None when
    there is none. `keys`: a list, or a select of the keys whose parameters are `params`. Without `wait`, rows that
    other servers are claiming at this moment are skipped (PostgreSQL's SKIP LOCKED), so concurrent servers claim
    different rows instead of queueing on one lock. The row's counts are checked again once it is locked, so no key
    is ever handed out beyond its target."""
    listed = isinstance(keys, (list, tuple))
    stmt = _claim_statement(None if listed else keys, had, wait)
    values = {"rater_pk": rater_pk, "target": target, **({"keys": list(keys)} if listed else params or {})}
    return conn.execute(stmt, values).scalar()


@functools.cache
def _claim_statement(keys_from, had: str, wait: bool):
    """claim's statement, built once for each select of keys (None: a list, the parameter "keys"), Trial column
    and way of locking."""
    column = getattr(Trial, had)
    keys = bindparam("keys", expanding=True) if keys_from is None else keys_from
    done = select(column).where(Trial.rater_pk == bindparam("rater_pk"), column.is_not(None))
    return (
        select(Cover.key)
        .where(Cover.key.in_(keys), _COVERED < bindparam("target"), Cover.key.not_in(done))
        .order_by(_COVERED, func.random())
        .limit(1)
        .with_for_update(skip_locked=not wait)
    )
