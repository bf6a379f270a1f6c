"""The crowd rating web app (Flask): sessions, familiarisation, rating trials, admin and export.

    app = create_app(manifest="stimuli/manifest.csv", db_url="postgresql://...", ratings_per_clip=20)

Arguments left as None are read from the environment (ADMIN_TOKEN, DATABASE_URL, RATING_MANIFEST,
RATINGS_PER_CLIP, CLIPS_PER_RATER, SLOT_TIMEOUT, COMPLETION_CODE, COMPLETION_URL, SECRET_KEY), which is how
`rating_app.wsgi:app` is configured under gunicorn. Also read: COOKIE_SECURE=1 (admin cookie over HTTPS
only) and DB_POOL_SIZE (connections per worker, default 10 + 10 overflow).
"""
from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

from flask import Flask, jsonify, request
from sqlalchemy.exc import OperationalError
from werkzeug.exceptions import HTTPException

from .manifest import AppError, load_manifest

__all__ = ["create_app", "AppError"]


def _env(name, kind=str):
    value = os.environ.get(name)
    if value is None or value == "":
        return None
    try:
        return kind(value)
    except ValueError:
        raise AppError(f"environment variable {name}={value!r} is not a valid {kind.__name__}") from None


def create_app(manifest=None, db_url=None, ratings_per_clip=None, clips_per_rater=None, admin_token=None,
               slot_timeout_s=None, completion_code=None, completion_url=None, secret_key=None,
               check_files=True) -> Flask:
    from . import db as dbm
    from .admin import bp as admin_bp
    from .api import bp as api_bp
    from .pages import bp as pages_bp

    manifest = manifest or _env("RATING_MANIFEST")
    ratings_per_clip = ratings_per_clip if ratings_per_clip is not None else (_env("RATINGS_PER_CLIP", int) or 20)
    clips_per_rater = clips_per_rater if clips_per_rater is not None else _env("CLIPS_PER_RATER", int)
    slot_timeout_s = slot_timeout_s if slot_timeout_s is not None else (_env("SLOT_TIMEOUT", float) or 3600.0)
    admin_token = admin_token if admin_token is not None else _env("ADMIN_TOKEN")
    completion_code = completion_code if completion_code is not None else _env("COMPLETION_CODE")
    completion_url = completion_url if completion_url is not None else _env("COMPLETION_URL")
    if ratings_per_clip < 1:
        raise AppError(f"ratings per clip must be >= 1, got {ratings_per_clip}")
    if clips_per_rater == 0:
        clips_per_rater = None                  # 0 means every clip still needing ratings
    if clips_per_rater is not None and clips_per_rater < 1:
        raise AppError(f"clips per rater must be >= 1, got {clips_per_rater}")
    if completion_url and not completion_url.startswith(("https://", "http://")):
        raise AppError(f"completion URL must start with https:// or http://, got {completion_url!r}")

    app = Flask(__name__)
    # Workers must share the cookie key: derive it from the admin token unless one is given.
    secret_key = secret_key or _env("SECRET_KEY") or hashlib.sha256(
        b"rating-app:" + (admin_token or os.urandom(32).hex()).encode()).hexdigest()
    app.config.update(
        SECRET_KEY=secret_key,
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Strict",
        SESSION_COOKIE_SECURE=os.environ.get("COOKIE_SECURE", "") == "1",     # set behind HTTPS
        MAX_CONTENT_LENGTH=16 * 1024,
        RATINGS_PER_CLIP=int(ratings_per_clip),
        CLIPS_PER_RATER=clips_per_rater,
        SLOT_TIMEOUT_S=float(slot_timeout_s),
        ADMIN_TOKEN=admin_token,
        COMPLETION_CODE=completion_code,
        COMPLETION_URL=completion_url,
    )
    clips = load_manifest(manifest, check_files=check_files) if manifest else []
    engine = dbm.make_engine(db_url)
    dbm.init_db(engine, clips)
    # Close connections opened during set-up so that forked workers (gunicorn --preload) start clean.
    engine.dispose()
    metrics = {}
    if manifest and (Path(manifest).resolve().parent / "metrics.csv").is_file():
        from .manifest import load_metrics
        try:
            metrics = load_metrics(Path(manifest).resolve().parent / "metrics.csv")
        except (AppError, OSError, ValueError) as e:
            logging.getLogger(__name__).warning("metrics.csv ignored: %s", e)
    app.extensions["rating_app"] = {
        "engine": engine,
        "clips": {c.clip_id: c for c in clips},
        "metrics": metrics,
        "manifest": str(manifest) if manifest else None,
    }
    if not app.logger.handlers or app.logger.level == logging.NOTSET:
        app.logger.setLevel(logging.INFO)

    app.register_blueprint(pages_bp)
    app.register_blueprint(api_bp)
    app.register_blueprint(admin_bp)

    @app.errorhandler(HTTPException)
    def _http_error(e: HTTPException):
        resp = jsonify(error=e.description or e.name)
        resp.status_code = e.code or 500
        if e.code == 401:
            resp.headers["WWW-Authenticate"] = 'Bearer realm="admin"'
        return resp

    @app.errorhandler(OperationalError)
    def _db_down(e):
        app.logger.error("database error on %s %s: %s", request.method, request.path, str(e).splitlines()[0])
        return jsonify(error="database unavailable, please retry"), 503

    @app.errorhandler(Exception)
    def _internal(e):
        # Never a stack trace to the client; the full one goes to the server log.
        app.logger.exception("unhandled error on %s %s", request.method, request.path)
        return jsonify(error="internal server error"), 500

    @app.after_request
    def _headers(resp):
        resp.headers.setdefault("X-Content-Type-Options", "nosniff")
        resp.headers.setdefault("X-Frame-Options", "DENY")
        resp.headers.setdefault("Referrer-Policy", "same-origin")
        resp.headers.setdefault(
            "Content-Security-Policy",
            "default-src 'self'; media-src 'self'; img-src 'self' data:; style-src 'self'; "
            "script-src 'self'; frame-ancestors 'none'; form-action 'self'")
        if request.path.startswith(("/api/", "/admin")):
            resp.headers.setdefault("Cache-Control", "no-store")
        return resp

    return app
