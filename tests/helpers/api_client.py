"""The rater API's steps for an ACR study, as the tests drive it through Flask's test client (CONTRACTS §5-6):
start a session, fetch the next trial, answer it, run a whole session, read the export; and a session made idle."""

import contextlib
import csv
import io

from rating_app.store.manifest import load_manifest

TOKEN_HDR = {"Authorization": "Bearer test-admin-token"}


def start(client, **body):
    r = client.post("/api/sessions", json=body)
    assert r.status_code == 201, r.json
    return r.json["session"]


def nxt(client, token):
    r = client.get(f"/api/sessions/{token}/next")
    assert r.status_code == 200, r.json
    return r.json


def answer(client, token, trial, rating=3, watched_ms=500):
    rating = None if trial["phase"] == "training" else rating
    return client.post(
        f"/api/sessions/{token}/ratings",
        json={"trial_id": trial["trial_id"], "rating": rating, "watched_ms": watched_ms},
    )


def complete(client, token, rating=lambda t: 3):
    seen = []
    for _ in range(100):
        j = nxt(client, token)
        if j.get("done"):
            return seen, j
        t = j["trial"]
        seen.append(t)
        r = answer(client, token, t, rating(t))
        assert r.status_code == 201, r.json
    raise AssertionError("session never ended")


def export_rows(client):
    r = client.get("/admin/export.csv", headers=TOKEN_HDR)
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.data.decode())))


def clips_by_role(app_stimuli):
    out = {}
    for c in load_manifest(app_stimuli):
        out.setdefault(c.role, set()).add(c.clip_id)
    return out


def idle(app, token, hours=2):
    """Move a session's last answer (and last poll) `hours` into the past, as if it had been idle that long."""
    import datetime as dt

    from sqlalchemy import update

    from rating_app.store.db import Rater, app_engine, utcnow

    with app_engine(app).begin() as conn:
        past = utcnow() - dt.timedelta(hours=hours)
        conn.execute(update(Rater).where(Rater.token == token).values(last_progress=past, last_seen=past))


@contextlib.contextmanager
def answered_after(app, trial_id, ms, monkeypatch):
    """Within it, the app's answer clock reads `ms` milliseconds after trial `trial_id` was served: a viewing check's
    wait is then exact, however busy the machine (an answer's real delay can be a second under load)."""
    import datetime as dt

    from sqlalchemy import select

    from rating_app.store.db import Trial, app_engine
    from rating_app.trials import answers

    with app_engine(app).connect() as conn:
        served = conn.execute(select(Trial.served_at).where(Trial.id == trial_id)).scalar_one()
    with monkeypatch.context() as m:
        m.setattr(answers, "utcnow", lambda: served + dt.timedelta(milliseconds=ms))
        yield


def rate_everything(client):
    """A new rater through a whole ACR session, answering 3 to every rating trial; the export's rows."""
    token = client.post("/api/sessions", json={}).json["session"]
    for _ in range(200):
        j = client.get(f"/api/sessions/{token}/next").json
        if j.get("done"):
            break
        t = j["trial"]
        rating = None if t["phase"] == "training" else 3
        r = client.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], "rating": rating})
        assert r.status_code == 201, r.json
    r = client.get("/admin/export.csv", headers=TOKEN_HDR)
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.data.decode())))
