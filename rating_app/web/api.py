"""The rater JSON API (CONTRACTS §5, §8): its endpoints. The page uses it; so do the simulated crowd and the load
tests.

Each endpoint is a thin door into the module that does the work: starting a session (trials/session_start.py), serving a
trial (trials/serving.py), its videos (trials/trial_videos.py), storing an answer (trials/answers.py), on a session's
row (trials/sessions.py). Every design (designs/) takes the same path: a trial is a slot served with a clip or a unit of
several clips, and answered with the design's value."""

from __future__ import annotations

from flask import Blueprint, abort, current_app, jsonify
from sqlalchemy import func, insert, select, update

from ..guard.bodies import int_field, json_body
from ..guard.limits import escape_text, same_site_only
from ..pairing.assign import expire_idle
from ..store.db import Event, Rater, Trial, TrialClip, app_engine, read_engine, utcnow
from ..trials import answers, session_start, sessions
from ..trials.serving import serve, trial_reply
from ..trials.trial_videos import CLIP_VIDEO, TRIAL_VIDEO, send_video, video_row

bp = Blueprint("api", __name__, url_prefix="/api")

EVENT_KINDS = ("video_error", "video_stalled", "page_error")
MAX_EVENTS = 30  # per session: enough for every trial's playback problem, not a log flood


@bp.post("/sessions")
def create_session():
    same_site_only()
    return session_start.start()


# The two hot calls use Core statements on a plain connection (no ORM unit of work): they are what 200
# concurrent raters hit. Every answer is committed before it is acknowledged. On SQLite, GET next only reads once
# its trial has been served (a write serves a new trial, ends a session, or refreshes a stale last_seen): a
# write transaction there takes the whole database. On PostgreSQL it locks only the session's row, so GET next
# goes straight to the write transaction, which saves a round trip in the usual case, a trial not yet served.
@bp.get("/sessions/<token>/next")
def next_trial(token):
    now = utcnow()
    if app_engine().dialect.name == "sqlite":
        with read_engine().connect() as conn, conn.begin():
            rater, trial = sessions.with_current(conn, token)
        if (
            trial is not None
            and trial.served_at is not None
            and not sessions.idle(rater, now)
            and not sessions.stale(rater, now)
        ):
            return trial_reply(token, rater, trial)
    with app_engine().begin() as conn:
        rater = sessions.lookup(conn, token, now)
        if current_app.config["STUDY_SOUND"] and rater.audio_passed_at is None and rater.expired_at is None:
            return jsonify(error="the audio check comes first", audio_check=True), 403
        if rater.completed_at is None and sessions.idle(rater, now):
            expire_idle(conn, current_app.config["SLOT_TIMEOUT_S"], now, rater.id)
            return sessions.expired_reply()
        trial, dropped = serve(conn, rater.id, now) if rater.completed_at is None else (None, False)
        if trial is not None:
            return trial_reply(token, sessions.lookup(conn, token) if dropped else rater, trial, conn)
        if rater.completed_at is None:
            if sessions.lookup(conn, token).n_rating == 0:
                # Every slot was dropped (the study filled meanwhile): nothing was rated, so no code.
                conn.execute(update(Rater).where(Rater.id == rater.id).values(expired_at=now))
                return jsonify(
                    error="study full: every clip has all its ratings. Thank you for your interest", full=True
                ), 409
            conn.execute(
                update(Rater)
                .where(Rater.id == rater.id, Rater.completed_at.is_(None))
                .values(completed_at=now, last_seen=now)
            )
    return jsonify(sessions.completion(rater))


@bp.get("/sessions/<token>/trials/<int(max=2147483647):trial_id>/video.mp4")
def trial_video(token, trial_id):
    """The video of a served trial; the bytes sent are recorded (an answer before the whole file was sent is
    flagged)."""
    t = video_row(TRIAL_VIDEO, token, trial_id=trial_id)
    if t is None or t.clip_id is None or t.served_at is None or t.released:
        abort(404, "unknown video")
    return send_video(Trial, t)


@bp.get("/sessions/<token>/trials/<int(max=2147483647):trial_id>/clips/<any(A,B,C,D,E,F,G,H):label>.mp4")
def clip_video(token, trial_id, label):
    """One clip of a served trial of several clips, by the label the rater sees; the bytes sent are recorded per
    clip (an answer before every clip's whole file was sent is flagged)."""
    t = video_row(CLIP_VIDEO, token, trial_id=trial_id, label=label)
    if t is None or t.served_at is None or t.released:
        abort(404, "unknown video")
    return send_video(TrialClip, t)


@bp.post("/sessions/<token>/ratings")
def post_rating(token):
    return answers.accept(token)


@bp.post("/sessions/<token>/events")
def post_event(token):
    body = json_body(("trial_id", "kind", "detail"), required=("kind",))
    kind = body["kind"]
    if kind not in EVENT_KINDS:
        abort(400, f"field 'kind' must be one of {', '.join(EVENT_KINDS)}")
    detail = body.get("detail") or ""
    if not isinstance(detail, str):
        abort(400, "field 'detail' must be a string")
    detail = escape_text(detail)[:500]
    trial_id = int_field(body, "trial_id", 1, 2**31 - 1, nullable=True)
    with app_engine().begin() as conn:
        rater = sessions.lookup(conn, token)
        clip = None
        if trial_id is not None:
            clip = conn.execute(select(Trial.clip_id).where(Trial.id == trial_id, Trial.rater_pk == rater.id)).first()
            if clip is None:
                abort(404, "unknown trial for this session")
            clip = clip.clip_id
        n = conn.execute(select(func.count()).select_from(Event).where(Event.rater_pk == rater.id)).scalar()
        if n >= MAX_EVENTS:
            return jsonify(error=f"at most {MAX_EVENTS} reports per session"), 429
        conn.execute(
            insert(Event).values(rater_pk=rater.id, trial_pk=trial_id, kind=kind, detail=detail, created_at=utcnow())
        )
    current_app.logger.warning("client %s: rater %s clip %s: %s", kind, rater.rater_id, clip, detail)
    return jsonify(logged=True), 201
