"""The crowd rating web app (Flask): sessions, familiarisation, rating trials, admin and export.

    app = create_app(manifest="stimuli/manifest.csv", db_url="postgresql://...", ratings_per_clip=20)

Arguments left as None are read from the environment (ADMIN_TOKEN, DATABASE_URL, RATING_MANIFEST, STUDY_DESIGN,
STUDY_QUESTION, RATINGS_PER_CLIP, CLIPS_PER_RATER, CATCH_PER_RATER, SLOT_TIMEOUT, MIN_VIEW, SESSIONS_PER_CLIENT,
COMPLETION_CODE, COMPLETION_URL, SECRET_KEY), which is how `rating_app.wsgi:app` is configured under gunicorn.
Also read: COOKIE_SECURE=1 (admin cookie over HTTPS only), PROXY_COUNT (trusted reverse proxies in front, whose
X-Forwarded-For names the client; default 0), VIDEO_ACCEL (nginx or caddy: that proxy sends the videos' bytes through an
internal redirect, videos.py; default off) and DB_POOL_SIZE (connections per worker, default 10 + 10 overflow).
Every setting is checked here, so a bad one stops the start with one line instead of failing on each request.
`config` (or RATING_CONFIG): a study file holding these settings in lower case (study_config.py); an environment
variable that is set overrides its key there.
"""

from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path

from flask import Flask, jsonify, request
from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError, SQLAlchemyError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from werkzeug.exceptions import HTTPException

from moglow_eval.core.cli import number

from .manifest import AppError, load_manifest

__all__ = ["create_app", "AppError", "SETTINGS"]

# name: (kind, default, lo, hi, lo_open); the CLI flags use the same bounds.
SETTINGS = {
    "RATINGS_PER_CLIP": (int, 20, 1, 1_000_000, False),
    "CLIPS_PER_RATER": (int, 0, 0, 1_000_000, False),  # 0: every clip still needing ratings
    "CATCH_PER_RATER": (int, 4, 0, 1_000_000, False),  # catch trials per session from the pool; 0: every one
    "SLOT_TIMEOUT": (float, 3600.0, 0.0, 1e7, True),  # seconds without an answer before a session expires
    "MIN_VIEW": (float, 1.0, 0.0, 1.0, False),  # share of each clip that must have played
    "SESSIONS_PER_CLIENT": (int, 10, 0, 1_000_000, False),  # new sessions per client address per hour; 0: no limit
    "PROXY_COUNT": (int, 0, 0, 10, False),
}


def setting(name: str, given=None, env=None):
    """`given`, else the environment variable `name` (in `env`, default os.environ), else the default; checked
    against SETTINGS."""
    kind, default, lo, hi, lo_open = SETTINGS[name]
    raw = given if given is not None else (os.environ if env is None else env).get(name) or None
    if raw is None:
        return default
    try:
        return number(kind, lo, hi, lo_open)(str(raw))
    except argparse.ArgumentTypeError as e:
        where = name if given is None else name.lower()
        raise AppError(f"{where}: {e}") from None


def _env(name, env=None):
    return (os.environ if env is None else env).get(name) or None


