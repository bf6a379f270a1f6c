"""Rating app JSON API (CONTRACTS §5-6): the flow, assignment, idempotency and every bad-input case.
Each test runs on SQLite and on PostgreSQL (the `app` fixture is parametrised)."""

import threading

from helpers.api_client import TOKEN_HDR, answer, clips_by_role, complete, export_rows, idle, nxt, start

from rating_app.store.manifest import load_manifest


def test_whole_session_flow_and_export(client, app_stimuli):
    roles = clips_by_role(app_stimuli)
    r = client.post("/api/sessions", json={"external_id": "PID123", "study_id": "S1", "session_id": "X9"})
    assert r.status_code == 201
    body = r.json
    assert body["n_trials"] == len(roles["training"]) + len(roles["test"]) + len(roles["catch"])
    token = body["session"]
    trials, done = complete(client, token, rating=lambda t: 1 + t["index"] % 5)
    # familiarisation first, every training clip once; then every test and catch clip once
    phases = [t["phase"] for t in trials]
    assert phases == ["training"] * len(roles["training"]) + ["rating"] * (len(roles["test"]) + len(roles["catch"]))
    assert {t["clip_id"] for t in trials if t["phase"] == "training"} == roles["training"]
    assert {t["clip_id"] for t in trials if t["phase"] == "rating"} == roles["test"] | roles["catch"]
    assert [t["index"] for t in trials if t["phase"] == "rating"] == list(
        range(1, len(roles["test"]) + len(roles["catch"]) + 1)
    )
    # never a hint of the condition: the trial carries only opaque ids, the video URL only the clip id
    for t in trials:
        assert set(t) == {"trial_id", "clip_id", "video_url", "phase", "index", "of"}
        assert t["video_url"] == f"/api/sessions/{token}/trials/{t['trial_id']}/video.mp4"
    assert done["done"] is True and done["completion_code"]
    assert nxt(client, token) == done  # stays done, same code
    rows = export_rows(client)
    assert len(rows) == len(roles["test"]) + len(roles["catch"])  # training acks are never exported
    for col in (
        "rater_id",
        "clip_id",
        "condition",
        "rating",
        "role",
        "item",
        "trial_index",
        "watched_ms",
        "submitted_at",
    ):
        assert col in rows[0]
    by_clip = {row["clip_id"]: row for row in rows}
    for t in trials:
        if t["phase"] == "rating":
            row = by_clip[t["clip_id"]]
            assert int(row["rating"]) == 1 + t["index"] % 5 and int(row["trial_index"]) == t["index"]
            assert row["role"] == ("catch" if t["clip_id"] in roles["catch"] else "test")
            assert row["external_id"] == "PID123" and row["watched_ms"] == "500"
            assert row["submitted_at"].endswith("Z")
    assert {r["condition"] for r in rows} == {"NAT", "MG", "FL", "BAD"}


def test_random_order_per_rater(client):
    orders = []
    for _ in range(2):
        trials, _ = complete(client, start(client))
        orders.append([t["clip_id"] for t in trials if t["phase"] == "rating"])
    assert sorted(orders[0]) == sorted(orders[1]) and orders[0] != orders[1]


def test_repeated_submission_stored_once(client):
    token = start(client)
    t = nxt(client, token)["trial"]
    assert answer(client, token, t).status_code == 201  # training ack
    assert answer(client, token, t).status_code == 200
    while t["phase"] == "training":
        t = nxt(client, token)["trial"]
        if t["phase"] == "training":
            assert answer(client, token, t).status_code == 201
    assert answer(client, token, t, rating=2).status_code == 201
    again = answer(client, token, t, rating=5)  # no going back, no change
    assert again.status_code == 200 and again.json["rating"] == 2
    rows = [r for r in export_rows(client) if r["clip_id"] == t["clip_id"]]
    assert len(rows) == 1 and rows[0]["rating"] == "2"
    assert nxt(client, token)["trial"]["trial_id"] != t["trial_id"]


