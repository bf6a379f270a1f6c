"""Admin: dashboard, progress and the ratings.csv export, all behind ADMIN_TOKEN.

A script sends `Authorization: Bearer TOKEN`; a browser logs in once through a form and then carries an
HttpOnly, SameSite=Strict session cookie naming a login row in the database (the dashboard only reads, so there
is nothing to forge). Logout deletes the row, so a copied cookie stops working at once, in every worker. Wrong
tokens are counted per client: after LOCKOUT_FAILURES within LOCKOUT_WINDOW the client is refused (429) until
the window has passed, whatever token it sends.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import os
import secrets

from flask import (
    Blueprint,
    Response,
    abort,
    current_app,
    flash,
    get_flashed_messages,
    jsonify,
    redirect,
    render_template,
    request,
    session,
    url_for,
)
from sqlalchemy import delete, func, insert, select

from ..guard.limits import client_key, same_site_only
from ..operations import health
from ..operations.export import export_csv
from ..operations.progress import progress
from ..pairing.active import for_units
from ..store.db import AdminLogin, LoginFailure, app_engine, utcnow
from ..store.manifest import AppError
from ..store.reasons import latest_texts
from ..store.rounds import current_units, refresh

bp = Blueprint("admin", __name__, url_prefix="/admin")

LOCKOUT_FAILURES = 10
LOCKOUT_WINDOW = dt.timedelta(minutes=15)
LOGIN_MAX_AGE = dt.timedelta(hours=12)


def _locked_out(conn, client, now) -> bool:
    n = conn.execute(
        select(func.count())
        .select_from(LoginFailure)
        .where(LoginFailure.client == client, LoginFailure.at >= now - LOCKOUT_WINDOW)
    ).scalar()
    return n >= LOCKOUT_FAILURES


def _check_token(given: str | None) -> bool:
    """Compare a token with ADMIN_TOKEN, counting a wrong one against the client; 429 while locked out."""
    want = current_app.config["ADMIN_TOKEN"]
    if not want:
        return False
    client, now = client_key(), utcnow()
    with app_engine().begin() as conn:
        if _locked_out(conn, client, now):
            abort(429, "too many wrong admin tokens from this address; try again in 15 minutes")
        ok = given is not None and hmac.compare_digest(given.encode(), want.encode())
        if not ok:
            conn.execute(insert(LoginFailure).values(client=client, at=now))
    return ok


def _login_hash(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def authorised() -> bool:
    auth = request.headers.get("Authorization", "")
    if auth.startswith("Bearer "):
        return _check_token(auth[len("Bearer ") :].strip())
    key = session.get("admin")
    if not current_app.config["ADMIN_TOKEN"] or not isinstance(key, str):
        return False
    with app_engine().connect() as conn:
        created = conn.execute(select(AdminLogin.created_at).where(AdminLogin.key_hash == _login_hash(key))).scalar()
    return created is not None and utcnow() - created < LOGIN_MAX_AGE


def require_admin():
    if not current_app.config["ADMIN_TOKEN"]:
        abort(401, "admin is disabled: start the server with RATING_ADMIN_TOKEN set")
    if not authorised():
        abort(401, "admin token required (Authorization: Bearer RATING_ADMIN_TOKEN)")


@bp.get("")
@bp.get("/")
def dashboard():
    if not authorised():
        return render_template("admin_login.html", error=None), 401
    data = _progress()
    return render_template(
        "admin.html",
        p=data,
        min_view=current_app.config["MIN_VIEW"],
        design=current_app.config["STUDY_DESIGN"],
        words=current_app.extensions["rating_app"]["design"].dashboard,
        export_file=current_app.extensions["rating_app"]["design"].export_file,
        warnings=health.of_app().list(),
        reason_texts=_reason_texts(),
        conditions=_conditions(),
        messages=get_flashed_messages(with_categories=True),
    )


def _conditions():
    """The study's conditions and rounds (a design that grows round by round), or None."""
    from ..designs import of_app
    from ..operations.conditions import conditions_table

    if not of_app().grows:
        return None
    with app_engine().connect() as conn:
        return conditions_table(conn)


def _round_change(fn, *args):
    """Run an add or a withdrawal for the dashboard's form (a message, back to the dashboard) or a script with
    the Bearer token (JSON: the result, or 400 with the one-line refusal)."""
    require_admin()
    same_site_only()
    script = request.headers.get("Authorization", "").startswith("Bearer ")
    try:
        out = fn(app_engine(), *args)
    except AppError as e:
        if script:
            return jsonify(error=str(e)), 400
        flash(str(e), "error")
        return redirect(url_for("admin.dashboard"))
    with app_engine().connect() as conn:
        refresh(conn)  # this worker at once; the others when they next hand out a unit or start a session
    if script:
        return jsonify(out)
    flash(" ".join(f"{k}: {v if not isinstance(v, list) else ', '.join(v)};" for k, v in out.items()), "done")
    return redirect(url_for("admin.dashboard"))


