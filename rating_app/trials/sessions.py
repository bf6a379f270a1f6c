"""A rater's session as the API reads it: its row (looked up, locked, refreshed), whether it has gone idle, its
current trial, and the replies that end it (expired, completed).

The hot statements are built once: building one costs about as much Python time as running it. They use Core
statements on a plain connection (no ORM unit of work): they are what 200 concurrent raters hit.
"""

from __future__ import annotations

from types import SimpleNamespace

from flask import abort, current_app, jsonify
from sqlalchemy import and_, bindparam, select, update
from sqlalchemy.orm import aliased

from ..guard.bodies import check_token
from ..store.db import Rater, StudySetting, Trial
from ..store.rounds import REVISION

TOUCH_EVERY_S = 30  # last_seen (shown on the dashboard) is refreshed at most this often
RATER_COLS = (
    Rater.id,
    Rater.rater_id,
    Rater.n_training,
    Rater.n_rating,
    Rater.completed_at,
    Rater.expired_at,
    Rater.completion_code,
    Rater.last_seen,
    Rater.last_progress,
    Rater.audio_passed_at,
)
TRIAL_COLS = (
    Trial.id,
    Trial.clip_id,
    Trial.kind,
    Trial.phase,
    Trial.index,
    Trial.position,
    Trial.served_at,
    Trial.unit,
    Trial.sample_clip,
)


_RATER = select(*RATER_COLS).where(Rater.token == bindparam("token"))
_RATER_LOCKED = _RATER.with_for_update()


def is_open(t=Trial):
    """Trial `t` (or an alias of it) is still to be answered: unanswered and not released."""
    return and_(t.answered_at.is_(None), t.released.is_(False))


# With the study's revision (store/rounds.py) read in the same statement, so that the worker that hands the trial a unit
# learns of a round begun or a condition withdrawn without a statement of its own.
_REVISION = select(StudySetting.value).where(StudySetting.name == REVISION).scalar_subquery().label("study_revision")
_CURRENT = (
    select(*TRIAL_COLS, _REVISION)
    .where(Trial.rater_pk == bindparam("rater_pk"), is_open())
    .order_by(Trial.position)
    .limit(1)
)
OPEN = aliased(Trial)  # another trial of the same rater
# The rater and its current trial in one read (GET next's read-only first step on SQLite). A read only: under a
# row lock, PostgreSQL would re-check the locked row but not the trial read beside it, so the write paths lock
# first and read the trial in a statement of its own.
_RATER_CURRENT = (
    select(*RATER_COLS, *(c.label("t_" + c.key) for c in TRIAL_COLS))
    .select_from(Rater)
    .outerjoin(
        Trial,
        Trial.id
        == select(OPEN.id)
        .where(OPEN.rater_pk == Rater.id, is_open(OPEN))
        .order_by(OPEN.position)
        .limit(1)
        .correlate(Rater)
        .scalar_subquery(),
    )
    .where(Rater.token == bindparam("token"))
)


def lookup(conn, token: str, now=None):
    """The rater's row; 404 for an unknown token. With `now` (in a write transaction), the row is locked first
    of all, so one session's writes (serving, answering, expiring) run one at a time and every transaction takes
    a rater row before any other; and last_seen is refreshed when it is stale."""
    check_token(token)
    lock = now is not None and conn.dialect.name != "sqlite"  # SQLite: BEGIN IMMEDIATE already holds the lock
    row = conn.execute(_RATER_LOCKED if lock else _RATER, {"token": token}).first()
    if row is None:
        abort(404, "unknown session")
    if now is not None and stale(row, now):
        conn.execute(update(Rater).where(Rater.id == row.id).values(last_seen=now))
    return row


def stale(row, now) -> bool:
    return (now - row.last_seen).total_seconds() > TOUCH_EVERY_S


def idle(row, now) -> bool:
    """No answer for longer than the slot timeout (the session will be expired)."""
    return row.completed_at is None and (
        row.expired_at is not None or (now - row.last_progress).total_seconds() > current_app.config["SLOT_TIMEOUT_S"]
    )


def current(conn, rater_pk):
    """The trial on the rater's screen: the first unanswered one in the rater's order."""
    return conn.execute(_CURRENT, {"rater_pk": rater_pk}).first()


def with_current(conn, token: str):
    """(rater, its current trial or None) in one read, for a read-only transaction; 404 for an unknown token."""
    check_token(token)
    row = conn.execute(_RATER_CURRENT, {"token": token}).first()
    if row is None:
        abort(404, "unknown session")
    m = row._mapping
    rater = SimpleNamespace(**{c.key: m[c.key] for c in RATER_COLS})
    trial = SimpleNamespace(**{c.key: m["t_" + c.key] for c in TRIAL_COLS}) if m["t_id"] is not None else None
    return rater, trial


def expired_reply():
    return jsonify(
        error="this session has expired: nothing was answered for too long. It cannot be continued "
        "and gives no completion code",
        expired=True,
    ), 410


def completion(rater) -> dict:
    out = {"done": True, "completion_code": rater.completion_code}
    url = current_app.config["COMPLETION_URL"]
    if url:
        out["redirect_url"] = url.replace("{code}", rater.completion_code)
    return out
