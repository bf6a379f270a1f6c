"""Admin: dashboard, ratings.csv export and the clip table, all behind ADMIN_TOKEN.

A script sends `Authorization: Bearer TOKEN`; a browser logs in once through a form and then carries an
HttpOnly, SameSite=Strict session cookie (the dashboard only reads, so there is nothing to forge).
"""
from __future__ import annotations

import hmac

from flask import (Blueprint, Response, abort, current_app, jsonify, redirect, render_template, request,
                   session, url_for)

from .export import export_csv, progress

bp = Blueprint("admin", __name__, url_prefix="/admin")


def _token_ok(given: str | None) -> bool:
    want = current_app.config["ADMIN_TOKEN"]
    return bool(want) and given is not None and hmac.compare_digest(given.encode(), want.encode())


def authorised() -> bool:
    auth = request.headers.get("Authorization", "")
    if auth.startswith("Bearer "):
        return _token_ok(auth[len("Bearer "):].strip())
    return bool(session.get("admin")) and bool(current_app.config["ADMIN_TOKEN"])


def require_admin():
    if not current_app.config["ADMIN_TOKEN"]:
        abort(401, "admin is disabled: start the server with ADMIN_TOKEN set")
    if not authorised():
        abort(401, "admin token required (Authorization: Bearer ADMIN_TOKEN)")


def _engine():
    return current_app.extensions["rating_app"]["engine"]


@bp.get("")
@bp.get("/")
def dashboard():
    if not authorised():
        return render_template("admin_login.html", error=None), 401
    data = progress(_engine(), current_app.config["RATINGS_PER_CLIP"])
    return render_template("admin.html", p=data)


@bp.post("/login")
def login():
    if _token_ok(request.form.get("token")):
        session.clear()
        session["admin"] = True
        return redirect(url_for("admin.dashboard"))
    return render_template("admin_login.html", error="wrong token"), 401


@bp.post("/logout")
def logout():
    session.clear()
    return redirect(url_for("admin.dashboard"))


@bp.get("/export.csv")
def export():
    require_admin()
    body = export_csv(_engine())
    return Response(body, mimetype="text/csv",
                    headers={"Content-Disposition": "attachment; filename=ratings.csv"})


@bp.get("/progress.json")
def progress_json():
    require_admin()
    data = progress(_engine(), current_app.config["RATINGS_PER_CLIP"])
    for r in data["raters"]:
        r["started"], r["last_seen"] = r["started"].isoformat() + "Z", r["last_seen"].isoformat() + "Z"
    for e in data["events"]:
        e["at"] = e["at"].isoformat() + "Z"
    return jsonify(data)


@bp.get("/clips.json")
def clips_json():
    """The clip table with conditions and metrics: what the simulated crowd needs to play its part."""
    require_admin()
    ext = current_app.extensions["rating_app"]
    out = []
    for c in ext["clips"].values():
        rec = {"clip_id": c.clip_id, "condition": c.condition, "role": c.role, "item": c.item,
               "frames": c.frames, "fps": c.fps}
        rec.update({k: v for k, v in ext["metrics"].get(c.clip_id, {}).items()
                    if k not in ("condition", "role", "item")})
        out.append(rec)
    return jsonify(clips=out)
