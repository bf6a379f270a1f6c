"""Issue 11, the rating app: a study nobody can game, stall or crash. One test (or more) per finding of the attack
review; each runs on SQLite and PostgreSQL (the `app_db_url` fixture is parametrised)."""

import collections
import csv
import datetime as dt
import hashlib
import io
import os

import pytest
from helpers.api_client import (
    TOKEN_HDR,
    answer,
    answered_after,
    clips_by_role,
    complete,
    export_rows,
    idle,
    nxt,
    start,
)
from helpers.concurrent_raters import run_raters
from helpers.fake_stimuli import write_fake_stimuli
from helpers.flags import video_flags
from sqlalchemy import update

from rating_app.store.db import Trial, app_engine, utcnow
from rating_app.store.manifest import AppError, load_manifest


def at(app, i):
    """A test client that comes from client address number i."""
    c = app.test_client()
    c.environ_base["REMOTE_ADDR"] = f"10.{i // 60000}.{i // 250 % 240}.{i % 250 + 1}"
    return c


def to_test_trial(c, token, roles):
    """Answer familiarisation and catch trials until a test trial is on screen; return it."""
    t = nxt(c, token)["trial"]
    while t["phase"] == "training" or t["clip_id"] not in roles["test"]:
        assert answer(c, token, t, 1).status_code == 201
        t = nxt(c, token)["trial"]
    return t


def backdate_served(app, trial_id, seconds=60):
    with app_engine(app).begin() as conn:
        conn.execute(
            update(Trial).where(Trial.id == trial_id).values(served_at=utcnow() - dt.timedelta(seconds=seconds))
        )


# 1 --------------------------------------------------------------------------------------------------- blinding
def test_video_responses_carry_nothing_that_sorts_by_condition(tmp_path, app_db_url, make_app):
    manifest = write_fake_stimuli(tmp_path / "stimuli")
    clips = load_manifest(manifest)
    order = {"NAT": 1, "MG": 2, "FL": 3, "BAD": 4}
    for c in clips:  # rendered condition by condition, as make_stimuli did
        t = 1_700_000_000 + 3600 * order[c.condition]
        os.utime(c.video, (t, t))
    app = make_app(manifest=manifest, ratings_per_clip=1, min_view=0)
    cl = app.test_client()
    token = start(cl)
    seen, etags = {}, {}
    for t in complete(cl, token)[0]:
        seen[t["clip_id"]] = cl.get(t["video_url"])
    for c in clips:
        for r in (seen.get(c.clip_id), cl.get(f"/videos/{c.clip_id}.mp4")):
            if r is None:
                continue
            data = c.video.read_bytes()
            assert r.status_code == 200 and r.data == data
            assert "Last-Modified" not in r.headers and "Expires" not in r.headers
            # A keyed hash of the content: one per file, but none that whoever holds the bytes can compute (a
            # system's submitter would recognise their own videos by a plain hash).
            etags.setdefault(c.clip_id, set()).add(r.headers["ETag"])
            assert hashlib.sha256(data).hexdigest()[:32] not in r.headers["ETag"] and len(r.headers["ETag"]) == 34
    assert all(len(e) == 1 for e in etags.values())
    # Date is the time of the response (it changes when the responses cross a second), not of the file.
    varying = ("Content-Length", "ETag", "Date")
    names = {tuple(sorted(k for k, _ in r.headers if k not in varying)) for r in seen.values()}
    values = {tuple(sorted((k, v) for k, v in r.headers if k not in varying)) for r in seen.values()}
    assert len(names) == 1 and len(values) == 1  # the same headers and values for every clip
    url = next(iter(seen.values())).request.path
    r = cl.get(url, headers={"Range": "bytes=0-99"})  # seeking still works
    assert r.status_code == 206 and len(r.data) == 100
    r = cl.get(url, headers={"If-None-Match": seen[next(iter(seen))].headers["ETag"]})
    assert r.status_code in (200, 304)


