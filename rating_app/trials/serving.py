"""Serving a trial (GET /api/sessions/TOKEN/next): a slot gets its clip or unit when first served, and the trial
is sent as the page shows it.

The server, not the page, decides whether a clip was watched: it records when it first served each trial (and,
trial_videos.py, which bytes of its videos it sent). Every design takes the same path: its `assign` picks what a
slot shows, its `payload` is the design's part of the trial (designs/).
"""

from __future__ import annotations

import contextlib
import random
import secrets
from types import SimpleNamespace

from flask import current_app, jsonify, url_for
from sqlalchemy import insert, select, text, update

from ..designs import LABELS, of_app
from ..pairing import active
from ..pairing.assign import expire_idle, hold, lock_assign
from ..store.db import Rater, Trial, TrialClip, read_engine
from ..store.rounds import current_units
from ..store.samples import draw
from . import sessions


def _assign(conn, rng, rater_pk, t, wait):
    """The clip id or Unit for trial `t`, or None."""
    # As of the study's latest round and withdrawals (store/rounds.py); its revision was read with the trial ("0":
    # none yet).
    units = current_units(conn, t.study_revision or "0")
    ext, cfg = current_app.extensions["rating_app"], current_app.config
    # pairing/active.py: chooses among what the balanced rule allows
    if t.kind == "test" and cfg["PAIRING"] == "active":
        unit = active.for_units(ext, units).pick(conn, rng, rater_pk, units, cfg["RATINGS_PER_CLIP"], wait)
        if unit is not None:
            return unit
    return of_app().assign(conn, rng, rater_pk, t.kind, cfg["RATINGS_PER_CLIP"], units, wait)


def _give(conn, rng, rater_pk, t, assigned, now):
    """Trial `t` gets its clip or unit, is marked served, and a test slot is held in its Cover row; returns the
    trial as served."""
    shown = None
    ext = current_app.extensions["rating_app"]
    seed, samples = ext["sample_seed"], ext["samples"]
    if isinstance(assigned, str):
        key, served = assigned, {"clip_id": assigned}
        if assigned in samples:  # a stochastic system's clip: the rater's own draw of its samples (store/samples.py)
            served["sample_clip"] = draw(seed, rater_pk, assigned, assigned, samples)
    else:
        key, served = assigned.key, {"unit": assigned.key}
        # Sides and page order are drawn per trial; labels follow the order shown. A stochastic system's clip is
        # the rater's own draw of its samples.
        clips = [draw(seed, rater_pk, key, c, samples) for c in assigned.clips]
        order = rng.sample(clips, len(clips))
        shown = [SimpleNamespace(label=LABELS[i], clip_id=c) for i, c in enumerate(order)]
        conn.execute(
            insert(TrialClip),
            [{"trial_pk": t.id, "position": i, "label": r.label, "clip_id": r.clip_id} for i, r in enumerate(shown)],
        )
    conn.execute(update(Trial).where(Trial.id == t.id).values(served_at=now, **served))
    hold(conn, key)  # test and catch slots alike (catch units are balanced too)
    return SimpleNamespace(**{**t._asdict(), "served_at": now, **served, "shown": shown})


def serve(conn, rater_pk: int, now):
    """(the current trial, served; whether slots were dropped): a test or catch slot gets its clip (or is dropped
    when none is left), and the first serving time is recorded. In a write transaction that holds the rater's
    row (`sessions.lookup` with `now`), so no concurrent GET next of this session can serve the same trial."""
    dropped = False
    while True:
        t = sessions.current(conn, rater_pk)
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
            return _give(conn, rng, rater_pk, t, assigned, now), dropped
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


def trial_reply(token, rater, trial, conn=None):
    """The trial as sent to the page. A design that shows several clips per trial has them read unless
    `trial.shown` holds them (a trial just served); the others show the trial's own clip."""
    out = {
        "trial_id": trial.id,
        "phase": trial.phase,
        "index": trial.index,
        "of": rater.n_training if trial.phase == "training" else rater.n_rating,
    }
    design = of_app()
    if not design.several_clips:
        video = url_for("api.trial_video", token=token, trial_id=trial.id)
        clip = getattr(trial, "sample_clip", None) or trial.clip_id  # the sample it shows (store/samples.py)
        out.update(design.payload([{"clip_id": clip, "video_url": video}]))
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
    out.update(design.payload(shown))
    return jsonify(trial=out)
