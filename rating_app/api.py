"""The rater JSON API (CONTRACTS §5). The page uses it; so do the simulated crowd and the load tests.

Every answer is committed before it is sent, so an acknowledged rating survives a crash of the server.
The session token in the URL is the only credential (no cookies), which makes the API immune to CSRF.
"""
from __future__ import annotations

import math
import random
import re
import secrets

from flask import Blueprint, abort, current_app, jsonify, request, url_for
from sqlalchemy import func, insert, or_, select, update
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from .assign import StudyFull, plan_trials
from .db import Event, Rater, Rating, Trial, utcnow

bp = Blueprint("api", __name__, url_prefix="/api")

TOKEN = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
EXTERNAL = re.compile(r"^[A-Za-z0-9_.:@-]{1,128}$")
EVENT_KINDS = ("video_error", "video_stalled", "page_error")
MAX_WATCHED_MS = 24 * 3600 * 1000


def engine():
    return current_app.extensions["rating_app"]["engine"]


def json_body(allowed: tuple[str, ...], required: tuple[str, ...] = (), optional_body=False) -> dict:
    if optional_body and not request.get_data(cache=True):
        body = {}
    else:
        if not request.is_json:
            abort(415, "expected a JSON body (Content-Type: application/json)")
        body = request.get_json(silent=True)
        if not isinstance(body, dict):
            abort(400, "body must be a JSON object")
    unknown = sorted(set(body) - set(allowed))
    if unknown:
        abort(400, f"unknown field '{unknown[0]}'")
    for k in required:
        if k not in body:
            abort(400, f"missing field '{k}'")
    return body


def _int_field(body, name, lo, hi, nullable=False):
    v = body.get(name)
    if v is None and nullable:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (isinstance(v, float) and not (
            math.isfinite(v) and v.is_integer())):
        abort(400, f"field '{name}' must be an integer")
    v = int(v)
    if not lo <= v <= hi:
        abort(400, f"field '{name}' must be between {lo} and {hi}")
    return v


def _ext(body, name):
    v = body.get(name)
    if v is None:
        return None
    if not isinstance(v, str) or not EXTERNAL.match(v):
        abort(400, f"field '{name}' must be 1-128 characters of letters, digits and _.:@-")
    return v


def _session_reply(rater: Rater, status: int):
    return jsonify(session=rater.token, rater_id=rater.rater_id, n_trials=rater.n_training + rater.n_rating,
                   n_training=rater.n_training, n_rating=rater.n_rating, resumed=status == 200), status


@bp.post("/sessions")
def create_session():
    body = json_body(("external_id", "study_id", "session_id"), optional_body=True)
    external_id, study_id, ext_session = _ext(body, "external_id"), _ext(body, "study_id"), _ext(body, "session_id")
    cfg = current_app.config
    with Session(engine()) as s:
        try:
            with s.begin():
                if external_id is not None:
                    # The same participant again (reload, second tab, retried request): resume.
                    old = s.scalar(select(Rater).where(Rater.external_id == external_id))
                    if old is not None:
                        return _session_reply(old, 200)
                rng = random.Random(secrets.randbits(64))
                try:
                    plan = plan_trials(s, rng, cfg["RATINGS_PER_CLIP"], cfg["CLIPS_PER_RATER"],
                                       cfg["SLOT_TIMEOUT_S"])
                except StudyFull as e:
                    return jsonify(error=str(e), full=True), 409
                now = utcnow()
                rater = Rater(token=secrets.token_urlsafe(24), rater_id="r" + secrets.token_hex(6),
                              external_id=external_id, study_id=study_id, external_session=ext_session,
                              created_at=now, last_seen=now,
                              completion_code=cfg["COMPLETION_CODE"] or secrets.token_hex(4).upper())
                s.add(rater)
                s.flush()
                counters, rows = {"training": 0, "rating": 0}, []
                for pos, (clip_id, phase) in enumerate(plan):
                    counters[phase] += 1
                    rows.append({"rater_pk": rater.id, "clip_id": clip_id, "phase": phase, "position": pos,
                                 "index": counters[phase], "released": False})
                s.execute(insert(Trial), rows)            # one multi-row INSERT, not one per trial
                rater.n_training, rater.n_rating = counters["training"], counters["rating"]
                s.flush()
                return _session_reply(rater, 201)
        except IntegrityError:
            # Two concurrent requests with the same external id: the other one won; resume it.
            if external_id is None:
                raise
            with s.begin():
                old = s.scalar(select(Rater).where(Rater.external_id == external_id))
                if old is None:
                    raise
                return _session_reply(old, 200)


