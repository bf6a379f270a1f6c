"""The rater JSON API (CONTRACTS §5). The page uses it; so do the simulated crowd and the load tests.

Every answer is committed before it is sent, so an acknowledged rating survives a crash of the server.
The session token in the URL is the credential for a session's calls; creating a session needs a JSON body and
refuses cross-site browsers, and resuming one by participant id needs proof (the platform's session id, or the
resume cookie set at creation), so a participant id alone never hands out a token.

The server, not the page, decides whether a clip was watched: it records when it first served each trial and which
bytes of its video it sent (fetched.py), and refuses an answer that comes before the clip could have played to the
end.

Every design (designs.py) takes the same path: a pairwise or parallel trial is a slot like an acr one, served
with a unit of several clips instead of one clip, and answered with a preference or a page of ratings.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import hmac
import math
import random
import re
import secrets
from types import SimpleNamespace

from flask import Blueprint, abort, current_app, jsonify, request, url_for
from sqlalchemy import and_, bindparam, func, insert, or_, select, text, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import aliased

from core import study

from . import fetched
from .assign import (
    StudyFull,
    answer,
    assign_slot,
    assign_unit,
    expire_idle,
    hold,
    lock_assign,
    plan_session,
    plan_units,
)
from .db import Event, PageRating, Preference, Rater, Rating, Trial, TrialClip, app_engine, read_engine, utcnow
from .designs import ANSWER_FIELD, LABELS
from .designs import required_ms as design_required_ms
from .guard import check_depth, client_key, escape_text, same_site_only

bp = Blueprint("api", __name__, url_prefix="/api")

TOKEN = re.compile(r"[A-Za-z0-9_-]{16,64}")  # always fullmatch: '$' would let a trailing newline in
EXTERNAL = re.compile(r"[A-Za-z0-9_.:@-]{1,128}")
EVENT_KINDS = ("video_error", "video_stalled", "page_error")
MAX_WATCHED_MS = 24 * 3600 * 1000
MAX_EVENTS = 30  # per session: enough for every trial's playback problem, not a log flood
TOLERANCE_MS = 250  # clock and decoding slack on the minimum viewing time
RESUME_COOKIE = "rating_resume"
CLIENT_WINDOW = dt.timedelta(hours=1)


def json_body(allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
    if not request.is_json:
        abort(415, "expected a JSON body (Content-Type: application/json)")
    check_depth(request.get_data(cache=True))
    body = request.get_json(silent=True)
    if not isinstance(body, dict):
        abort(400, "body must be a JSON object")
    unknown = sorted(set(body) - set(allowed))
    if unknown:
        abort(400, f"unknown field '{escape_text(unknown[0])[:64]}'")
    for k in required:
        if k not in body:
            abort(400, f"missing field '{k}'")
    return body


def _int_field(body, name, lo, hi, nullable=False):
    v = body.get(name)
    if v is None and nullable:
        return None
    if (
        isinstance(v, bool)
        or not isinstance(v, (int, float))
        or (isinstance(v, float) and not (math.isfinite(v) and v.is_integer()))
    ):
        abort(400, f"field '{name}' must be an integer")
    v = int(v)
    if not lo <= v <= hi:
        abort(400, f"field '{name}' must be between {lo} and {hi}")
    return v


def _ext(body, name):
    v = body.get(name)
    if v is None:
        return None
    if not isinstance(v, str) or not EXTERNAL.fullmatch(v):
        abort(400, f"field '{name}' must be 1-128 characters of letters, digits and _.:@-")
    return v


def _hash(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


def _session_reply(rater, status: int, resume_secret: str | None = None):
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


def _expired_reply():
    return jsonify(
        error="this session has expired: nothing was answered for too long. It cannot be continued "
        "and gives no completion code",
        expired=True,
    ), 410


def _resume(conn, external_id, ext_session, now):
    """The session of a returning participant, but only with proof that it is the same person."""
    old = conn.execute(select(Rater).where(Rater.external_id == external_id)).first()
    if old is None:
        return None
    cookie = request.cookies.get(RESUME_COOKIE)
    proof = (bool(old.external_session and ext_session) and hmac.compare_digest(old.external_session, ext_session)) or (
        bool(cookie and old.resume_hash) and hmac.compare_digest(_hash(cookie), old.resume_hash)
    )
    if not proof:
        return jsonify(
            error="this participant id has already started a session; it can be resumed only from the "
            "same browser or through the recruiting platform's link",
            resume=False,
        ), 409
    if old.expired_at is not None or expire_idle(conn, current_app.config["SLOT_TIMEOUT_S"], now, old.id):
        return _expired_reply()
    return _session_reply(old, 200)


@bp.post("/sessions")
def create_session():
    same_site_only()
    body = json_body(("external_id", "study_id", "session_id"))
    external_id, study_id, ext_session = _ext(body, "external_id"), _ext(body, "study_id"), _ext(body, "session_id")
    cfg = current_app.config
    now = utcnow()
    try:
        with app_engine().begin() as conn:
            if external_id is not None:
                # The same participant again (a new tab, a retried request): resume, with proof.
                resumed = _resume(conn, external_id, ext_session, now)
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
            rng = random.Random(secrets.randbits(64))
            try:
                if cfg["STUDY_DESIGN"] == "acr":
                    plan = plan_session(
                        conn, rng, cfg["RATINGS_PER_CLIP"], cfg["CLIPS_PER_RATER"], cfg["CATCH_PER_RATER"]
                    )
                else:
                    ext = current_app.extensions["rating_app"]
                    plan = plan_units(
                        conn,
                        rng,
                        cfg["RATINGS_PER_CLIP"],
                        cfg["CLIPS_PER_RATER"],
                        cfg["STUDY_DESIGN"],
                        ext["clips"].values(),
                        ext["units"],
                        cfg["CATCH_PER_RATER"],
                    )
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
                resume_hash=_hash(resume_secret),
                n_early=0,
                n_training=n_training,
                n_rating=len(plan) - n_training,
                completion_code=cfg["COMPLETION_CODE"] or secrets.token_hex(4).upper(),
            )
            rater_pk = conn.execute(insert(Rater).values(**values).returning(Rater.id)).scalar()
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
            rater = conn.execute(select(Rater).where(Rater.id == rater_pk)).one()
            return _session_reply(rater, 201, resume_secret)
    except IntegrityError:
        # Two concurrent requests with the same external id: the other one won; resume it (with proof).
        if external_id is None:
            raise
        with app_engine().begin() as conn:
            resumed = _resume(conn, external_id, ext_session, now)
            if resumed is None:
                raise
            return resumed


def _completion(rater) -> dict:
    out = {"done": True, "completion_code": rater.completion_code}
    url = current_app.config["COMPLETION_URL"]
    if url:
        out["redirect_url"] = url.replace("{code}", rater.completion_code)
    return out


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
)


# The hot statements are built once: building one costs about as much Python time as running it.
_RATER = select(*RATER_COLS).where(Rater.token == bindparam("token"))
_RATER_LOCKED = _RATER.with_for_update()


def _is_open(t=Trial):
    """Trial `t` (or an alias of it) is still to be answered: unanswered and not released."""
    return and_(t.answered_at.is_(None), t.released.is_(False))


_CURRENT = (
    select(*TRIAL_COLS).where(Trial.rater_pk == bindparam("rater_pk"), _is_open()).order_by(Trial.position).limit(1)
)
_open = aliased(Trial)
# The rater and its current trial in one read (GET next's read-only first step on SQLite). A read only: under a
# row lock, PostgreSQL would re-check the locked row but not the trial read beside it, so the write paths lock
# first and read the trial in a statement of its own.
_RATER_CURRENT = (
    select(*RATER_COLS, *(c.label("t_" + c.key) for c in TRIAL_COLS))
    .select_from(Rater)
    .outerjoin(
        Trial,
        Trial.id
        == select(_open.id)
        .where(_open.rater_pk == Rater.id, _is_open(_open))
        .order_by(_open.position)
        .limit(1)
        .correlate(Rater)
        .scalar_subquery(),
    )
    .where(Rater.token == bindparam("token"))
)


def _check_token(token: str) -> None:
    """404 for a string that cannot be a session token, before it reaches the database."""
    if not TOKEN.fullmatch(token):
        abort(404, "unknown session")


def _rater(conn, token: str, now=None):
    """The rater's row; 404 for an unknown token. With `now` (in a write transaction), the row is locked first
    of all, so one session's writes (serving, answering, expiring) run one at a time and every transaction takes
    a rater row before any other; and last_seen is refreshed when it is stale."""
    _check_token(token)
    lock = now is not None and conn.dialect.name != "sqlite"  # SQLite: BEGIN IMMEDIATE already holds the lock
    row = conn.execute(_RATER_LOCKED if lock else _RATER, {"token": token}).first()
    if row is None:
        abort(404, "unknown session")
    if now is not None and _stale(row, now):
        conn.execute(update(Rater).where(Rater.id == row.id).values(last_seen=now))
    return row


def _stale(row, now) -> bool:
    return (now - row.last_seen).total_seconds() > TOUCH_EVERY_S


def _idle(row, now) -> bool:
    """No answer for longer than the slot timeout (the session will be expired)."""
    return row.completed_at is None and (
        row.expired_at is not None or (now - row.last_progress).total_seconds() > current_app.config["SLOT_TIMEOUT_S"]
    )


def _current(conn, rater_pk):
    """The trial on the rater's screen: the first unanswered one in the rater's order."""
    return conn.execute(_CURRENT, {"rater_pk": rater_pk}).first()


def _rater_current(conn, token: str):
    """(rater, its current trial or None) in one read, for a read-only transaction; 404 for an unknown token."""
    _check_token(token)
    row = conn.execute(_RATER_CURRENT, {"token": token}).first()
    if row is None:
        abort(404, "unknown session")
    m = row._mapping
    rater = SimpleNamespace(**{c.key: m[c.key] for c in RATER_COLS})
    trial = SimpleNamespace(**{c.key: m["t_" + c.key] for c in TRIAL_COLS}) if m["t_id"] is not None else None
    return rater, trial


def _assign(conn, rng, rater_pk, t, wait):
    """The clip (acr) or Unit for trial `t`, or None."""
    cfg = current_app.config
    if cfg["STUDY_DESIGN"] == "acr":
        return assign_slot(conn, rng, rater_pk, t.kind, cfg["RATINGS_PER_CLIP"], wait)
    units = current_app.extensions["rating_app"]["units"]
    return assign_unit(conn, rng, rater_pk, t.kind, cfg["RATINGS_PER_CLIP"], units, wait)


def _give(conn, rng, t, assigned, now):
    """Trial `t` gets its clip (acr) or unit, is marked served, and a test slot is held in its Cover row;
    returns the trial as served."""
    shown = None
    if isinstance(assigned, str):
        key, served = assigned, {"clip_id": assigned}
    else:
        key, served = assigned.key, {"unit": assigned.key}
        # Sides (pairwise) and page order (parallel) are drawn per trial; labels follow the order shown.
        order = rng.sample(assigned.clips, len(assigned.clips))
        shown = [SimpleNamespace(label=LABELS[i], clip_id=c) for i, c in enumerate(order)]
        conn.execute(
            insert(TrialClip),
            [{"trial_pk": t.id, "position": i, "label": r.label, "clip_id": r.clip_id} for i, r in enumerate(shown)],
        )
    conn.execute(update(Trial).where(Trial.id == t.id).values(served_at=now, **served))
    hold(conn, key)  # test and catch slots alike (catch units are balanced too)
    return SimpleNamespace(**{**t._asdict(), "served_at": now, **served, "shown": shown})


def _serve(conn, rater_pk: int, now):
    """(the current trial, served; whether slots were dropped): a test or catch slot gets its clip (or is dropped
    when none is left), and the first serving time is recorded. In a write transaction that holds the rater's
    row (`_rater` with `now`), so no concurrent GET next of this session can serve the same trial."""
    dropped = False
    while True:
        t = _current(conn, rater_pk)
        if t is None or t.served_at is not None:
            return t, dropped
        if t.clip_id is not None or t.unit is not None:
            conn.execute(update(Trial).where(Trial.id == t.id, Trial.served_at.is_(None)).values(served_at=now))
            return SimpleNamespace(**{**t._asdict(), "served_at": now}), dropped
        if conn.dialect.name == "postgresql":
            # Handing out a slot is not an answer: if a crash loses this commit, the trial is served again. Not
            # waiting for the WAL flush shortens the time the claimed Cover row stays locked.
            conn.execute(text("SET LOCAL synchronous_commit TO OFF"))
        rng = random.Random(secrets.randbits(64))
        assigned = _assign(conn, rng, rater_pk, t, wait=False)
        if assigned is None:
            # Nothing free to claim: release what idle sessions hold and look again, waiting for rows other
            # servers are claiming. Under the assignment lock, so one server at a time does this.
            lock_assign(conn)
            expire_idle(conn, current_app.config["SLOT_TIMEOUT_S"], now)
            assigned = _assign(conn, rng, rater_pk, t, wait=True)
        if assigned is not None:
            return _give(conn, rng, t, assigned, now), dropped
        # No clip left for this slot: drop it; the later rating trials move up one.
        conn.execute(update(Trial).where(Trial.id == t.id).values(released=True))
        conn.execute(
            update(Trial)
            .where(Trial.rater_pk == rater_pk, Trial.phase == "rating", Trial.position > t.position)
            .values(index=Trial.index - 1)
        )
        conn.execute(update(Rater).where(Rater.id == rater_pk).values(n_rating=Rater.n_rating - 1))
        dropped = True


def _trial_clips(conn, trial_pk):
    return conn.execute(
        select(TrialClip.label, TrialClip.clip_id, TrialClip.video_at)
        .where(TrialClip.trial_pk == trial_pk)
        .order_by(TrialClip.position)
    ).all()


def _trial_reply(token, rater, trial, conn=None):
    """The trial as sent to the page; the clips of a pairwise or parallel trial are read unless `trial.shown`
    holds them (a trial just served)."""
    out = {
        "trial_id": trial.id,
        "phase": trial.phase,
        "index": trial.index,
        "of": rater.n_training if trial.phase == "training" else rater.n_rating,
    }
    design = current_app.config["STUDY_DESIGN"]
    if design == "acr":
        out.update(clip_id=trial.clip_id, video_url=url_for("api.trial_video", token=token, trial_id=trial.id))
        return jsonify(trial=out)
    clips = getattr(trial, "shown", None)
    if clips is None:
        own = read_engine().connect() if conn is None else contextlib.nullcontext(conn)
        with own as c:
            clips = _trial_clips(c, trial.id)
    shown = [
        {
            "clip_id": r.clip_id,
            "label": r.label,
            "video_url": url_for("api.clip_video", token=token, trial_id=trial.id, label=r.label),
        }
        for r in clips
    ]
    out["design"] = design
    if design in study.PAIR_DESIGNS and len(shown) == 2:
        out.update(a=shown[0], b=shown[1])
    else:
        out["clips"] = shown
    return jsonify(trial=out)


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
            rater, trial = _rater_current(conn, token)
        if trial is not None and trial.served_at is not None and not _idle(rater, now) and not _stale(rater, now):
            return _trial_reply(token, rater, trial)
    with app_engine().begin() as conn:
        rater = _rater(conn, token, now)
        if current_app.config["STUDY_SOUND"] and rater.audio_passed_at is None and rater.expired_at is None:
            return jsonify(error="the audio check comes first", audio_check=True), 403
        if rater.completed_at is None and _idle(rater, now):
            expire_idle(conn, current_app.config["SLOT_TIMEOUT_S"], now, rater.id)
            return _expired_reply()
        trial, dropped = _serve(conn, rater.id, now) if rater.completed_at is None else (None, False)
        if trial is not None:
            return _trial_reply(token, _rater(conn, token) if dropped else rater, trial, conn)
        if rater.completed_at is None:
            if _rater(conn, token).n_rating == 0:
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
    return jsonify(_completion(rater))


# A video request reads the session, the trial and (pairwise, parallel) the clip in one statement: the page
# fetches every clip of every trial, so these are the app's most frequent requests.
_TRIAL_VIDEO = (
    select(Trial.id, Trial.clip_id, Trial.video_ranges, Trial.released, Trial.served_at)
    .join(Rater, Rater.id == Trial.rater_pk)
    .where(Rater.token == bindparam("token"), Trial.id == bindparam("trial_id"))
)
_CLIP_VIDEO = (
    select(TrialClip.id, TrialClip.clip_id, TrialClip.video_ranges, Trial.released, Trial.served_at)
    .join(Trial, Trial.id == TrialClip.trial_pk)
    .join(Rater, Rater.id == Trial.rater_pk)
    .where(Rater.token == bindparam("token"), Trial.id == bindparam("trial_id"), TrialClip.label == bindparam("label"))
)


def _video_row(stmt, token, **params):
    """The row of a video request, or None; 404 "unknown session" for a token no session has."""
    _check_token(token)
    with read_engine().connect() as conn, conn.begin():
        row = conn.execute(stmt, {"token": token, **params}).first()
        if row is None:
            _rater(conn, token)  # only to tell an unknown session from an unknown video
    return row


def _send_video(table, row):
    """The video of `row` (a Trial or TrialClip), with the bytes this response carries added to the row's
    `video_ranges` (fetched.py) unless those already cover the file. The ranges are swapped in only if the row
    still holds the ones read, so two concurrent range requests never drop each other's bytes: the loser reads
    again and retries."""
    videos = current_app.extensions["rating_app"]["videos"]
    size = videos.size(row.clip_id)
    if current_app.config["VIDEO_ACCEL"] != "off":
        resp, new = videos.accel(row.clip_id)  # the proxy sends the bytes: the range it was asked for
    else:
        resp = videos.response(row.clip_id)
        new = fetched.served(resp, request.method, size or 0)
    have = row.video_ranges
    for _ in range(8):
        if new is None or fetched.covers(have, size):
            break
        merged = fetched.dump(fetched.merge(fetched.parse(have), new))
        if merged == have:
            break
        with app_engine().begin() as conn:
            done = conn.execute(
                update(table)
                .where(table.id == row.id, table.video_ranges.is_not_distinct_from(have))
                .values(video_ranges=merged, video_at=func.coalesce(table.video_at, utcnow()))
            ).rowcount
            if done:
                break
            have = conn.execute(select(table.video_ranges).where(table.id == row.id)).scalar()
    return resp


@bp.get("/sessions/<token>/trials/<int(max=2147483647):trial_id>/video.mp4")
def trial_video(token, trial_id):
    """The video of a served trial; the bytes sent are recorded (an answer before the whole file was sent is
    flagged)."""
    t = _video_row(_TRIAL_VIDEO, token, trial_id=trial_id)
    if t is None or t.clip_id is None or t.served_at is None or t.released:
        abort(404, "unknown video")
    return _send_video(Trial, t)


@bp.get("/sessions/<token>/trials/<int(max=2147483647):trial_id>/clips/<any(A,B,C,D,E,F,G,H):label>.mp4")
def clip_video(token, trial_id, label):
    """One clip of a served pairwise or parallel trial, by the label the rater sees; the bytes sent are recorded
    per clip (an answer before every clip's whole file was sent is flagged)."""
    t = _video_row(_CLIP_VIDEO, token, trial_id=trial_id, label=label)
    if t is None or t.served_at is None or t.released:
        abort(404, "unknown video")
    return _send_video(TrialClip, t)


def required_ms(clip_id: str | None, clip_ids=None) -> int:
    """The least time between serving a trial and its answer: the clip's duration (frames / fps from the
    manifest) less a small tolerance, times MIN_VIEW (1 unless lowered for tests and simulations). With
    `clip_ids` (pairwise, parallel), the time every clip of the trial needs (designs.required_ms)."""
    clips = current_app.extensions["rating_app"]["clips"]

    def duration(cid):
        clip = clips.get(cid or "")
        return clip.duration_ms if clip is not None and clip.duration_ms else 0

    if clip_ids:
        total = design_required_ms(current_app.config["STUDY_DESIGN"], [duration(c) for c in clip_ids])
    else:
        total = duration(clip_id)
    return int(current_app.config["MIN_VIEW"] * max(0, total - TOLERANCE_MS))


def _parse_answer(body, design, training, shown):
    """The answer's value for this design: None for a familiarisation trial (which must send null)."""
    name = ANSWER_FIELD[design]
    if training:
        if body.get(name) is not None:
            abort(400, f"field '{name}' must be null for a familiarisation trial")
        return None
    if name not in body:
        abort(400, f"missing field '{name}'")
    if design == "acr":
        return _int_field(body, "rating", 1, 5)
    if design in study.PAIR_DESIGNS:
        return _int_field(body, "preference", -2, 2)
    ratings = body.get("ratings")
    if not isinstance(ratings, dict):
        abort(400, "field 'ratings' must be an object {clip_id: rating 0-100} for every clip of the page")
    want = {r.clip_id for r in shown}
    if set(ratings) != want:
        abort(400, "field 'ratings' must rate every clip of the page, and only those")
    return {cid: _int_field(ratings, cid, 0, 100) for cid in sorted(want)}


# The trial being answered, with the position of the rater's first open trial: only the trial on screen can be
# answered, the first unanswered, unreleased one once served. (This trial itself counts as open here, in case a
# concurrent duplicate has just answered it.)
_ANSWERED_TRIAL = select(
    Trial.id,
    Trial.phase,
    Trial.clip_id,
    Trial.position,
    Trial.answered_at,
    Trial.released,
    Trial.served_at,
    Trial.video_at,
    Trial.video_ranges,
    Trial.kind,
    Trial.unit,
    select(func.min(_open.position))
    .where(
        _open.rater_pk == Trial.rater_pk,
        or_(_is_open(_open), _open.id == Trial.id),
    )
    .correlate(Trial)
    .scalar_subquery()
    .label("first"),
).where(Trial.id == bindparam("trial_id"), Trial.rater_pk == bindparam("rater_pk"))


# ... and, in pairwise and parallel, with one row per clip of the trial, in the order shown.
_ANSWERED_TRIAL_CLIPS = (
    _ANSWERED_TRIAL.add_columns(
        TrialClip.label.label("clip_label"),
        TrialClip.clip_id.label("clip_clip_id"),
        TrialClip.video_at.label("clip_video_at"),
        TrialClip.video_ranges.label("clip_video_ranges"),
    )
    .outerjoin(TrialClip, TrialClip.trial_pk == Trial.id)
    .order_by(TrialClip.position)
)


@bp.post("/sessions/<token>/ratings")
def post_rating(token):
    cfg = current_app.config
    design = cfg["STUDY_DESIGN"]
    body = json_body(("trial_id", ANSWER_FIELD[design], "watched_ms"), required=("trial_id",))
    trial_id = _int_field(body, "trial_id", 1, 2**31 - 1)
    watched_ms = _int_field(body, "watched_ms", 0, MAX_WATCHED_MS, nullable=True)
    now = utcnow()
    with app_engine().begin() as conn:
        rater = _rater(conn, token, now)
        rows = conn.execute(
            _ANSWERED_TRIAL if design == "acr" else _ANSWERED_TRIAL_CLIPS, {"trial_id": trial_id, "rater_pk": rater.id}
        ).all()
        if not rows:
            abort(404, "unknown trial for this session")
        trial = rows[0]
        training = trial.phase == "training"
        shown = [
            SimpleNamespace(
                label=r.clip_label, clip_id=r.clip_clip_id, video_at=r.clip_video_at, video_ranges=r.clip_video_ranges
            )
            for r in rows
            if design != "acr" and r.clip_label is not None
        ]
        rating = _parse_answer(body, design, training, shown)
        if trial.answered_at is not None:  # a repeat: acknowledged, stored once
            return _duplicate(conn, trial.id, training)
        if _idle(rater, now):
            expire_idle(conn, cfg["SLOT_TIMEOUT_S"], now, rater.id)
            return _expired_reply()
        if trial.released or trial.served_at is None or trial.position != trial.first:
            abort(409, "this trial has not been shown yet")
        need = required_ms(trial.clip_id, [r.clip_id for r in shown])
        elapsed = (now - trial.served_at).total_seconds() * 1000
        if elapsed < need:
            conn.execute(update(Rater).where(Rater.id == rater.id).values(n_early=Rater.n_early + 1))
            return jsonify(
                error="answered before the video could have played to the end",
                too_early=True,
                retry_after_ms=int(math.ceil(need - elapsed)),
            ), 425
        # Take the rater row first (as expire_idle does), then the trial: an answer and the expiry or a
        # concurrent duplicate of it can never both succeed.
        cutoff = now - dt.timedelta(seconds=cfg["SLOT_TIMEOUT_S"])
        ok = conn.execute(
            update(Rater)
            .where(Rater.id == rater.id, Rater.expired_at.is_(None), Rater.last_progress >= cutoff)
            .values(last_progress=now, last_seen=now)
        ).rowcount
        if ok != 1:
            return _expired_reply()
        claimed = conn.execute(update(Trial).where(Trial.id == trial.id, _is_open()).values(answered_at=now)).rowcount
        if claimed != 1:
            return _duplicate(conn, trial.id, training)
        if not training:
            _store(conn, design, trial, rater.id, shown, rating, watched_ms, now)
        if trial.kind != "training":
            answer(conn, trial.clip_id or trial.unit)  # the trial's db.COVER_KEY
        return jsonify(stored=True), 201


def _store(conn, design, trial, rater_pk, shown, value, watched_ms, now):
    """Insert the answer, in the transaction that claimed the trial."""
    if design == "acr":
        conn.execute(
            insert(Rating).values(
                trial_pk=trial.id,
                rater_pk=rater_pk,
                clip_id=trial.clip_id,
                rating=value,
                watched_ms=watched_ms,
                submitted_at=now,
                flags=_video_flags([trial]),
            )
        )
        return
    flags = _video_flags(shown)
    if design in study.PAIR_DESIGNS:
        conn.execute(
            insert(Preference).values(
                trial_pk=trial.id,
                rater_pk=rater_pk,
                clip_a=shown[0].clip_id,
                clip_b=shown[1].clip_id,
                preference=value,
                watched_ms=watched_ms,
                submitted_at=now,
                flags=flags,
            )
        )
    else:
        conn.execute(
            insert(PageRating),
            [
                {
                    "trial_pk": trial.id,
                    "rater_pk": rater_pk,
                    "clip_id": cid,
                    "rating": v,
                    "watched_ms": watched_ms,
                    "submitted_at": now,
                    "flags": flags,
                }
                for cid, v in value.items()
            ],
        )


def _video_flags(parts) -> str:
    """`no_video` and / or `partial_video` for the clips of an answered trial whose file was not sent in full."""
    videos = current_app.extensions["rating_app"]["videos"]
    found = {fetched.status(p.video_at, p.video_ranges, videos.size(p.clip_id)) for p in parts}
    return ";".join(sorted(f for f in found if f))


def _duplicate(conn, trial_pk, training):
    design = current_app.config["STUDY_DESIGN"]
    name = ANSWER_FIELD[design]
    stored = None
    if not training and design == "acr":
        stored = conn.execute(select(Rating.rating).where(Rating.trial_pk == trial_pk)).scalar()
    elif not training and design in study.PAIR_DESIGNS:
        stored = conn.execute(select(Preference.preference).where(Preference.trial_pk == trial_pk)).scalar()
    elif not training:
        stored = (
            dict(
                conn.execute(select(PageRating.clip_id, PageRating.rating).where(PageRating.trial_pk == trial_pk)).all()
            )
            or None
        )
    return jsonify(stored=False, duplicate=True, **{name: stored}), 200


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
    trial_id = _int_field(body, "trial_id", 1, 2**31 - 1, nullable=True)
    with app_engine().begin() as conn:
        rater = _rater(conn, token)
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
