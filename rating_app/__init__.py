"""The crowd rating web app (Flask): sessions, familiarisation, rating trials, admin and export.

    app = create_app(manifest="stimuli/manifest.csv", db_url="postgresql://...", ratings_per_clip=20)

Arguments left as None are read from the environment (ADMIN_TOKEN, DATABASE_URL, RATING_MANIFEST, STUDY_DESIGN,
STUDY_QUESTION, RATINGS_PER_CLIP, CLIPS_PER_RATER, SLOT_TIMEOUT, MIN_VIEW, SESSIONS_PER_CLIENT, COMPLETION_CODE,
COMPLETION_URL, SECRET_KEY), which is how `rating_app.wsgi:app` is configured under gunicorn. Also read:
COOKIE_SECURE=1 (admin cookie over HTTPS only), PROXY_COUNT (trusted reverse proxies in front, whose X-Forwarded-For
names the client; default 0) and DB_POOL_SIZE (connections per worker, default 10 + 10 overflow). Every setting is
checked here, so a bad one stops the start with one line instead of failing on each request.
"""

from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path

from flask import Flask, jsonify, request
from sqlalchemy.engine import make_url
from sqlalchemy.exc import OperationalError, SQLAlchemyError
from werkzeug.exceptions import HTTPException

from core.cli import number

from .manifest import AppError, load_manifest

__all__ = ["create_app", "AppError", "SETTINGS"]

# name: (kind, default, lo, hi, lo_open); the CLI flags use the same bounds.
SETTINGS = {
    "RATINGS_PER_CLIP": (int, 20, 1, 1_000_000, False),
    "CLIPS_PER_RATER": (int, 0, 0, 1_000_000, False),  # 0: every clip still needing ratings
    "SLOT_TIMEOUT": (float, 3600.0, 0.0, 1e7, True),  # seconds without an answer before a session expires
    "MIN_VIEW": (float, 1.0, 0.0, 1.0, False),  # share of each clip that must have played
    "SESSIONS_PER_CLIENT": (int, 10, 0, 1_000_000, False),  # new sessions per client address per hour; 0: no limit
    "PROXY_COUNT": (int, 0, 0, 10, False),
}


def setting(name: str, given=None):
    """`given`, else the environment variable `name`, else the default; checked against SETTINGS."""
    kind, default, lo, hi, lo_open = SETTINGS[name]
    raw = given if given is not None else os.environ.get(name) or None
    if raw is None:
        return default
    try:
        return number(kind, lo, hi, lo_open)(str(raw))
    except argparse.ArgumentTypeError as e:
        where = name if given is None else name.lower()
        raise AppError(f"{where}: {e}") from None


def _env(name):
    return os.environ.get(name) or None


def create_app(
    manifest=None,
    db_url=None,
    ratings_per_clip=None,
    clips_per_rater=None,
    admin_token=None,
    slot_timeout_s=None,
    completion_code=None,
    completion_url=None,
    secret_key=None,
    check_files=True,
    min_view=None,
    sessions_per_client=None,
    design=None,
    question=None,
) -> Flask:
    """`design`: acr (default), pairwise or parallel (designs.py); fixed for the life of the database.
    `ratings_per_clip` and `clips_per_rater` count the design's units: clips (acr), pairs of conditions of an
    item (pairwise) or pages (parallel)."""
    from .admin import bp as admin_bp
    from .api import bp as api_bp
    from .db import make_read_engine
    from .designs import build_units
    from .pages import bp as pages_bp
    from .videos import VideoStore

    manifest = manifest or _env("RATING_MANIFEST")
    if not manifest:
        raise AppError("no stimulus manifest: set RATING_MANIFEST (or --manifest) to stimuli/manifest.csv")
    config = _config(
        ratings_per_clip=ratings_per_clip,
        clips_per_rater=clips_per_rater,
        slot_timeout_s=slot_timeout_s,
        min_view=min_view,
        sessions_per_client=sessions_per_client,
        design=design,
        question=question,
        admin_token=admin_token,
        completion_code=completion_code,
        completion_url=completion_url,
    )
    proxies = setting("PROXY_COUNT")
    app = Flask(__name__)
    if proxies:
        from werkzeug.middleware.proxy_fix import ProxyFix

        app.wsgi_app = ProxyFix(app.wsgi_app, x_for=proxies, x_proto=proxies, x_host=proxies)
    app.config.update(
        SECRET_KEY=secret_key or _env("SECRET_KEY") or _derived_secret(config["ADMIN_TOKEN"]),
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Strict",
        SESSION_COOKIE_SECURE=os.environ.get("COOKIE_SECURE", "") == "1",  # set behind HTTPS
        MAX_CONTENT_LENGTH=16 * 1024,
        **config,
    )
    clips = load_manifest(manifest, check_files=check_files)
    units = build_units(config["STUDY_DESIGN"], clips)
    engine = _open_database(db_url, clips, config["STUDY_DESIGN"], _cover_keys(config["STUDY_DESIGN"], clips, units))
    app.extensions["rating_app"] = {
        "engine": engine,
        "read_engine": make_read_engine(engine),
        "clips": {c.clip_id: c for c in clips},
        "videos": VideoStore(clips, Path(manifest).resolve().parent, preload=check_files),
        "units": units,
    }
    app.register_blueprint(pages_bp)
    app.register_blueprint(api_bp)
    app.register_blueprint(admin_bp)
    _handle_errors(app)
    app.after_request(_headers)
    return app