# 2 ---------------------------------------------------------------------------------------------- slot hoarding
def test_sixty_hoarders_cannot_keep_real_raters_out(make_app, app_stimuli):
    roles = clips_by_role(app_stimuli)
    app = make_app(ratings_per_clip=3, min_view=0)
    hoarders = []
    for i in range(60):  # 60 sessions from 60 addresses, polling but never answering
        c = at(app, i)
        hoarders.append((c, start(c)))
    for _ in range(3):
        for c, token in hoarders:
            assert "trial" in nxt(c, token)
    real = []
    for i in range(1000, 1010):
        c = at(app, i)
        r = c.post("/api/sessions", json={})
        if r.status_code == 409:
            assert r.json["full"] and "every clip has all its ratings" in r.json["error"]
            break
        assert r.status_code == 201, r.json
        real.append(complete(c, r.json["session"])[0])
    else:
        raise AssertionError("the study never filled")
    rows = export_rows(app.test_client())
    per_clip = collections.Counter(r["clip_id"] for r in rows if r["role"] == "test")
    assert per_clip == {c: 3 for c in roles["test"]}  # filled completely, by the real raters only
    assert len(real) == 3


def test_a_session_holds_one_slot_and_polling_does_not_keep_it(make_app, app_stimuli):
    roles = clips_by_role(app_stimuli)
    app = make_app(ratings_per_clip=1, min_view=0)
    c = app.test_client()
    ghost = start(c)
    held = to_test_trial(c, ghost, roles)
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert sum(x["in_progress"] for x in p["per_clip"] if x["role"] == "test") == 1
    idle(app, ghost)
    assert c.get(f"/api/sessions/{ghost}/next").status_code == 410  # a poll after the timeout does not revive
    trials, _ = complete(c, start(c))
    assert held["clip_id"] in {t["clip_id"] for t in trials}


def test_sessions_per_client_and_only_same_site_json(make_app):
    app = make_app(ratings_per_clip=3, min_view=0, sessions_per_client=4)
    c = at(app, 7)
    for _ in range(4):
        start(c)
    r = c.post("/api/sessions", json={})
    assert r.status_code == 429 and "error" in r.json
    assert at(app, 8).post("/api/sessions", json={}).status_code == 201
    c = at(app, 9)
    assert c.post("/api/sessions").status_code == 415  # empty body
    assert c.post("/api/sessions", data="{}", content_type="text/plain").status_code == 415
    assert c.post("/api/sessions", data="", content_type="application/json").status_code == 400
    for hdr in (
        {"Sec-Fetch-Site": "cross-site"},
        {"Sec-Fetch-Site": "same-site"},
        {"Origin": "https://evil.example"},
        {"Origin": "null"},
    ):
        r = c.post("/api/sessions", json={}, headers=hdr)
        assert r.status_code == 403 and "cross-site" in r.json["error"], hdr
    ok = c.post("/api/sessions", json={}, headers={"Origin": "http://localhost", "Sec-Fetch-Site": "same-origin"})
    assert ok.status_code == 201
    n = len(c.get("/admin/progress.json", headers=TOKEN_HDR).json["raters"])
    assert n == 4 + 1 + 1