def test_concurrent_duplicate_posts_counted_once(app):
    client = app.test_client()
    token = start(client)
    t = nxt(client, token)["trial"]
    while t["phase"] == "training":
        answer(client, token, t)
        t = nxt(client, token)["trial"]
    statuses, barrier = [], threading.Barrier(8)

    def post():
        c = app.test_client()
        barrier.wait()
        statuses.append(answer(c, token, t, rating=4).status_code)

    threads = [threading.Thread(target=post) for _ in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert sorted(statuses) == [200] * 7 + [201], (statuses, export_rows(client))
    assert sum(r["clip_id"] == t["clip_id"] for r in export_rows(client)) == 1


def test_resume_by_external_id(client):
    r1 = client.post("/api/sessions", json={"external_id": "same-person"})
    r2 = client.post("/api/sessions", json={"external_id": "same-person"})
    assert r1.status_code == 201 and r2.status_code == 200
    assert r1.json["session"] == r2.json["session"] and r2.json["resumed"] is True


def test_assignment_fills_targets_with_fewest_raters_then_closes(client, app_stimuli):
    roles = clips_by_role(app_stimuli)
    for _ in range(3):  # target is 3 ratings per clip
        trials, _ = complete(client, start(client))
        assert {t["clip_id"] for t in trials if t["phase"] == "rating"} == roles["test"] | roles["catch"]
    r = client.post("/api/sessions", json={})
    assert r.status_code == 409 and r.json["full"] is True and "study full" in r.json["error"]
    assert b'data-full="1"' in client.get("/").data
    rows = export_rows(client)
    per_clip = {}
    for row in rows:
        if row["role"] == "test":
            per_clip[row["clip_id"]] = per_clip.get(row["clip_id"], 0) + 1
    assert per_clip == {c: 3 for c in roles["test"]}


def test_balanced_share_and_abandoned_slots(app_stimuli, make_app):
    roles = clips_by_role(app_stimuli)
    n_test = len(roles["test"])
    app = make_app(ratings_per_clip=1, clips_per_rater=n_test // 3, slot_timeout_s=3600, min_view=0)
    c = app.test_client()
    got = []
    for _ in range(3):
        trials, _ = complete(c, start(c))
        tests = {t["clip_id"] for t in trials if t["clip_id"] in roles["test"]}
        assert len(tests) == n_test // 3
        assert roles["catch"] <= {t["clip_id"] for t in trials}  # every rater gets every catch clip
        got.append(tests)
    assert set().union(*got) == roles["test"] and sum(map(len, got)) == n_test  # each clip exactly once
    assert c.post("/api/sessions", json={}).status_code == 409

    # A rater who walks away on a test trial holds that one slot, and only until the timeout has passed.
    app = make_app(ratings_per_clip=2, slot_timeout_s=3600, min_view=0)  # each clip has 1 rating already
    c = app.test_client()
    ghost = start(c)
    t = nxt(c, ghost)["trial"]
    while t["phase"] == "training" or t["clip_id"] not in roles["test"]:
        assert answer(c, ghost, t, 1).status_code == 201
        t = nxt(c, ghost)["trial"]
    held = t["clip_id"]
    trials, _ = complete(c, start(c))
    assert {x["clip_id"] for x in trials} >= roles["test"] - {held} and held not in {x["clip_id"] for x in trials}
    r = c.post("/api/sessions", json={})
    assert r.status_code == 409 and "for now" in r.json["error"]
    idle(app, ghost)  # nothing answered for longer than the slot timeout
    trials, _ = complete(c, start(c))
    assert held in {x["clip_id"] for x in trials}
    r = c.get(f"/api/sessions/{ghost}/next")  # the ghost is told it expired, and gets no code
    assert r.status_code == 410 and r.json["expired"] is True and "completion_code" not in r.json
    assert c.post("/api/sessions", json={}).status_code == 409


# ---------------------------------------------------------------------------------------------- bad input
RATING_CASES = [
    ({"trial_id": "1", "rating": 3}, 400, "trial_id"),
    ({"trial_id": True, "rating": 3}, 400, "trial_id"),
    ({"trial_id": 1.5, "rating": 3}, 400, "trial_id"),
    ({"rating": 3}, 400, "trial_id"),
    ({"trial_id": 0, "rating": 3}, 400, "trial_id"),
    ({"trial_id": 999999, "rating": 3}, 404, "trial"),
    ({"trial_id": "OWN", "rating": 0}, 400, "rating"),
    ({"trial_id": "OWN", "rating": 6}, 400, "rating"),
    ({"trial_id": "OWN", "rating": 2.5}, 400, "rating"),
    ({"trial_id": "OWN", "rating": "3"}, 400, "rating"),
    ({"trial_id": "OWN", "rating": True}, 400, "rating"),
    ({"trial_id": "OWN", "rating": None}, 400, "rating"),
    ({"trial_id": "OWN"}, 400, "rating"),
    ({"trial_id": "OWN", "rating": 3, "watched_ms": -1}, 400, "watched_ms"),
    ({"trial_id": "OWN", "rating": 3, "watched_ms": "long"}, 400, "watched_ms"),
    ({"trial_id": "OWN", "rating": 3, "condition": "NAT"}, 400, "unknown field"),
    ({"trial_id": "OTHER", "rating": 3}, 404, "trial"),
    ({"trial_id": "LATER", "rating": 3}, 409, "not been shown"),
]


def test_rating_bad_input(client):
    token = start(client)
    t = nxt(client, token)["trial"]
    while t["phase"] == "training":
        answer(client, token, t)
        t = nxt(client, token)["trial"]
    other = start(client)
    ids = {"OWN": t["trial_id"], "OTHER": nxt(client, other)["trial"]["trial_id"], "LATER": t["trial_id"] + 1}
    for case, status, needle in RATING_CASES:
        body = {k: ids.get(v, v) if k == "trial_id" and isinstance(v, str) else v for k, v in case.items()}
        r = client.post(f"/api/sessions/{token}/ratings", json=body)
        assert r.status_code == status, (case, r.json)
        assert needle in r.json["error"], case
        assert nxt(client, token)["trial"]["trial_id"] == t["trial_id"]  # nothing was stored
    assert export_rows(client) == []


def test_training_trial_rejects_a_rating(client):
    token = start(client)
    t = nxt(client, token)["trial"]
    assert t["phase"] == "training"
    r = client.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], "rating": 4})
    assert r.status_code == 400 and "null" in r.json["error"]


