"""The rater's page (one HTML page driven by static/study.js through the JSON API) and the videos by clip id
(for the admin and old links; the page plays each trial's own URL, which records the fetch)."""

from __future__ import annotations

import re

from flask import Blueprint, abort, current_app, jsonify, render_template, request
from sqlalchemy.orm import Session

from moglow_eval.core import colours, study

from ..guard.bodies import EXTERNAL
from ..operations import health
from ..store.db import app_engine
from ..store.rounds import refresh

bp = Blueprint("pages", __name__)

VIDEO_NAME = re.compile(rf"({study.CLIP_ID.pattern})\.mp4")  # fullmatch
# Query parameters Prolific appends to a study URL ({{%PROLIFIC_PID%}} etc.), plus generic fallbacks.
ID_PARAMS = {
    "external_id": ("PROLIFIC_PID", "participant", "worker_id", "pid"),
    "study_id": ("STUDY_ID", "study"),
    "session_id": ("SESSION_ID", "session"),
}


@bp.get("/")
def index():
    ids = {}
    for key, names in ID_PARAMS.items():
        for n in names:
            v = request.args.get(n)
            if v and EXTERNAL.fullmatch(v):
                ids[key] = v
                break
    cfg = current_app.config
    with Session(app_engine().execution_options(read_only=True)) as s:  # no write lock on SQLite
        ext = refresh(s.connection())
        target = cfg["RATINGS_PER_CLIP"]
        full = ext["design"].is_full(s, target, ext["units"]) or not ext["clips"]
    design = ext["design"]
    return render_template(
        "study.html",
        ids=ids,
        full=full,
        design=design.name,
        page_template=design.page_template,  # the design's parts of the page
        page_kind=design.page,
        answer_field=design.answer_field,
        question=cfg["STUDY_QUESTION"],
        sound=cfg["STUDY_SOUND"],
        interlocutor=_named_colour(cfg.get("INTERLOCUTOR_COLOUR")),  # two people: the one drawn the same in both
        video_size=cfg.get("VIDEO_SIZE"),  # (width, height) of every video, or None: laid out square until loaded
        figure=cfg.get("FIGURE", "stick figure"),  # the page's word for what the videos draw
        reasons=cfg["VOTE_REASONS"],  # the boxes shown with a vote, and the free text's limit (store/reasons.py)
        reason_text=cfg["REASON_TEXT"],
    )


def _named_colour(hex_colour):
    """{"hex", "name"} of the interlocutor's colour for the page's words and swatch; None where the study gave none."""
    if not hex_colour:
        return None
    return {"hex": hex_colour, "name": colours.colour_name(colours.from_hex(hex_colour))}


@bp.get("/videos/<name>")
def video(name):
    # Only files named by clip id in the manifest: no listing, no path from the client ever reaches the disk.
    m = VIDEO_NAME.fullmatch(name)
    clip = current_app.extensions["rating_app"]["clips"].get(m.group(1)) if m else None
    if clip is None:
        abort(404, "unknown video")
    videos = current_app.extensions["rating_app"]["videos"]
    if current_app.config["VIDEO_ACCEL"] != "off":
        return videos.accel(clip.clip_id)[0]  # the proxy sends the bytes
    return videos.response(clip.clip_id)


@bp.get("/healthz")
def healthz():
    cfg = current_app.config
    return jsonify(ok=True, design=cfg["STUDY_DESIGN"], min_view=cfg["MIN_VIEW"], warnings=health.of_app().list())
