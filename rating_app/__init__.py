"""The crowd rating web app (Flask): sessions, familiarisation, rating trials, admin and export.

    app = create_app(manifest="stimuli/manifest.csv", db_url="postgresql://...", ratings_per_clip=20)

The settings are one table (settings.py): each is a keyword argument here, an environment variable under the
prefix RATING_ (how `rating_app.wsgi:app` is configured under gunicorn), a key of the study file (`config`, or
RATING_CONFIG; store/config.py) and, most of them, a flag of `serve`. An argument left as None is read from the
environment, then the study file, then the default. Every setting is checked here, so a bad one stops the start
with one line instead of failing on each request.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from flask import Flask, jsonify, request
from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError, SQLAlchemyError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from werkzeug.exceptions import HTTPException

from moglow_eval.core import study

from .store.manifest import AppError, interlocutor_colour, load_manifest, reference_name, video_size
from .store.settings import ARGS, SETTINGS, resolve

__all__ = ["create_app", "AppError", "SETTINGS"]


def create_app(*, config=None, check_files=True, **given) -> Flask:
    """The app with the settings `given` (settings.ARGS: manifest, db_url, design, ratings_per_clip, ...; design
    is one of moglow_eval.core.study.DESIGNS, fixed for the life of the database; ratings_per_clip and
    clips_per_rater count the design's units: clips, pairs of conditions of an item, pages, ...), the others from
    the environment, the study file `config` and the defaults. `check_files`: read every video at the start."""
    from .store.config import study_environment

    unknown = sorted(set(given) - set(ARGS))
    if unknown:
        raise TypeError(f"create_app() got an unexpected keyword argument {unknown[0]!r}")
    env = study_environment(config, SETTINGS)
    values = resolve(given, env)
    if not values["RATING_MANIFEST"]:
        raise AppError(
            "no stimulus manifest: set RATING_MANIFEST (or --manifest, or rating_manifest in the study file) to "
            "stimuli/manifest.csv"
        )
    app = Flask(__name__)
    if values["PROXY_COUNT"]:
        from werkzeug.middleware.proxy_fix import ProxyFix

        n = values["PROXY_COUNT"]
        app.wsgi_app = ProxyFix(app.wsgi_app, x_for=n, x_proto=n, x_host=n)
    config = _app_config(values)
    app.config.update(
        VIDEO_ACCEL=values["VIDEO_ACCEL"],
        SECRET_KEY=values["SECRET_KEY"] or _derived_secret(config["ADMIN_TOKEN"]),
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Strict",
        SESSION_COOKIE_SECURE=values["COOKIE_SECURE"],  # set behind HTTPS
        MAX_CONTENT_LENGTH=16 * 1024,
        **config,
    )
    _open_study(app, values, check_files)
    _register(app)
    return app


def _app_config(values) -> dict:
    """The study's settings as app.config entries, once the design, its question and the completion URL are
    checked."""
    from . import designs

    design = designs.get(values["STUDY_DESIGN"])
    question = values["STUDY_QUESTION"] or design.question
    if len(question) > 200 or not question.isprintable():
        raise AppError("question: at most 200 printable characters on one line")
    completion_url = values["COMPLETION_URL"]
    if completion_url and not completion_url.startswith(("https://", "http://")):
        raise AppError(f"completion URL must start with https:// or http://, got {completion_url!r}")
    for env, plain in (("PAIRING", "balanced"), ("STOP_WHEN", "never")):
        if values[env] != plain and not design.ranks_conditions:
            ranking = " or ".join(d.name for d in designs.DESIGNS.values() if d.ranks_conditions)
            raise AppError(f"{env.lower()}: {values[env]} needs the {ranking} design, not {design.name}")
    from .store.reasons import configure

    return {
        **configure(design, values["VOTE_REASONS"], values["REASON_TEXT"], designs.taking_reasons()),
        **{k: values[k] for k in ("PAIRING", "PAIRING_RANDOM", "PAIRING_INDIFFERENCE", "STOP_WHEN", "STOP_LEVEL")},
        "STOP_WIDTH": values["STOP_WIDTH"],
        "STOP_MAX_VOTES": values["STOP_MAX_VOTES"],
        "RATINGS_PER_CLIP": values["RATINGS_PER_CLIP"],
        "CLIPS_PER_RATER": values["CLIPS_PER_RATER"] or None,  # 0: all clips still short of their target
        "CATCH_PER_RATER": values["CATCH_PER_RATER"] or None,  # 0: every catch unit
        "SLOT_TIMEOUT_S": float(values["SLOT_TIMEOUT"]),
        "MIN_VIEW": float(values["MIN_VIEW"]),
        "SESSIONS_PER_CLIENT": values["SESSIONS_PER_CLIENT"],
        "PROXY_COUNT": values["PROXY_COUNT"],
        "ADMIN_TOKEN": values["ADMIN_TOKEN"],
        "COMPLETION_CODE": values["COMPLETION_CODE"],
        "COMPLETION_URL": completion_url,
        "STUDY_DESIGN": design.name,
        "STUDY_QUESTION": question,
        "UPLOAD_ROOT": values["UPLOAD_ROOT"] or None,
    }


def _open_study(app: Flask, values: dict, check_files: bool) -> None:
    """The manifest's clips, the design's units, the database and the videos, in the app's extension state."""
    from . import designs
    from .media.audio_check import load_audio_check
    from .media.videos import VideoStore
    from .operations import health
    from .store.db import make_read_engine
    from .store.samples import group as group_samples
    from .store.samples import standing

    manifest = values["RATING_MANIFEST"]
    design = designs.get(app.config["STUDY_DESIGN"])
    # A stochastic system's samples (pairing/samples.py): the balancing counts the clip that stands for them; every
    # sample is a clip of the database and its video is served.
    every, samples = group_samples(design.serving_clips(load_manifest(manifest, check_files=check_files)))
    clips = standing(every)
    units = design.build_units(clips)
    app.config["STUDY_SOUND"] = any(c.audio for c in clips)  # the page plays sound and checks the rater hears
    # The interlocutor's colour as the renderer drew it (study.json), which the rater's page names; None: unnamed.
    app.config["INTERLOCUTOR_COLOUR"] = interlocutor_colour(manifest)
    # The videos' size, so that the page lays out a wide two-person video as wide before it loads.
    app.config["VIDEO_SIZE"] = video_size(every)
    # The page says "stick figure" only where every video draws one (the manifest's style; empty: the stick).
    app.config["FIGURE"] = "stick figure" if {c.style or "stick" for c in clips} == {"stick"} else "figure"
    engine = _open_database(
        values["DATABASE_URL"],
        values["DB_POOL_SIZE"],
        every,
        design.name,
        design.cover_keys(clips, units),
        target_raters(design.pool(clips, units)[0], app.config),
        reference_name(manifest),
    )
    app.extensions["rating_app"] = {
        "manifest": Path(manifest).resolve(),
        "engine": engine,
        "read_engine": make_read_engine(engine),
        "clips": {c.clip_id: c for c in every},
        "samples": samples,
        "sample_seed": _sample_seed(engine),
        # With VIDEO_ACCEL the proxy sends the bytes: no video is read into a worker's memory.
        "videos": VideoStore(
            every,
            Path(manifest).resolve().parent,
            preload=check_files and values["VIDEO_ACCEL"] == "off",
            cache_bytes=values["VIDEO_CACHE_MB"] * 2**20,
            key=hashlib.sha256(b"video-etag:" + app.secret_key.encode()).digest(),
        ),
        "design": design,
        "units": units,
        "audio_check": load_audio_check(manifest) if app.config["STUDY_SOUND"] else {},
        "warnings": health.Warnings(app.logger),
    }
    _open_rounds(app)  # may withdraw units: the ranking below is built on what is served
    if app.config["PAIRING"] == "active" or app.config["STOP_WHEN"] == "settled":
        from .pairing.active import ActivePairing

        ext = app.extensions["rating_app"]
        ext["ranking"] = ActivePairing(ext["units"], ext["clips"], app.config)
    pool = health.catch_pool_warning(
        design.name, clips, units, app.config["CLIPS_PER_RATER"], app.config["CATCH_PER_RATER"]
    )
    if pool:
        health.of_app(app).add("catch_pool", pool)


def _sample_seed(engine) -> str:
    """The study's sample seed (db.SAMPLE_SEED), written by the database's first start."""
    from .store.db import SAMPLE_SEED, study_setting

    with engine.connect() as conn:
        seed = study_setting(conn, SAMPLE_SEED)
    engine.dispose()
    return seed


def _open_rounds(app: Flask) -> None:
    """Record the study's manifest and conditions (rounds.py) and serve what the database says is served now: a
    withdrawn condition's pairs never again."""
    from sqlalchemy.orm import Session

    from .store import rounds
    from .store.db import utcnow
    from .store.schema import init_lock

    ext = app.extensions["rating_app"]
    # Under the lock the schema is made under: gunicorn's workers start at once, and on a fresh database each would
    # insert the manifest's row and the conditions' rows (a worker that lost the race failed to boot, and took the
    # whole server down with it).
    with init_lock(ext["engine"]), Session(ext["engine"]) as s, s.begin():
        rounds.record_start(s, ext["manifest"], ext["clips"].values(), utcnow())
        gone = rounds.withdrawn(s.connection())
        ext["units"] = rounds.active_units(ext["units"], ext["clips"], gone)
        ext["revision"] = rounds.revision(s.connection())
    ext["engine"].dispose()  # as _open_database: forked workers start without the set-up's connections


def _register(app: Flask) -> None:
    """The blueprints, the error handlers and the response headers."""
    from .media.audio_check import bp as audio_check_bp
    from .operations import health
    from .web.admin import bp as admin_bp
    from .web.api import bp as api_bp
    from .web.pages import bp as pages_bp

    app.before_request(health.note_untrusted_proxy)
    app.register_blueprint(pages_bp)
    app.register_blueprint(api_bp)
    app.register_blueprint(audio_check_bp)
    app.register_blueprint(admin_bp)
    _handle_errors(app)
    app.after_request(_headers)


def _derived_secret(admin_token):
    # Workers must share the cookie key: derive it from the admin token unless one is given.
    return hashlib.sha256(b"rating-app:" + (admin_token or os.urandom(32).hex()).encode()).hexdigest()


def target_raters(test_units: int, config) -> int:
    """How many raters fill the study: every test unit's target answers, each rater answering CLIPS_PER_RATER
    units (all of them when unset); a lower bound, as slots of raters who leave are served again."""
    per_rater = min(config["CLIPS_PER_RATER"] or test_units, test_units)
    return -(-test_units * config["RATINGS_PER_CLIP"] // max(per_rater, 1))


def _open_database(db_url, pool_size, clips, design, cover_keys, n_raters, reference):
    """The engine, with the schema created and the manifest's clips and the design stored; AppError, one line,
    when the database cannot be opened."""
    from .store import db as dbm

    engine = dbm.make_engine(db_url, pool_size=pool_size)
    try:
        names = {study.REFERENCE_NAME: reference} if reference else {}
        dbm.init_db(engine, clips, design, cover_keys, {dbm.TARGET_RATERS: n_raters, **names})
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