def _iso(t):
    return None if t is None else t.isoformat() + "Z"


@bp.post("/conditions")
def add_condition_form():
    """Add a condition from a stimulus folder on the server (the form's `manifest`, optional `condition`)."""
    from ..operations.conditions import add_condition

    require_admin()  # before any answer that names a path
    same_site_only()
    manifest = (request.form.get("manifest") or "").strip()
    if not manifest:
        abort(400, "field 'manifest' must name the new condition's manifest.csv on the server")
    manifest = _under_upload_root(manifest)
    cond = (request.form.get("condition") or "").strip()
    study = current_app.extensions["rating_app"]["manifest"]
    return _round_change(lambda eng: add_condition(eng, manifest, [cond] if cond else (), study))


def _under_upload_root(manifest: str) -> str:
    """The form's manifest path, resolved, when it lies under UPLOAD_ROOT (symlinks followed); otherwise the form
    reads nothing: 400. Without UPLOAD_ROOT the form is off, so a stolen admin login never makes the app read its
    own files (its environment, its database) into the study folder."""
    root = current_app.config["UPLOAD_ROOT"]
    if not root:
        abort(400, "the dashboard adds conditions only from under RATING_UPLOAD_ROOT, which is not set; set it, or run "
              "python -m rating_app add-condition on the server")  # fmt: skip
    root = os.path.realpath(root)
    path = os.path.realpath(os.path.join(root, manifest))
    if os.path.commonpath([root, path]) != root or path == root:
        abort(400, f"field 'manifest' must name a manifest.csv under the upload root {root}")
    return path


@bp.post("/conditions/withdraw")
def withdraw_condition_form():
    from ..operations.conditions import withdraw_condition

    cond = (request.form.get("condition") or "").strip()
    if not cond:
        abort(400, "field 'condition' is required")
    return _round_change(withdraw_condition, cond)


def _reason_texts():
    """The latest free texts given with votes (a design that takes reasons), or None."""
    if not current_app.extensions["rating_app"]["design"].takes_reasons:
        return None
    with app_engine().connect() as conn:
        return latest_texts(conn)


def _progress():
    cfg, ext = current_app.config, current_app.extensions["rating_app"]
    with app_engine().connect() as conn:
        units = current_units(conn)
    data = progress(app_engine(), cfg["RATINGS_PER_CLIP"], cfg["STUDY_DESIGN"], units)
    ranking = for_units(ext, units)
    if ranking is not None:  # active pairing or the stopping rule: how far from settled
        with app_engine().connect() as conn:
            ranking.refresh(conn, now=True)
        data["ranking"] = ranking.status()
    return data


@bp.post("/login")
def login():
    if _check_token(request.form.get("token")):
        key = secrets.token_urlsafe(24)
        with app_engine().begin() as conn:
            conn.execute(insert(AdminLogin).values(key_hash=_login_hash(key), created_at=utcnow()))
        session.clear()
        session["admin"] = key
        return redirect(url_for("admin.dashboard"))
    return render_template("admin_login.html", error="wrong token"), 401


@bp.post("/logout")
def logout():
    key = session.get("admin")
    if isinstance(key, str):
        with app_engine().begin() as conn:
            conn.execute(delete(AdminLogin).where(AdminLogin.key_hash == _login_hash(key)))
    session.clear()
    return redirect(url_for("admin.dashboard"))


@bp.get("/export.csv")
def export():
    require_admin()
    if request.args.get("format") == "battles":  # the leaderboard's battle format (operations/battles.py)
        from ..operations.battles import export_battles

        try:
            body, name = export_battles(app_engine()), "battles.csv"
        except AppError as e:
            abort(400, str(e))
    else:
        body = export_csv(app_engine())
        name = current_app.extensions["rating_app"]["design"].export_file
    return Response(body, mimetype="text/csv", headers={"Content-Disposition": f"attachment; filename={name}"})


@bp.get("/progress.json")
def progress_json():
    require_admin()
    data = _progress()
    data["min_view"] = current_app.config["MIN_VIEW"]
    data["design"] = current_app.config["STUDY_DESIGN"]
    data["warnings"] = health.of_app().list()
    conditions = _conditions()
    if conditions is not None:  # a study with rounds: its conditions, the round each joined in, withdrawn when
        data["conditions"] = [
            {**c, "added_at": c["added_at"].isoformat() + "Z", "withdrawn_at": _iso(c["withdrawn_at"])}
            for c in conditions
        ]
    for r in data["raters"]:
        r["started"], r["last_seen"] = r["started"].isoformat() + "Z", r["last_seen"].isoformat() + "Z"
    for e in data["events"]:
        e["at"] = e["at"].isoformat() + "Z"
    return jsonify(data)