MALFORMED = [
    ({"data": "rating=3", "content_type": "application/x-www-form-urlencoded"}, 415),  # a cross-site form
    ({"data": "{not json", "content_type": "application/json"}, 400),
    ({"data": "[1, 2]", "content_type": "application/json"}, 400),
    ({"data": '{"trial_id": 1, "pad": "' + "x" * 20000 + '"}', "content_type": "application/json"}, 413),
]


def test_malformed_bodies(client):
    token = start(client)
    for kwargs, status in MALFORMED:
        r = client.post(f"/api/sessions/{token}/ratings", **kwargs)
        assert r.status_code == status and "error" in r.json, kwargs
        r = client.post("/api/sessions", **kwargs)
        assert r.status_code == status and "error" in r.json, kwargs


SESSION_CASES = [
    ({"external_id": "a b"}, "external_id"),
    ({"external_id": "x" * 200}, "external_id"),
    ({"external_id": 5}, "external_id"),
    ({"study_id": "<script>"}, "study_id"),
    ({"role": "admin"}, "unknown field"),
]


def test_session_bad_input(client):
    for body, needle in SESSION_CASES:
        r = client.post("/api/sessions", json=body)
        assert r.status_code == 400 and needle in r.json["error"], body
    assert client.get("/admin/progress.json", headers=TOKEN_HDR).json["raters"] == []