def _completion(rater: Rater) -> dict:
    out = {"done": True, "completion_code": rater.completion_code}
    url = current_app.config["COMPLETION_URL"]
    if url:
        out["redirect_url"] = url.replace("{code}", rater.completion_code)
    return out


TOUCH_EVERY_S = 30     # last_seen (for freeing abandoned slots) is refreshed at most this often
RATER_COLS = (Rater.id, Rater.rater_id, Rater.n_training, Rater.n_rating, Rater.completed_at,
              Rater.completion_code, Rater.last_seen)


def _rater(conn, token: str, now=None):
    """The rater's row; 404 for an unknown token. With `now`, refreshes last_seen when it is stale."""
    if not TOKEN.match(token):
        abort(404, "unknown session")
    row = conn.execute(select(*RATER_COLS).where(Rater.token == token)).first()
    if row is None:
        abort(404, "unknown session")
    if now is not None and _stale(row, now):
        conn.execute(update(Rater).where(Rater.id == row.id).values(last_seen=now))
    return row


def _stale(row, now) -> bool:
    return (now - row.last_seen).total_seconds() > TOUCH_EVERY_S


def _current(conn, rater_pk):
    """The trial on the rater's screen: the first unanswered one in the rater's order."""
    return conn.execute(select(Trial.id, Trial.clip_id, Trial.phase, Trial.index, Trial.position)
                        .where(Trial.rater_pk == rater_pk, Trial.answered_at.is_(None), Trial.released.is_(False))
                        .order_by(Trial.position).limit(1)).first()


# The two hot calls use Core statements on a plain connection (no ORM unit of work): they are what 200
# concurrent raters hit. GET next only reads (a short write follows when last_seen is stale or the session
# has just ended); every answer is committed before it is acknowledged.
@bp.get("/sessions/<token>/next")
def next_trial(token):
    now = utcnow()
    with engine().connect().execution_options(read_only=True) as conn, conn.begin():
        rater = _rater(conn, token)
        trial = _current(conn, rater.id)
    stmt = None
    if trial is None and rater.completed_at is None:
        stmt = update(Rater).where(Rater.id == rater.id, Rater.completed_at.is_(None)) \
            .values(completed_at=now, last_seen=now)
    elif _stale(rater, now):
        stmt = update(Rater).where(Rater.id == rater.id).values(last_seen=now)
    if stmt is not None:
        with engine().begin() as conn:
            conn.execute(stmt)
    if trial is None:
        return jsonify(_completion(rater))
    return jsonify(trial={
        "trial_id": trial.id, "clip_id": trial.clip_id,
        "video_url": url_for("pages.video", name=trial.clip_id + ".mp4"),
        "phase": trial.phase, "index": trial.index,
        "of": rater.n_training if trial.phase == "training" else rater.n_rating})


def _insert_ignore(conn):
    return (sqlite_insert if conn.dialect.name == "sqlite" else pg_insert)(Rating)