def create_app(
    manifest=None,
    db_url=None,
    ratings_per_clip=None,
    clips_per_rater=None,
    catch_per_rater=None,
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
    config=None,
) -> Flask:
    """`design`: one of moglow_eval.core.study.DESIGNS (designs/; default acr); fixed for the life of the database.
    `ratings_per_clip` and `clips_per_rater` count the design's units (clips, pairs of conditions of an item,
    pages, ...)."""
    from .study_config import study_environment
    from .videos import ACCEL

    env = study_environment(config or _env("RATING_CONFIG"), SETTINGS)
    manifest = manifest or _env("RATING_MANIFEST", env)
    if not manifest:
        raise AppError(
            "no stimulus manifest: set RATING_MANIFEST (or --manifest, or rating_manifest in the study file) to "
            "stimuli/manifest.csv"
        )
    config = _config(
        env,
        ratings_per_clip=ratings_per_clip,
        clips_per_rater=clips_per_rater,
        catch_per_rater=catch_per_rater,
        slot_timeout_s=slot_timeout_s,
        min_view=min_view,
        sessions_per_client=sessions_per_client,
        design=design,
        question=question,
        admin_token=admin_token,
        completion_code=completion_code,
        completion_url=completion_url,
    )
    proxies = config["PROXY_COUNT"]
    app = Flask(__name__)
    if proxies:
        from werkzeug.middleware.proxy_fix import ProxyFix

        app.wsgi_app = ProxyFix(app.wsgi_app, x_for=proxies, x_proto=proxies, x_host=proxies)
    accel = (_env("VIDEO_ACCEL", env) or "off").strip().lower()
    if accel not in ACCEL:
        raise AppError(f"VIDEO_ACCEL: {accel!r} must be one of {', '.join(ACCEL)}")
    app.config.update(
        VIDEO_ACCEL=accel,
        SECRET_KEY=secret_key or _env("SECRET_KEY", env) or _derived_secret(config["ADMIN_TOKEN"]),
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Strict",
        SESSION_COOKIE_SECURE=env.get("COOKIE_SECURE", "") == "1",  # set behind HTTPS
        MAX_CONTENT_LENGTH=16 * 1024,
        **config,
    )
    _install_study(app, manifest, db_url or _env("DATABASE_URL", env), env, check_files)
    return app


def _install_study(app, manifest, db_url, env, check_files) -> None:
    """The study behind a configured app: its design's clips and units, the database (opened and stored to), the
    videos, the set-up warnings and the blueprints."""
    from . import designs, health
    from .admin import bp as admin_bp
    from .api import bp as api_bp
    from .audio_check import bp as audio_check_bp
    from .audio_check import load_audio_check
    from .db import make_read_engine
    from .pages import bp as pages_bp
    from .videos import VideoStore

    config, accel = app.config, app.config["VIDEO_ACCEL"]
    design = designs.get(config["STUDY_DESIGN"])
    clips = design.serving_clips(load_manifest(manifest, check_files=check_files))
    units = design.build_units(clips)
    app.config["STUDY_SOUND"] = any(c.audio for c in clips)  # the page plays sound and checks the rater hears
    engine = _open_database(
        db_url,
        _env("DB_POOL_SIZE", env),
        clips,
        design.name,
        design.cover_keys(clips, units),
        target_raters(design.pool(clips, units)[0], config),
    )
    app.extensions["rating_app"] = {
        "engine": engine,
        "read_engine": make_read_engine(engine),
        "clips": {c.clip_id: c for c in clips},
        # With VIDEO_ACCEL the proxy sends the bytes: no video is read into a worker's memory.
        "videos": VideoStore(clips, Path(manifest).resolve().parent, preload=check_files and accel == "off"),
        "design": design,
        "units": units,
        "audio_check": load_audio_check(manifest) if app.config["STUDY_SOUND"] else {},
        "warnings": health.Warnings(app.logger),
    }
    pool = health.catch_pool_warning(
        config["STUDY_DESIGN"], clips, units, config["CLIPS_PER_RATER"], config["CATCH_PER_RATER"]
    )
    if pool:
        health.of_app(app).add("catch_pool", pool)
    app.before_request(health.note_untrusted_proxy)
    app.register_blueprint(pages_bp)
    app.register_blueprint(api_bp)
    app.register_blueprint(audio_check_bp)
    app.register_blueprint(admin_bp)
    _handle_errors(app)
    app.after_request(_headers)