# 3 ---------------------------------------------------------------------------------------- viewing enforced
def test_answer_before_the_clip_could_play_is_refused_and_flagged(make_app, app_stimuli, monkeypatch):
    app = make_app(ratings_per_clip=3)  # MIN_VIEW: the default, the whole clip
    c = app.test_client()
    token = start(c, external_id="fast")
    t = nxt(c, token)["trial"]
    # 8 ms after the trial was served, by the app's clock: a loaded machine could otherwise take the clip's 0.55 s
    # between serving it and the answer, which would then be in time.
    with answered_after(app, t["trial_id"], 8, monkeypatch):
        r = answer(c, token, t)  # watched_ms claimed
    assert r.status_code == 425 and r.json["too_early"] is True
    clip = {x.clip_id: x for x in load_manifest(app_stimuli)}[t["clip_id"]]
    assert 0 < r.json["retry_after_ms"] <= clip.duration_ms - 250
    backdate_served(app, t["trial_id"])  # as if the clip had played meanwhile
    assert answer(c, token, t).status_code == 201
    t = nxt(c, token)["trial"]
    while True:  # the rest: video never fetched, no early attempt
        backdate_served(app, t["trial_id"])
        assert answer(c, token, t).status_code == 201
        j = nxt(c, token)
        if j.get("done"):
            break
        t = j["trial"]
    honest = start(c, external_id="honest")
    while True:
        j = nxt(c, honest)
        if j.get("done"):
            break
        t = j["trial"]
        assert c.get(t["video_url"]).status_code == 200
        backdate_served(app, t["trial_id"])
        assert answer(c, honest, t).status_code == 201
    rows = export_rows(c)
    flags = {(r["external_id"], video_flags(r["flags"])) for r in rows}
    assert flags == {("fast", "no_video;too_fast"), ("honest", "")}
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert p["raters_suspicious"] == 1 and p["min_view"] == 1.0
    fast = next(r for r in p["raters"] if r["external_id"] == "fast")
    assert fast["flags"] == ["too_fast", "no_video"] and fast["early_answers"] == 1
    c.post("/admin/login", data={"token": "test-admin-token"})
    assert "Minimum viewing time lowered" not in c.get("/admin").data.decode()


def test_lowered_minimum_is_shown_on_the_dashboard(make_app, tmp_path):
    # 10-s clips: a quarter of one is a 2.4-s window, which a loaded machine cannot miss between next and answer.
    app = make_app(manifest=write_fake_stimuli(tmp_path / "long", n_frames=200), ratings_per_clip=3, min_view=0.25)
    c = app.test_client()
    token = start(c)
    t = nxt(c, token)["trial"]
    r = answer(c, token, t)
    assert r.status_code == 425 and 0.25 * 9750 / 2 < r.json["retry_after_ms"] <= 0.25 * 9750 + 1
    assert c.get("/admin/progress.json", headers=TOKEN_HDR).json["min_view"] == 0.25
    c.post("/admin/login", data={"token": "test-admin-token"})
    html = c.get("/admin").data.decode()
    assert "Minimum viewing time lowered" in html and "25%" in html


# 4 and 5 ------------------------------------------------------------------------------ expiry and released trials
def test_expired_session_gets_410_and_no_code(make_app, app_stimuli):
    app = make_app(ratings_per_clip=3, min_view=0)
    c = app.test_client()
    token = start(c)
    t = nxt(c, token)["trial"]
    idle(app, token)
    for r in (c.get(f"/api/sessions/{token}/next"), answer(c, token, t), c.get(f"/api/sessions/{token}/next")):
        assert r.status_code == 410 and r.json["expired"] is True and "completion_code" not in r.json
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert p["raters_completed"] == 0 and p["raters_expired"] == 1


def test_released_trial_cannot_push_a_clip_over_target(make_app, app_stimuli):
    roles = clips_by_role(app_stimuli)
    app = make_app(ratings_per_clip=1, min_view=0)
    c = app.test_client()
    late = start(c)
    t = to_test_trial(c, late, roles)
    idle(app, late)
    complete(c, start(c))  # takes the released slot
    r = answer(c, late, t)
    assert r.status_code == 410
    per_clip = collections.Counter(r["clip_id"] for r in export_rows(c) if r["role"] == "test")
    assert set(per_clip.values()) == {1}


def test_concurrent_raters_never_exceed_the_target(make_app, app_stimuli):
    roles = clips_by_role(app_stimuli)
    app = make_app(ratings_per_clip=2, min_view=0, sessions_per_client=0)
    errors = run_raters(app, answer, timeout=120)
    assert not errors
    per_clip = collections.Counter(r["clip_id"] for r in export_rows(app.test_client()) if r["role"] == "test")
    assert per_clip == {c: 2 for c in roles["test"]}


