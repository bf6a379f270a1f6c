"""The videos of a served trial, sent by the URLs the page plays: the bytes each response carries are recorded
(media/fetched.py), so an answer before a clip's whole file was sent is flagged.

A video request reads the session, the trial and (a trial of several clips) the clip in one statement: the page
fetches every clip of every trial, so these are the app's most frequent requests.
"""

from __future__ import annotations

import functools

from flask import current_app, request
from sqlalchemy import bindparam, func, select, update

from ..guard.bodies import check_token
from ..media import fetched
from ..store.db import Rater, Trial, TrialClip, app_engine, read_engine, utcnow
from ..store.rounds import know_clips
from . import sessions

TRIAL_VIDEO = (  # the clip, or the sample of it drawn for this rater (store/samples.py)
    select(
        Trial.id,
        func.coalesce(Trial.sample_clip, Trial.clip_id).label("clip_id"),
        Trial.video_ranges,
        Trial.released,
        Trial.served_at,
    )
    .join(Rater, Rater.id == Trial.rater_pk)
    .where(Rater.token == bindparam("token"), Trial.id == bindparam("trial_id"))
)
CLIP_VIDEO = (
    select(TrialClip.id, TrialClip.clip_id, TrialClip.video_ranges, Trial.released, Trial.served_at)
    .join(Trial, Trial.id == TrialClip.trial_pk)
    .join(Rater, Rater.id == Trial.rater_pk)
    .where(Rater.token == bindparam("token"), Trial.id == bindparam("trial_id"), TrialClip.label == bindparam("label"))
)


def video_row(stmt, token, **params):
    """The row of a video request, or None; 404 "unknown session" for a token no session has."""
    check_token(token)
    with read_engine().connect() as conn, conn.begin():
        row = conn.execute(stmt, {"token": token, **params}).first()
        if row is None:
            sessions.lookup(conn, token)  # only to tell an unknown session from an unknown video
    return row


def send_video(table, row):
    """The video of `row` (a Trial or TrialClip), with the bytes this response carries added to the row's
    `video_ranges` (media/fetched.py) unless those already cover the file. The ranges are swapped in only if the row
    still holds the ones read, so two concurrent range requests never drop each other's bytes: the loser reads
    again and retries."""
    videos = current_app.extensions["rating_app"]["videos"]
    if row.clip_id not in videos.paths:  # a clip of a round this worker has not loaded yet (store/rounds.py)
        with read_engine().connect() as conn:
            know_clips(conn, [row.clip_id])
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
                _ranges_write(table), {"row_pk": row.id, "have": have, "merged": merged, "now": utcnow()}
            )
            if done.rowcount:
                break
            have = conn.execute(select(table.video_ranges).where(table.id == row.id)).scalar()
    return resp


@functools.cache
def _ranges_write(table):
    """send_video's write for rows of `table`, built once (a video request is the app's most frequent, and building
    a statement costs SQLAlchemy more CPU than running it): the new ranges, only over the ones read; the first
    fetch's time, once. Its parameters typed as their columns, so a time is written as the column writes it."""
    ranges, at = table.video_ranges, table.video_at
    return (
        update(table)
        .where(table.id == bindparam("row_pk"), ranges.is_not_distinct_from(bindparam("have", type_=ranges.type)))
        .values(
            video_ranges=bindparam("merged", type_=ranges.type),
            video_at=func.coalesce(at, bindparam("now", type_=at.type)),
        )
    )