def test_unknown_tokens_404(client):
    start(client)
    for token in ("nosuchtokennosuchtoken", "short", "..%2F..%2Fetc", "a" * 65):
        for r in (
            client.get(f"/api/sessions/{token}/next"),
            client.post(f"/api/sessions/{token}/ratings", json={"trial_id": 1, "rating": 3}),
            client.post(f"/api/sessions/{token}/events", json={"kind": "video_error"}),
        ):
            assert r.status_code == 404 and "error" in r.json, token


def test_videos_only_by_clip_id(client, app_stimuli):
    clip = load_manifest(app_stimuli)[0]
    r = client.get(f"/videos/{clip.clip_id}.mp4")
    assert r.status_code == 200 and r.mimetype == "video/mp4" and r.data == clip.video.read_bytes()
    r = client.get(f"/videos/{clip.clip_id}.mp4", headers={"Range": "bytes=0-99"})  # seeking / Safari
    assert r.status_code == 206 and len(r.data) == 100
    for bad in (
        "/videos/",
        "/videos",
        "/videos/0000000000000000.mp4",
        f"/videos/{clip.clip_id}",
        "/videos/..%2Fmanifest.csv",
        "/videos/../manifest.csv",
        f"/videos/videos%2F{clip.clip_id}.mp4",
        "/static/",
        "/static/../manifest.csv",
        "/manifest.csv",
    ):
        r = client.get(bad)
        assert r.status_code == 404, bad
        assert b"clip_id" not in r.data and b"<li>" not in r.data


