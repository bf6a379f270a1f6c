"""Storing an answer (POST /api/sessions/TOKEN/ratings): checked, refused when early, stored once.

Every answer is committed before it is acknowledged, so an acknowledged answer survives a crash of the server.
Only the trial on screen can be answered, and not before its clips could have played to the end (the viewing
rule: MIN_VIEW x (the design's playing time - TOLERANCE_MS)). The study's design parses and stores the value
(designs/); this module holds what every design shares.
"""

from __future__ import annotations

import datetime as dt
import math
from types import SimpleNamespace

from flask import abort, current_app, jsonify
from sqlalchemy import bindparam, func, or_, select, update

from ..designs import of_app
from ..guard.bodies import int_field, json_body
from ..media import fetched
from ..pairing.assign import answer, expire_idle
from ..store.db import Rater, Trial, TrialClip, app_engine, utcnow
from ..store.reasons import parse_answer as parse_reasons
from ..store.rounds import know_clips
from . import sessions
from .sessions import OPEN, is_open

MAX_WATCHED_MS = 24 * 3600 * 1000
TOLERANCE_MS = 250  # clock and decoding slack on the minimum viewing time

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
    select(func.min(OPEN.position))
    .where(
        OPEN.rater_pk == Trial.rater_pk,
        or_(is_open(OPEN), OPEN.id == Trial.id),
    )
    .correlate(Trial)
    .scalar_subquery()
    .label("first"),
).where(Trial.id == bindparam("trial_id"), Trial.rater_pk == bindparam("rater_pk"))


# An answer's two writes, built once: the rater's progress, only while the session is live, and the trial, only
# while it is open. (Typed as their columns, so a time is written as the columns write it.)
_NOW = bindparam("now", type_=Rater.last_progress.type)
_PROGRESS = (
    update(Rater)
    .where(Rater.id == bindparam("rater_pk"), Rater.expired_at.is_(None), Rater.last_progress >= bindparam("cutoff"))
    .values(last_progress=_NOW, last_seen=_NOW)
)
_ANSWERED = update(Trial).where(Trial.id == bindparam("trial_pk"), is_open()).values(answered_at=_NOW)

# ... and, for a design whose trial shows several clips, with one row per clip of the trial, in the order shown.
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


def required_ms(clip_ids, conn=None) -> int:
    """The least time between serving a trial and its answer: the design's playing time of the trial's clips
    (durations, frames / fps, from the manifest) less a small tolerance, times MIN_VIEW (1 unless lowered for
    tests and simulations)."""
    clips = know_clips(conn, clip_ids) if conn is not None else current_app.extensions["rating_app"]["clips"]

    def duration(cid):
        clip = clips.get(cid or "")
        return clip.duration_ms if clip is not None and clip.duration_ms else 0

    total = of_app().required_ms([duration(c) for c in clip_ids])
    return int(current_app.config["MIN_VIEW"] * max(0, total - TOLERANCE_MS))


def _parse(design, body, training, shown):
    """The answer's value: None for a familiarisation trial (which must send null)."""
    name = design.answer_field
    if training:
        if body.get(name) is not None:
            abort(400, f"field '{name}' must be null for a familiarisation trial")
        if design.answer_extra:
            parse_reasons(body, training=True)  # none on a familiarisation trial
        return None
    if name not in body:
        abort(400, f"missing field '{name}'")
    return design.parse_answer(body, shown)


def _answered_trial(conn, design, trial_id, rater_pk):
    """(the trial being answered, its clips as shown); 404 for a trial of another session."""
    stmt = _ANSWERED_TRIAL_CLIPS if design.several_clips else _ANSWERED_TRIAL
    rows = conn.execute(stmt, {"trial_id": trial_id, "rater_pk": rater_pk}).all()
    if not rows:
        abort(404, "unknown trial for this session")
    shown = [
        SimpleNamespace(
            label=r.clip_label, clip_id=r.clip_clip_id, video_at=r.clip_video_at, video_ranges=r.clip_video_ranges
        )
        for r in rows
        if design.several_clips and r.clip_label is not None
    ]
    return rows[0], shown


def _too_early(conn, rater_pk, trial, shown, now):
    """The 425 reply when the trial's clips cannot have played to the end yet, else None."""
    need = required_ms([r.clip_id for r in shown] or [trial.clip_id], conn)
    elapsed = (now - trial.served_at).total_seconds() * 1000
    if elapsed >= need:
        return None
    conn.execute(update(Rater).where(Rater.id == rater_pk).values(n_early=Rater.n_early + 1))
    return jsonify(
        error="answered before the video could have played to the end",
        too_early=True,
        retry_after_ms=int(math.ceil(need - elapsed)),
    ), 425


def accept(token):
    """The reply to POST /api/sessions/TOKEN/ratings."""
    cfg, design = current_app.config, of_app()
    body = json_body(("trial_id", design.answer_field, "watched_ms", *design.answer_extra), required=("trial_id",))
    trial_id = int_field(body, "trial_id", 1, 2**31 - 1)
    watched_ms = int_field(body, "watched_ms", 0, MAX_WATCHED_MS, nullable=True)
    now = utcnow()
    with app_engine().begin() as conn:
        rater = sessions.lookup(conn, token, now)
        trial, shown = _answered_trial(conn, design, trial_id, rater.id)
        training = trial.phase == "training"
        value = _parse(design, body, training, shown)
        if trial.answered_at is not None:  # a repeat: acknowledged, stored once
            return _duplicate(conn, trial.id, training)
        if sessions.idle(rater, now):
            expire_idle(conn, cfg["SLOT_TIMEOUT_S"], now, rater.id)
            return sessions.expired_reply()
        if trial.released or trial.served_at is None or trial.position != trial.first:
            abort(409, "this trial has not been shown yet")
        early = _too_early(conn, rater.id, trial, shown, now)
        if early is not None:
            return early
        # Take the rater row first (as expire_idle does), then the trial: an answer and the expiry or a
        # concurrent duplicate of it can never both succeed.
        cutoff = now - dt.timedelta(seconds=cfg["SLOT_TIMEOUT_S"])
        ok = conn.execute(_PROGRESS, {"rater_pk": rater.id, "cutoff": cutoff, "now": now}).rowcount
        if ok != 1:
            return sessions.expired_reply()
        claimed = conn.execute(_ANSWERED, {"trial_pk": trial.id, "now": now}).rowcount
        if claimed != 1:
            return _duplicate(conn, trial.id, training)
        if not training:
            # The clips whose video was fetched: the trial's clip rows, or the trial itself when it shows one.
            flags = _video_flags(shown or [trial])
            design.store(conn, trial, rater.id, shown, value, watched_ms, now, flags)
        if trial.kind != "training":
            answer(conn, trial.clip_id or trial.unit)  # the trial's db.COVER_KEY
        return jsonify(stored=True), 201


def _video_flags(parts) -> str:
    """`no_video` and / or `partial_video` for the clips of an answered trial whose file was not sent in full."""
    videos = current_app.extensions["rating_app"]["videos"]
    found = {fetched.status(p.video_at, p.video_ranges, videos.size(p.clip_id)) for p in parts}
    return ";".join(sorted(f for f in found if f))


def _duplicate(conn, trial_pk, training):
    design = of_app()
    stored = None if training else design.stored_answer(conn, trial_pk)
    return jsonify(stored=False, duplicate=True, **{design.answer_field: stored}), 200