# 6 ------------------------------------------------------------------------------------------------ PID takeover
def test_participant_id_alone_does_not_hand_out_a_session(app):
    victim = app.test_client()
    r = victim.post("/api/sessions", json={"external_id": "PID-victim", "session_id": "PROLIFIC-SESS-1"})
    assert r.status_code == 201
    token = r.json["session"]
    attacker = app.test_client()
    for body in ({"external_id": "PID-victim"}, {"external_id": "PID-victim", "session_id": "guess"}):
        r = attacker.post("/api/sessions", json=body)
        assert r.status_code == 409 and "session" not in r.json and token not in r.data.decode(), body
    r = attacker.post("/api/sessions", json={"external_id": "PID-victim", "session_id": "PROLIFIC-SESS-1"})
    assert r.status_code == 200 and r.json["session"] == token  # the platform's session id is proof
    r = victim.post("/api/sessions", json={"external_id": "PID-victim"})
    assert r.status_code == 200 and r.json["session"] == token  # so is the resume cookie


# 7 ------------------------------------------------------------------------------------------------------ admin
def test_logout_revokes_a_copied_cookie(client):
    r = client.post("/admin/login", data={"token": "test-admin-token"})
    assert r.status_code == 302
    cookie = client.get_cookie("session")
    thief = client.application.test_client()
    thief.set_cookie("session", cookie.value)
    assert thief.get("/admin/export.csv").status_code == 200
    client.post("/admin/logout")
    assert thief.get("/admin/export.csv").status_code == 401
    assert thief.get("/admin").status_code == 401


def test_admin_token_guessing_is_locked_out_per_client(app):
    guesser = at(app, 3)
    for i in range(10):
        assert guesser.post("/admin/login", data={"token": f"guess{i}"}).status_code == 401
    assert guesser.post("/admin/login", data={"token": "test-admin-token"}).status_code == 429
    assert guesser.get("/admin/export.csv", headers=TOKEN_HDR).status_code == 429
    other = at(app, 4)
    assert other.post("/admin/login", data={"token": "test-admin-token"}).status_code == 302
    for i in range(10):
        other.get("/admin/progress.json", headers={"Authorization": f"Bearer guess{i}"})
    assert other.get("/admin/progress.json", headers=TOKEN_HDR).status_code == 429


# 10 --------------------------------------------------------------------------------------------- API input
def test_nested_json_and_ids_are_refused_with_400(client):
    deep = "[" * 5000 + "]" * 5000
    for path in ("/api/sessions",):
        r = client.post(path, data='{"external_id": ' + deep + "}", content_type="application/json")
        assert r.status_code == 400 and "nested" in r.json["error"]
    token = start(client)
    r = client.post(
        f"/api/sessions/{token}/ratings", data='{"trial_id": ' + deep + "}", content_type="application/json"
    )
    assert r.status_code == 400
    for bad in ("PID1\n", "x" * 128 + "\n", "x" * 129, "PID\r"):
        r = client.post("/api/sessions", json={"external_id": bad})
        assert r.status_code == 400 and "external_id" in r.json["error"], repr(bad)
    assert client.post("/api/sessions", json={"external_id": "x" * 128}).status_code == 201


def test_export_neutralises_formulas(client):
    token = start(client, external_id="-2", study_id="@SUM")
    complete(client, token)
    text = client.get("/admin/export.csv", headers=TOKEN_HDR).data.decode()
    rows = list(csv.DictReader(io.StringIO(text)))
    assert rows and {(r["external_id"], r["study_id"]) for r in rows} == {("'-2", "'@SUM")}
    for line in text.splitlines():
        assert not any(cell.startswith(("=", "+", "-", "@")) for cell in line.split(","))