def test_admin_requires_token(client):
    for path in ("/admin/export.csv", "/admin/progress.json"):
        assert client.get(path).status_code == 401
        assert client.get(path, headers={"Authorization": "Bearer wrong"}).status_code == 401
        assert client.get(path, headers=TOKEN_HDR).status_code == 200
    assert client.get("/admin").status_code == 401
    assert client.post("/admin/login", data={"token": "wrong"}).status_code == 401
    r = client.post("/admin/login", data={"token": "test-admin-token"})
    assert r.status_code == 302
    cookie = r.headers["Set-Cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    page = client.get("/admin")
    assert page.status_code == 200 and b"Rating progress" in page.data


def test_admin_disabled_without_token(make_app):
    c = make_app(admin_token="", ratings_per_clip=3).test_client()
    assert c.get("/admin/export.csv", headers={"Authorization": "Bearer "}).status_code == 401
    assert c.post("/admin/login", data={"token": ""}).status_code == 401


def test_dashboard_progress_and_catch_failures(client, app_stimuli):
    roles = clips_by_role(app_stimuli)
    complete(client, start(client, external_id="good"), rating=lambda t: 1)
    complete(client, start(client, external_id="bad"), rating=lambda t: 5)  # rates the catch clips 5
    p = client.get("/admin/progress.json", headers=TOKEN_HDR).json
    raters = {r["external_id"]: r for r in p["raters"]}
    assert raters["good"]["catch_failures"] == 0 and raters["bad"]["catch_failures"] == len(roles["catch"])
    assert p["raters_failed_catch"] == 1 and p["raters_completed"] == 2
    assert p["ratings_test"] == 2 * len(roles["test"])
    conds = {c["condition"]: c for c in p["per_condition"]}
    assert conds["BAD"]["ratings"] == 2 * len(roles["catch"]) and conds["BAD"]["mean"] == 3.0
    assert all(c["ratings"] == 2 for c in p["per_clip"])
    client.post("/admin/login", data={"token": "test-admin-token"})
    html = client.get("/admin").data.decode()
    assert "bad" in html and "NAT" in html and "<progress" in html


def test_dashboard_states_the_bytes_a_session_downloads(client, app_stimuli):
    """What a rater downloads is what the server sent: every byte of each video fetched in full, counted once per
    session, the median over finished sessions on the dashboard; a session that fetched nothing counts nothing."""
    token = start(client, external_id="watcher")
    sent = 0
    for _ in range(100):
        j = nxt(client, token)
        if j.get("done"):
            break
        t = j["trial"]
        body = client.get(t["video_url"]).data
        client.get(t["video_url"])  # a replay sends the bytes again but adds nothing new
        sent += len(body)
        assert answer(client, token, t).status_code == 201
    assert sent > 0
    p = client.get("/admin/progress.json", headers=TOKEN_HDR).json
    raters = {r["external_id"]: r for r in p["raters"]}
    assert raters["watcher"]["bytes_sent"] == sent and p["bytes_per_session"] == sent
    complete(client, start(client, external_id="blind"))  # fetched no video: 0 bytes, the median of two
    p = client.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert {r["external_id"]: r["bytes_sent"] for r in p["raters"]}["blind"] == 0
    assert p["bytes_per_session"] == sent // 2
    client.post("/admin/login", data={"token": "test-admin-token"})
    assert "MB of video (median)" in client.get("/admin").data.decode()


def test_failed_playback_is_logged(client, caplog):
    token = start(client)
    t = nxt(client, token)["trial"]
    with caplog.at_level("WARNING"):
        r = client.post(
            f"/api/sessions/{token}/events",
            json={"kind": "video_error", "trial_id": t["trial_id"], "detail": "MEDIA_ERR_DECODE"},
        )
    assert r.status_code == 201
    assert any("video_error" in m and "MEDIA_ERR_DECODE" in m and t["clip_id"] in m for m in caplog.messages)
    p = client.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert p["events"][0]["kind"] == "video_error"
    assert client.post(f"/api/sessions/{token}/events", json={"kind": "rm -rf"}).status_code == 400
    assert (
        client.post(f"/api/sessions/{token}/events", json={"kind": "video_error", "trial_id": 10**6}).status_code == 404
    )


def test_errors_are_json_without_stack_traces(app):
    def boom():
        raise RuntimeError("secret internal detail")

    app.add_url_rule("/boom", "boom", boom)
    c = app.test_client()
    app.config["TESTING"] = False  # behave as in production (no exception propagation)
    app.config["PROPAGATE_EXCEPTIONS"] = False
    r = c.get("/boom")
    assert r.status_code == 500 and r.json == {"error": "internal server error"}
    assert b"Traceback" not in r.data and b"secret" not in r.data
    r = c.delete("/api/sessions")
    assert r.status_code == 405 and "error" in r.json
    r = c.get("/nothing-here")
    assert r.status_code == 404 and r.is_json


def test_pages_carry_ids_and_no_condition(client):
    r = client.get("/?PROLIFIC_PID=5f1a2b&STUDY_ID=st1&SESSION_ID=se1")
    html = r.data.decode()
    assert r.status_code == 200
    assert 'data-external-id="5f1a2b"' in html and 'data-study-id="st1"' in html
    assert "completely unnatural: could not possibly be produced by a real person" in html
    assert "completely natural: looks like the motion of a real person" in html
    assert 'muted playsinline preload="auto"' in html and 'name="viewport"' in html
    for cond in ("NAT", "MG", "FL", "BAD"):
        assert cond not in html
    r = client.get('/?PROLIFIC_PID="><script>alert(1)</script>')
    assert "<script>alert" not in r.data.decode() and 'data-external-id=""' in r.data.decode()
    assert "script-src 'self'" in r.headers["Content-Security-Policy"]


def test_completion_code_and_redirect(make_app):
    app = make_app(
        ratings_per_clip=3,
        min_view=0,
        completion_code="C1ABCDEF",
        completion_url="https://app.prolific.com/submissions/complete?cc={code}",
    )
    c = app.test_client()
    _, done = complete(c, start(c))
    assert done["completion_code"] == "C1ABCDEF"
    assert done["redirect_url"] == "https://app.prolific.com/submissions/complete?cc=C1ABCDEF"
