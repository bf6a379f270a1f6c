"""Starting a session (POST /api/sessions): a new rater with its planned trials, or the same participant back.

Creating a session needs a JSON body and refuses cross-site browsers; resuming one by participant id needs proof
(the platform's session id, or the resume cookie set at creation), so a participant id alone never hands out a
token. The study's design plans the trials (designs/): training trials first, then test and catch slots that get
their clip or unit only when served.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import random
import secrets

from flask import current_app, jsonify, request
from sqlalchemy import func, insert, select
from sqlalchemy.exc import IntegrityError

from ..designs import LABELS, of_app
from ..guard.bodies import ext_field, json_body
from ..guard.limits import client_key
from ..pairing.active import for_units
from ..pairing.assign import StudyFull, expire_idle, lock_assign
from ..store.db import Rater, Trial, TrialClip, app_engine, utcnow
from ..store.rounds import refresh
from . import sessions
from .answers import TOLERANCE_MS

RESUME_COOKIE = "rating_resume"
CLIENT_WINDOW = dt.timedelta(hours=1)


def hash_secret(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


def reply(rater, status: int, resume_secret: str | None = None):
    cfg = current_app.config
    resp = jsonify(
        session=rater.token,
        rater_id=rater.rater_id,
        n_trials=rater.n_training + rater.n_rating,
        n_training=rater.n_training,
        n_rating=rater.n_rating,
        resumed=status == 200,
        min_view=cfg["MIN_VIEW"],
        view_tolerance_ms=TOLERANCE_MS,
        design=cfg["STUDY_DESIGN"],
    )
    resp.status_code = status
    if resume_secret:
        resp.set_cookie(
            RESUME_COOKIE,
            resume_secret,
            max_age=7 * 24 * 3600,
            path="/api/sessions",
            httponly=True,
            samesite="Strict",
            secure=cfg["SESSION_COOKIE_SECURE"],
        )
    return resp


def resume(conn, external_id, ext_session, now):
    """The session of a returning participant, but only with proof that it is the same person."""
    old = conn.execute(select(Rater).where(Rater.external_id == external_id)).first()
    if old is None:
        return None
    cookie = request.cookies.get(RESUME_COOKIE)
    proof = (bool(old.external_session and ext_session) and hmac.compare_digest(old.external_session, ext_session)) or (
        bool(cookie and old.resume_hash) and hmac.compare_digest(hash_secret(cookie), old.resume_hash)
    )
    if not proof:
        return jsonify(
            error="this participant id has already started a session; it can be resumed only from the "
            "same browser or through the recruiting platform's link",
            resume=False,
        ), 409
    if old.expired_at is not None or expire_idle(conn, current_app.config["SLOT_TIMEOUT_S"], now, old.id):
        return sessions.expired_reply()
    return reply(old, 200)


def start():
    """The reply to POST /api/sessions."""
    body = json_body(("external_id", "study_id", "session_id"))
    external_id, study_id, ext_session = (ext_field(body, k) for k in ("external_id", "study_id", "session_id"))
    cfg = current_app.config
    now = utcnow()
    try:
        with app_engine().begin() as conn:
            if external_id is not None:
                # The same participant again (a new tab, a retried request): resume, with proof.
                resumed = resume(conn, external_id, ext_session, now)
                if resumed is not None:
                    return resumed
            lock_assign(conn)
            client, limit = client_key(), cfg["SESSIONS_PER_CLIENT"]
            if (
                limit
                and conn.execute(
                    select(func.count())
                    .select_from(Rater)
                    .where(Rater.client == client, Rater.created_at >= now - CLIENT_WINDOW)
                ).scalar()
                >= limit
            ):
                return jsonify(error="too many new sessions from this address; please try again later"), 429
            expire_idle(conn, cfg["SLOT_TIMEOUT_S"], now)
            ext = refresh(conn)  # a round begun or a condition withdrawn since this worker loaded the study
            ranking = for_units(ext, ext["units"])
            closed = ranking.closed(conn) if ranking is not None else None
            if closed:  # the stopping rule (pairing/active.py): no new raters, started sessions finish
                return jsonify(error=closed, full=True, closed=True), 409
            rng = random.Random(secrets.randbits(64))
            try:
                plan = of_app().plan(conn, rng, cfg, ext["clips"].values(), ext["units"])
            except StudyFull as e:
                return jsonify(error=str(e), full=True), 409
            resume_secret = secrets.token_urlsafe(24)
            n_training = sum(kind == "training" for kind, _ in plan)
            values = dict(
                token=secrets.token_urlsafe(24),
                rater_id="r" + secrets.token_hex(6),
                external_id=external_id,
                study_id=study_id,
                external_session=ext_session,
                created_at=now,
                last_seen=now,
                last_progress=now,
                client=client,
                resume_hash=hash_secret(resume_secret),
                n_early=0,
                n_training=n_training,
                n_rating=len(plan) - n_training,
                completion_code=cfg["COMPLETION_CODE"] or secrets.token_hex(4).upper(),
            )
            rater_pk = conn.execute(insert(Rater).values(**values).returning(Rater.id)).scalar()
            _insert_trials(conn, rng, rater_pk, plan)
            rater = conn.execute(select(Rater).where(Rater.id == rater_pk)).one()
            return reply(rater, 201, resume_secret)
    except IntegrityError:
        # Two concurrent requests with the same external id: the other one won; resume it (with proof).
        if external_id is None:
            raise
        with app_engine().begin() as conn:
            resumed = resume(conn, external_id, ext_session, now)
            if resumed is None:
                raise
            return resumed


def _insert_trials(conn, rng, rater_pk, plan) -> None:
    """The session's planned trials, in order; a familiarisation trial of several clips gets its TrialClip rows
    (in an order drawn here)."""
    counters, rows, groups = {"training": 0, "rating": 0}, [], {}
    for pos, (kind, clip_id) in enumerate(plan):
        phase = "training" if kind == "training" else "rating"
        counters[phase] += 1
        if isinstance(clip_id, tuple):  # a familiarisation pair or page
            groups[pos], clip_id = clip_id, None
        rows.append(
            {
                "rater_pk": rater_pk,
                "clip_id": clip_id,
                "kind": kind,
                "phase": phase,
                "position": pos,
                "index": counters[phase],
                "released": False,
                "unit": "training" if pos in groups else None,
            }
        )
    conn.execute(insert(Trial), rows)  # one multi-row INSERT, not one per trial
    if groups:
        ids = dict(conn.execute(select(Trial.position, Trial.id).where(Trial.rater_pk == rater_pk)).all())
        conn.execute(
            insert(TrialClip),
            [
                {"trial_pk": ids[pos], "position": i, "label": LABELS[i], "clip_id": c}
                for pos, group in groups.items()
                for i, c in enumerate(rng.sample(group, len(group)))
            ],
        )