def _config(
    env,
    ratings_per_clip,
    clips_per_rater,
    catch_per_rater,
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
    from . import designs

    numbers = {  # checked first, in the order the settings are documented
        "RATINGS_PER_CLIP": setting("RATINGS_PER_CLIP", ratings_per_clip, env),
        "CLIPS_PER_RATER": setting("CLIPS_PER_RATER", clips_per_rater, env) or None,  # 0 / None: all clips still short
        "CATCH_PER_RATER": setting("CATCH_PER_RATER", catch_per_rater, env) or None,  # 0 / None: every catch unit
        "SLOT_TIMEOUT_S": float(setting("SLOT_TIMEOUT", slot_timeout_s, env)),
        "MIN_VIEW": float(setting("MIN_VIEW", min_view, env)),
        "SESSIONS_PER_CLIENT": setting("SESSIONS_PER_CLIENT", sessions_per_client, env),
        "PROXY_COUNT": setting("PROXY_COUNT", env=env),
    }
    design = designs.get(design if design is not None else _env("STUDY_DESIGN", env))
    question = (question if question is not None else _env("STUDY_QUESTION", env)) or design.question
    if len(question) > 200 or not question.isprintable():
        raise AppError("question: at most 200 printable characters on one line")
    completion_url = completion_url if completion_url is not None else _env("COMPLETION_URL", env)
    if completion_url and not completion_url.startswith(("https://", "http://")):
        raise AppError(f"completion URL must start with https:// or http://, got {completion_url!r}")
    return {
        **numbers,
        "ADMIN_TOKEN": admin_token if admin_token is not None else _env("ADMIN_TOKEN", env),
        "COMPLETION_CODE": completion_code if completion_code is not None else _env("COMPLETION_CODE", env),
        "COMPLETION_URL": completion_url,
        "STUDY_DESIGN": design.name,
        "STUDY_QUESTION": question,
    }


def _derived_secret(admin_token):
    # Workers must share the cookie key: derive it from the admin token unless one is given.
    return hashlib.sha256(b"rating-app:" + (admin_token or os.urandom(32).hex()).encode()).hexdigest()


def target_raters(test_units: int, config) -> int:
    """How many raters fill the study: every test unit's target answers, each rater answering CLIPS_PER_RATER
    units (all of them when unset); a lower bound, as slots of raters who leave are served again."""
    per_rater = min(config["CLIPS_PER_RATER"] or test_units, test_units)
    return -(-test_units * config["RATINGS_PER_CLIP"] // max(per_rater, 1))


def _open_database(db_url, pool_size, clips, design, cover_keys, n_raters):
    """The engine, with the schema created and the manifest's clips and the design stored; AppError, one line,
    when the database cannot be opened."""
    from . import db as dbm

    engine = dbm.make_engine(db_url, pool_size=pool_size)
    try:
        dbm.init_db(engine, clips, design, cover_keys, {dbm.TARGET_RATERS: n_raters})
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

    @app.errorhandler(DBAPIError)
    @app.errorhandler(PoolTimeout)
    def _db_error(e):
        if not _unavailable(e):
            return _internal(e)
        full = _disk_full(e)
        app.logger.error(
            "database %s on %s %s: %s",
            "full" if full else "error",
            request.method,
            request.path,
            (str(e).splitlines() or [e.__class__.__name__])[0],
        )
        msg = (
            "the server cannot store anything now: its disk is full. What you answered before is saved; please "
            "try again later"
            if full
            else "database unavailable, please retry"
        )
        resp = jsonify(error=msg, retryable=True)
        resp.status_code, resp.headers["Retry-After"] = 503, "2"
        return resp

    @app.errorhandler(Exception)
    def _unhandled(e):
        return _internal(e)

    def _internal(e):
        # Never a stack trace to the client; the full one goes to the server log.
        app.logger.exception("unhandled error on %s %s", request.method, request.path)
        return jsonify(error="internal server error"), 500


def _disk_full(e) -> bool:
    """SQLite's SQLITE_FULL (the disk, or the database's page limit) or PostgreSQL's disk_full (SQLSTATE 53100)."""
    orig = getattr(e, "orig", None)
    return getattr(orig, "sqlite_errorname", None) == "SQLITE_FULL" or getattr(orig, "sqlstate", None) == "53100"


def _unavailable(e) -> bool:
    """An error of the database server or its connection, which a retry may get past (503), not a bug (500): the
    server is down or restarting, a connection was cut, the pool is exhausted, the disk is full."""
    if isinstance(e, (OperationalError, InterfaceError, PoolTimeout)):
        return True
    return bool(getattr(e, "connection_invalidated", False)) or _disk_full(e)


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
