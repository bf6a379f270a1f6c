"""The audio check of a study with sound (ITU-T P.808's approach for crowdsourced listening tests): before the
examples, a rater hears a few spoken digits and types them. Two wrong answers end the session, kindly: the study
needs sound the rater can hear.

The samples and their answers come from `audio_check.csv` beside the manifest (generation.make_stimuli writes it
for a study with [audio]); only the server knows the answers. Each try plays a sample drawn at random for that
session, stored with it, so every worker of a study agrees on it. GET next refuses (403, `audio_check: true`)
until the check is passed (CONTRACTS §5).
"""

from __future__ import annotations

import random
import re
import secrets
from pathlib import Path

from flask import Blueprint, abort, current_app, jsonify, send_file
from sqlalchemy import update

from moglow_eval.core import user_files

from ..guard.bodies import check_token, json_body
from ..store.db import Rater, app_engine, utcnow
from ..store.manifest import AppError

bp = Blueprint("audio_check", __name__, url_prefix="/api")
MAX_TRIES = 2
FAILED = (
    "Thank you for trying. This study needs sound that you can hear clearly, and the digits did not match twice, "
    "so it cannot go on here. Nothing is wrong with you or your answers: it may be the volume, the speakers or a "
    "noisy room. You may close this page."
)


def load_audio_check(manifest) -> dict[str, tuple[Path, str]]:
    """{sample name: (its WAV, the digits)} from audio_check.csv beside the manifest; AppError, one line, when it
    is missing or wrong."""
    base = Path(manifest).resolve().parent
    path = base / "audio_check.csv"
    if not path.is_file():
        raise AppError(f"{path}: missing; a study with sound needs its audio check (generation.make_stimuli writes it)")
    out = {}
    with user_files.csv_rows(path, 1 << 20, AppError, "audio check file") as (_, rows):
        for line, row in rows:
            wav = (base / row.get("file", "")).resolve()
            answer = row.get("answer", "")
            if not wav.is_relative_to(base) or not wav.is_file() or not answer.isdigit():
                raise AppError(f"{path}:{line}: needs an existing file inside the stimulus folder and digits")
            out[wav.stem] = (wav, answer)
    if not out:
        raise AppError(f"{path}: no samples")
    return out


def _samples():
    return current_app.extensions["rating_app"]["audio_check"]


def _session(conn, token):
    check_token(token)
    row = conn.execute(
        Rater.__table__.select().where(Rater.token == token).with_for_update()
        if conn.dialect.name != "sqlite"
        else Rater.__table__.select().where(Rater.token == token)
    ).first()
    if row is None:
        abort(404, "unknown session")
    if not current_app.config.get("STUDY_SOUND"):
        abort(404, "this study has no sound and no audio check")
    return row


def _draw(exclude=None):
    names = sorted(n for n in _samples() if n != exclude) or sorted(_samples())
    return random.Random(secrets.randbits(64)).choice(names)


@bp.get("/sessions/<token>/audio-check.wav")
def sample(token):
    with app_engine().begin() as conn:
        rater = _session(conn, token)
        if rater.audio_passed_at is not None:
            abort(409, "the audio check is already passed")
        if (rater.audio_tries or 0) >= MAX_TRIES or rater.expired_at is not None:
            abort(410, FAILED)
        name = rater.audio_sample
        if name not in _samples():
            name = _draw()
            conn.execute(update(Rater).where(Rater.id == rater.id).values(audio_sample=name))
    resp = send_file(_samples()[name][0], mimetype="audio/wav", conditional=False, etag=False, last_modified=None)
    resp.headers["Cache-Control"] = "no-store"
    return resp


@bp.post("/sessions/<token>/audio-check")
def check(token):
    body = json_body(("answer",), required=("answer",))
    if not isinstance(body["answer"], str) or len(body["answer"]) > 64:
        abort(400, "field 'answer' must be the digits heard, as text")
    typed = re.sub(r"\D", "", body["answer"])
    with app_engine().begin() as conn:
        rater = _session(conn, token)
        if rater.audio_passed_at is not None:
            return jsonify(passed=True)
        tries = rater.audio_tries or 0
        if tries >= MAX_TRIES or rater.expired_at is not None:
            return jsonify(passed=False, final=True, error=FAILED), 410
        if rater.audio_sample not in _samples():
            abort(409, "play the sample first")
        if typed == _samples()[rater.audio_sample][1]:
            now = utcnow()  # passing counts as progress: the session's idle clock starts again
            conn.execute(update(Rater).where(Rater.id == rater.id).values(audio_passed_at=now, last_progress=now))
            return jsonify(passed=True)
        tries += 1
        final = tries >= MAX_TRIES
        values = dict(audio_tries=tries, audio_sample=None if final else _draw(rater.audio_sample))
        if final:
            values["expired_at"] = utcnow()
        conn.execute(update(Rater).where(Rater.id == rater.id).values(**values))
    if final:
        return jsonify(passed=False, final=True, error=FAILED), 200
    return jsonify(passed=False, final=False, tries_left=MAX_TRIES - tries)