def _config(
    ratings_per_clip,
    clips_per_rater,
    slot_timeout_s,
    min_view,
    sessions_per_client,
    design,
    question,
    admin_token,
    completion_code,
    completion_url,
) -> dict:
    """The study's settings as app.config entries: each given value, else its environment variable, checked."""
    from .designs import QUESTIONS, check_design

    numbers = {  # checked first, in the order the settings are documented
        "RATINGS_PER_CLIP": setting("RATINGS_PER_CLIP", ratings_per_clip),
        "CLIPS_PER_RATER": setting("CLIPS_PER_RATER", clips_per_rater) or None,  # 0 / None: all clips still short
        "SLOT_TIMEOUT_S": float(setting("SLOT_TIMEOUT", slot_timeout_s)),
        "MIN_VIEW": float(setting("MIN_VIEW", min_view)),
        "SESSIONS_PER_CLIENT": setting("SESSIONS_PER_CLIENT", sessions_per_client),
    }
    design = check_design(design if design is not None else _env("STUDY_DESIGN"))
    question = (question if question is not None else _env("STUDY_QUESTION")) or QUESTIONS[design]
    if len(question) > 200 or not question.isprintable():
        raise AppError("question: at most 200 printable characters on one line")
    completion_url = completion_url if completion_url is not None else _env("COMPLETION_URL")
    if completion_url and not completion_url.startswith(("https://", "http://")):
        raise AppError(f"completion URL must start with https:// or http://, got {completion_url!r}")
    return {
        **numbers,
        "ADMIN_TOKEN": admin_token if admin_token is not None else _env("ADMIN_TOKEN"),
        "COMPLETION_CODE": completion_code if completion_code is not None else _env("COMPLETION_CODE"),
        "COMPLETION_URL": completion_url,
        "STUDY_DESIGN": design,
        "STUDY_QUESTION": question,
    }


def _derived_secret(admin_token):
    # Workers must share the cookie key: derive it from the admin token unless one is given.
    return hashlib.sha256(b"rating-app:" + (admin_token or os.urandom(32).hex()).encode()).hexdigest()


def _cover_keys(design, clips, units):
    """What assignment balances: the test clips (acr) or the test units (pairwise, parallel)."""
    if design == "acr":
        return [c.clip_id for c in clips if c.role == "test"]
    return [k for k, u in units.items() if u.role == "test"]


def _open_database(db_url, clips, design, cover_keys):
    """The engine, with the schema created and the manifest's clips and the design stored; AppError, one line,
    when the database cannot be opened."""
    from . import db as dbm

    engine = dbm.make_engine(db_url)
    try:
        dbm.init_db(engine, clips, design, cover_keys)
    except SQLAlchemyError as e:
        where = make_url(str(engine.url)).render_as_string(hide_password=True)
        first = str(getattr(e, "orig", None) or e).strip().splitlines()
        raise AppError(f"cannot open the database {where}: {first[0] if first else e.__class__.__name__}") from None
    finally:
        # Close connections opened during set-up so that forked workers (gunicorn --preload) start clean.
        engine.dispose()
    return engine


def _handle_errors(app: Flask) -> None:
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


def _headers(resp):
    resp.headers.setdefault("X-Content-Type-Options", "nosniff")
    resp.headers.setdefault("X-Frame-Options", "DENY")
    resp.headers.setdefault("Referrer-Policy", "same-origin")
    resp.headers.setdefault(
        "Content-Security-Policy",
        "default-src 'self'; media-src 'self'; img-src 'self' data:; style-src 'self'; "
        "script-src 'self'; frame-ancestors 'none'; form-action 'self'",
    )
    if request.path.startswith(("/api/", "/admin")):
        resp.headers.setdefault("Cache-Control", "no-store")
    return resp