def test_events_are_escaped_and_limited(client, caplog):
    token = start(client)
    with caplog.at_level("WARNING"):
        r = client.post(
            f"/api/sessions/{token}/events", json={"kind": "page_error", "detail": "x\nERROR forged line\r\n"}
        )
    assert r.status_code == 201
    assert not any("\n" in m for m in caplog.messages)
    assert any("x\\nERROR forged line\\r\\n" in m for m in caplog.messages)
    p = client.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert p["events"][0]["detail"] == "x\\nERROR forged line\\r\\n"
    codes = [
        client.post(f"/api/sessions/{token}/events", json={"kind": "video_stalled"}).status_code for _ in range(40)
    ]
    assert codes.count(201) == 29 and codes[-1] == 429


def test_a_video_that_is_not_an_mp4_is_refused(tmp_path):
    """A manifest whose video names another file of the folder (its metrics.csv, a study key, an empty file) was
    served to raters as video; the app now stops at the manifest, naming the line."""
    manifest = write_fake_stimuli(tmp_path / "stimuli")
    rows = list(csv.DictReader(open(manifest, encoding="utf-8")))
    (tmp_path / "stimuli" / "videos" / "empty.mp4").touch()
    for edit in ("metrics.csv", "videos/empty.mp4"):
        bad = tmp_path / "stimuli" / "bad.csv"
        with open(bad, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows[:2] + [dict(rows[2], video=edit)] + rows[3:])
        with pytest.raises(AppError) as e:
            load_manifest(bad)
        assert str(e.value).startswith(f"{bad}:4: video {edit!r} is not an MP4 file"), str(e.value)
    assert len(load_manifest(manifest)) == len(rows)  # the real videos pass


def test_a_video_the_server_may_not_read_is_said_so(tmp_path):
    """A video of mode 000 (copied in with the wrong owner) was called "not an MP4 file"; it is named as unreadable.
    Run without root's rights over files, in a process of its own (helpers.cli.as_a_plain_user)."""
    import subprocess
    import sys

    from helpers.cli import as_a_plain_user
    from helpers.paths import ROOT

    manifest = write_fake_stimuli(tmp_path / "stimuli")
    video = tmp_path / "stimuli" / list(csv.DictReader(open(manifest, encoding="utf-8")))[2]["video"]
    video.chmod(0)
    code = f"from rating_app.store.manifest import load_manifest; load_manifest({str(manifest)!r})"
    try:
        r = subprocess.run(as_a_plain_user([sys.executable, "-c", code]), capture_output=True, text=True, cwd=ROOT)
    finally:
        video.chmod(0o644)
    last = r.stderr.strip().splitlines()[-1]
    assert r.returncode == 1 and f"{manifest}:4: video" in last, r.stderr
    assert "cannot be read (Permission denied)" in last and "not an MP4" not in last


def test_videos_outside_the_stimulus_folder_are_refused(tmp_path, make_app):
    manifest = write_fake_stimuli(tmp_path / "stimuli")
    outside = tmp_path / "secret.mp4"
    outside.write_bytes(b"not for raters")
    rows = list(csv.DictReader(open(manifest, encoding="utf-8")))
    for edit in ("../secret.mp4", str(outside), "videos/link.mp4"):
        (tmp_path / "stimuli" / "videos" / "link.mp4").unlink(missing_ok=True)
        (tmp_path / "stimuli" / "videos" / "link.mp4").symlink_to(outside)
        bad = tmp_path / "stimuli" / "bad.csv"
        with open(bad, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows([dict(rows[0], video=edit)] + rows[1:])
        with pytest.raises(AppError) as e:
            load_manifest(bad)
        assert f"{bad}:2:" in str(e.value) and "leaves the stimulus folder" in str(e.value)
    # a file swapped for a symlink after start-up is never served either
    app = make_app(manifest=manifest, ratings_per_clip=1, min_view=0)
    clip = load_manifest(manifest)[0]
    app.extensions["rating_app"]["videos"].videos.clear()
    clip.video.unlink()
    clip.video.symlink_to(outside)
    r = app.test_client().get(f"/videos/{clip.clip_id}.mp4")
    assert r.status_code == 404 and b"not for raters" not in r.data
