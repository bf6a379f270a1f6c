"""The rater API's steps in any design (CONTRACTS §8), as the tests drive it through Flask's test client: the clips a
trial shows, an answer the design takes, a whole session answered, and the export as rows. A session starts as in
an ACR study (helpers/api_client.py)."""

import csv
import io

from rating_app.store.manifest import load_manifest

from .api_client import TOKEN_HDR, start  # noqa: F401  (start: one of this module's steps)


def clips_of(manifest):
    return {c.clip_id: c for c in load_manifest(manifest)}


def shown(t):
    return [t] if "clip_id" in t else [t["a"], t["b"]] if "a" in t else t["clips"]


def value_for(t, pref=1, rating=lambda i, c: 40 + i):
    if "clip_id" in t:  # acr
        return {"rating": None if t["phase"] == "training" else 3}
    if t["phase"] == "training":
        return {"preference": None} if "a" in t else {"ratings": None}
    if "a" in t:
        return {"preference": pref(t) if callable(pref) else pref}
    return {"ratings": {c["clip_id"]: rating(i, c) for i, c in enumerate(t["clips"])}}


def post(c, token, t, **value):
    body = value or value_for(t)
    return c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], "watched_ms": 900, **body})


def complete(c, token, **answer):
    seen = []
    for _ in range(400):
        r = c.get(f"/api/sessions/{token}/next")
        assert r.status_code == 200, r.json
        if r.json.get("done"):
            return seen, r.json
        t = r.json["trial"]
        for x in shown(t):
            assert c.get(x["video_url"]).status_code == 200
        seen.append(t)
        r = post(c, token, t, **value_for(t, **answer))
        assert r.status_code == 201, r.json
    raise AssertionError("session never ended")


def export(c):
    r = c.get("/admin/export.csv", headers=TOKEN_HDR)
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.data.decode()))), r