@bp.post("/sessions/<token>/ratings")
def post_rating(token):
    body = json_body(("trial_id", "rating", "watched_ms"), required=("trial_id",))
    trial_id = _int_field(body, "trial_id", 1, 2**31 - 1)
    watched_ms = _int_field(body, "watched_ms", 0, MAX_WATCHED_MS, nullable=True)
    now = utcnow()
    with engine().begin() as conn:
        rater = _rater(conn, token, now)
        trial = conn.execute(select(Trial.id, Trial.phase, Trial.clip_id, Trial.position, Trial.answered_at)
                             .where(Trial.id == trial_id, Trial.rater_pk == rater.id)).first()
        if trial is None:
            abort(404, "unknown trial for this session")
        training = trial.phase == "training"
        if training and body.get("rating") is not None:
            abort(400, "field 'rating' must be null for a familiarisation trial")
        if not training:
            if "rating" not in body:
                abort(400, "missing field 'rating'")
            rating = _int_field(body, "rating", 1, 5)
        if trial.answered_at is not None:                       # a repeat: acknowledged, stored once
            stored = None if training else conn.execute(
                select(Rating.rating).where(Rating.trial_pk == trial.id)).scalar()
            return jsonify(stored=False, duplicate=True, rating=stored), 200
        # Only the trial on screen can be answered: the first unanswered one in the rater's order (a trial
        # released after a long absence still counts, so a late answer is kept rather than lost).
        # (This trial itself counts as unanswered here, in case a concurrent duplicate has just answered it.)
        first = conn.execute(select(func.min(Trial.position)).where(
            Trial.rater_pk == rater.id, or_(Trial.answered_at.is_(None), Trial.id == trial.id))).scalar()
        if trial.position != first:
            abort(409, "this trial has not been shown yet")
        if training:
            res = conn.execute(update(Trial).where(Trial.id == trial.id, Trial.answered_at.is_(None))
                               .values(answered_at=now))
            return (jsonify(stored=True), 201) if res.rowcount == 1 else (jsonify(stored=False, duplicate=True), 200)
        # INSERT .. ON CONFLICT DO NOTHING RETURNING: a concurrent duplicate waits on the unique index and
        # then inserts nothing, so a rating is stored exactly once whatever the timing.
        stmt = _insert_ignore(conn).values(trial_pk=trial.id, rater_pk=rater.id, clip_id=trial.clip_id,
                                           rating=rating, watched_ms=watched_ms, submitted_at=now)
        new_id = conn.execute(stmt.on_conflict_do_nothing(index_elements=["trial_pk"]).returning(Rating.id)).scalar()
        if new_id is not None:
            conn.execute(update(Trial).where(Trial.id == trial.id).values(answered_at=now))
            return jsonify(stored=True), 201
        stored = conn.execute(select(Rating.rating).where(Rating.trial_pk == trial.id)).scalar()
        return jsonify(stored=False, duplicate=True, rating=stored), 200


@bp.post("/sessions/<token>/events")
def post_event(token):
    body = json_body(("trial_id", "kind", "detail"), required=("kind",))
    kind = body["kind"]
    if kind not in EVENT_KINDS:
        abort(400, f"field 'kind' must be one of {', '.join(EVENT_KINDS)}")
    detail = body.get("detail") or ""
    if not isinstance(detail, str):
        abort(400, "field 'detail' must be a string")
    detail = detail[:500]
    trial_id = _int_field(body, "trial_id", 1, 2**31 - 1, nullable=True)
    with engine().begin() as conn:
        rater = _rater(conn, token)
        clip = None
        if trial_id is not None:
            clip = conn.execute(select(Trial.clip_id).where(Trial.id == trial_id, Trial.rater_pk == rater.id)).scalar()
            if clip is None:
                abort(404, "unknown trial for this session")
        conn.execute(insert(Event).values(rater_pk=rater.id, trial_pk=trial_id, kind=kind, detail=detail,
                                          created_at=utcnow()))
    current_app.logger.warning("client %s: rater %s clip %s: %s", kind, rater.rater_id, clip, detail)
    return jsonify(logged=True), 201
