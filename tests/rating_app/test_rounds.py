"""A condition joins a running pairwise study, and one is withdrawn (CONTRACTS §8, *Rounds*), on SQLite and on
PostgreSQL: `python -m rating_app add-condition` / `withdraw-condition` and the dashboard's forms. Nothing stored
changes (every row of every table is the same after the add), new raters get the new pairs from the running app,
each vote records its round, a withdrawn condition's pairs stop while its votes stay in the export, and every clash
is refused with one line, leaving the study folder and the database as they were."""

import csv
import io
import json
import os
import subprocess
import sys

import pytest
import requests
from helpers.api_client import TOKEN_HDR
from helpers.cli import fails_with
from helpers.fake_stimuli import write_fake_stimuli
from helpers.paths import ROOT
from helpers.study_folders import N_ITEMS, dump, folder_state, one_size

from rating_app.__main__ import main
from rating_app.store import rounds
from rating_app.store.db import app_engine, utcnow
from rating_app.store.manifest import load_manifest


def unchanged(before, after) -> None:
    """Every row of `before` is in `after`, the same; the round and the revision alone may move on."""
    for table, rows in before.items():
        for key, row in rows.items():
            if table == "study_settings" and key[0] in (rounds.ROUND, rounds.REVISION):
                continue
            assert after[table].get(key) == row, (table, key)


def complete(c, reasons=None, bad=(), prefer=None):
    """A new rater through the whole session, preferring A (or as `prefer(clip_a, clip_b)` says) but never a clip
    of `bad` (catch clips' ids, so that it passes its catch trials); its rater id."""
    r = c.post("/api/sessions", json={})
    assert r.status_code == 201, r.json
    token, rater_id = r.json["session"], r.json["rater_id"]
    for _ in range(400):
        r = c.get(f"/api/sessions/{token}/next")
        assert r.status_code == 200, r.json
        if r.json.get("done"):
            return rater_id
        t = r.json["trial"]
        for x in (t["a"], t["b"]):
            assert c.get(x["video_url"]).status_code == 200  # the new clips' videos are served too
        chosen = prefer(t["a"]["clip_id"], t["b"]["clip_id"]) if prefer else 1
        body = {"trial_id": t["trial_id"], "preference": None if t["phase"] == "training" else chosen}
        if t["phase"] != "training" and t["a"]["clip_id"] in bad:
            body["preference"] = -1
        if reasons and t["phase"] != "training":
            body["reasons"] = reasons
        r = c.post(f"/api/sessions/{token}/ratings", json=body)
        assert r.status_code == 201, r.json
    raise AssertionError("session never ended")


def through_training(c):
    """(token, rater id) of a new session with its familiarisation trials answered, and no rating trial served."""
    r = c.post("/api/sessions", json={}).json
    for _ in range(r["n_training"]):
        t = c.get(f"/api/sessions/{r['session']}/next").json["trial"]
        assert t["phase"] == "training"
        assert c.post(f"/api/sessions/{r['session']}/ratings", json={"trial_id": t["trial_id"]}).status_code == 201
    return r["session"], r["rater_id"]


def export(c):
    r = c.get("/admin/export.csv", headers=TOKEN_HDR)
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.data.decode())))


def pairs_of(rows, rater_id):
    return [frozenset((r["condition_a"], r["condition_b"])) for r in rows if r["rater_id"] == rater_id]


def test_a_condition_joins_a_running_study_and_is_withdrawn(make, folders, app_db_url):
    study, new = folders
    app = make(study, "pairwise", ratings_per_clip=3)
    c = app.test_client()
    first = complete(c, reasons=["MotionSmoothness"])
    early, early_id = through_training(c)  # a session that has started, and has not been served a rating trial yet
    engine = app_engine(app)
    before, files_before = dump(engine), folder_state(study)

    r = subprocess.run(
        [sys.executable, "-m", "rating_app", "add-condition", "--db", app_db_url, "--manifest", str(new)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out == {"round": 2, "conditions": ["SYS"], "clips": N_ITEMS, "pairs": 3 * N_ITEMS}
    after = dump(engine)
    unchanged(before, after)  # nothing already stored changed
    assert len(after["clips"]) == len(before["clips"]) + N_ITEMS
    assert len(after["cover"]) == len(before["cover"]) + 3 * N_ITEMS
    # The study folder: every file as it was, the manifest grown by the new clips, their videos beside it.
    files_after = folder_state(study)
    assert all(files_after[k] == v for k, v in files_before.items() if k not in ("manifest.csv", "metrics.csv"))
    sys_clips = [x for x in load_manifest(study) if x.condition == "SYS"]
    assert len(sys_clips) == N_ITEMS and all(x.role == "test" and x.video.is_file() for x in sys_clips)
    mtimes = {p.stat().st_mtime for p in (study.parent / "videos").glob("*.mp4")}
    assert len(mtimes) == 1  # the copies carry the set's one file time

    # The running app (not restarted) learns of the round as it hands out a unit: the early session's first test
    # trial is a new pair (the least covered), though no session has started since.
    clips = {x.clip_id: x.condition for x in load_manifest(study)}
    while True:
        t = c.get(f"/api/sessions/{early}/next").json["trial"]
        shown = {clips[t["a"]["clip_id"]], clips[t["b"]["clip_id"]]}
        answer = c.post(f"/api/sessions/{early}/ratings", json={"trial_id": t["trial_id"], "preference": 2})
        assert answer.status_code == 201
        if "BAD" not in shown:
            assert "SYS" in shown, shown
            break

    # The running app gives a new rater the new pairs; every vote records its round.
    second = complete(c)
    rows = export(c)
    assert {r["rater_id"] for r in rows} == {first, early_id, second}
    assert {r["round"] for r in rows if r["rater_id"] == first} == {"1"}
    assert {r["round"] for r in rows if r["rater_id"] != first} == {"2"}
    pairs = pairs_of([r for r in rows if r["role"] == "test"], second)
    assert sum("SYS" in p for p in pairs) == 3 * N_ITEMS
    assert all("SYS" not in p for p in pairs_of(rows, first))

    # Withdrawn through the dashboard's endpoint: a new rater gets no SYS pair; its votes stay in the export.
    r = c.post("/admin/conditions/withdraw", data={"condition": "SYS"}, headers=TOKEN_HDR)
    assert r.status_code == 200 and r.json["condition"] == "SYS", r.json
    assert c.post("/admin/conditions/withdraw", data={"condition": "SYS"}, headers=TOKEN_HDR).status_code == 400
    complete(c)
    rows = export(c)
    third = [r for r in rows if r["rater_id"] not in (first, early_id, second)]
    assert third and all("SYS" not in (r["condition_a"], r["condition_b"]) for r in third)
    assert sum("SYS" in (r["condition_a"], r["condition_b"]) for r in rows) >= 3 * N_ITEMS

    # A restart serves the grown manifest, the withdrawal kept; the dashboard lists the rounds.
    again = make(study, "pairwise", ratings_per_clip=3)
    units = again.extensions["rating_app"]["units"]
    clips = again.extensions["rating_app"]["clips"]
    assert units and all("SYS" not in {clips[x].condition for x in u.clips} for u in units.values() if u.role == "test")
    page = again.test_client().get("/admin", headers=TOKEN_HDR).get_data(as_text=True)
    assert 'id="conditions"' in page and "withdrawn" in page
    listed = again.test_client().get("/admin/progress.json", headers=TOKEN_HDR).json["conditions"]
    assert {(x["name"], x["round"], x["withdrawn_at"] is None) for x in listed} == {
        ("NAT", 1, True),
        ("MG", 1, True),
        ("FL", 1, True),
        ("SYS", 2, False),
    }


@pytest.mark.full  # add-condition run again and again: the full tier (the fast tier keeps the first test of it)
def test_clashes_are_refused_with_one_line_and_change_nothing(
    make, folders, tmp_path, capsys, app_db_url, stimulus_mp4
):
    study, new = folders
    app = make(study, "pairwise")
    complete(app.test_client())
    engine = app_engine(app)
    before, files = dump(engine), folder_state(study)
    args = ["add-condition", "--db", app_db_url, "--manifest"]

    def variant(name, **kw):
        m = write_fake_stimuli(tmp_path / name, catch_nat=True, **{"n_items": N_ITEMS, "seed": 2, **kw})
        one_size(m.parent, stimulus_mp4)
        return m

    def same():
        assert dump(engine) == before and folder_state(study) == files

    fails_with(main, [*args, str(study)], capsys, "every condition it has (FL, MG, NAT) is already in the study")
    fails_with(main, [*args, str(new), "--condition", "MG"], capsys, "condition MG is already in the study")
    short = variant("short", n_items=N_ITEMS - 1, conditions=("SYS",))
    fails_with(main, [*args, str(short)], capsys, f"has no test clip of item item{N_ITEMS - 1:02d}")
    other_fps = variant("fps", conditions=("SYS",), fps=25)
    fails_with(main, [*args, str(other_fps)], capsys, "(a mismatched design)")
    big = variant("big", conditions=("SYS",))
    video = next(x.video for x in load_manifest(big) if x.condition == "SYS" and x.role == "test")
    video.write_bytes(video.read_bytes() + b"\0" * 16)
    fails_with(main, [*args, str(big)], capsys, "every video must be one size")
    gone = variant("gone", conditions=("SYS",))
    next(x.video for x in load_manifest(gone) if x.condition == "SYS" and x.role == "test").unlink()
    fails_with(main, [*args, str(gone)], capsys, "not found")
    # a clip id the study already has (renamed in the new manifest)
    dup = variant("dup", conditions=("SYS",))
    text = dup.read_text()
    sys_id = next(x.clip_id for x in load_manifest(dup) if x.condition == "SYS")
    taken = next(x.clip_id for x in load_manifest(study))
    dup.write_text(text.replace(sys_id, taken))
    (dup.parent / "videos" / f"{sys_id}.mp4").rename(dup.parent / "videos" / f"{taken}.mp4")
    fails_with(main, [*args, str(dup)], capsys, "is already in the study")
    same()
    # The database refuses after the files were written (a condition of that name joined meanwhile): the study
    # folder is put back as it was.
    from sqlalchemy.orm import Session

    with Session(engine) as s, s.begin():
        s.add(rounds.StudyCondition(name="SYS", round=2, added_at=utcnow()))
    fails_with(main, [*args, str(new)], capsys, "SYS joined the study meanwhile")
    assert folder_state(study) == files
    fails_with(main, ["withdraw-condition", "--db", app_db_url, "--condition", "XX"], capsys, "no condition 'XX'")


def test_only_a_pairwise_study_grows(make, folders, capsys, app_db_url):
    study, new = folders
    make(study, "acr")
    fails_with(main, ["add-condition", "--db", app_db_url, "--manifest", str(new)], capsys, "only a pairwise study")


@pytest.mark.full  # the dashboard re-encodes the new videos: the full tier (the fast tier keeps add-condition)
def test_the_dashboard_adds_and_withdraws(make, folders, tmp_path):
    study, new = folders
    app = make(study, "pairwise", upload_root=str(tmp_path))
    c = app.test_client()
    r = c.post("/admin/conditions", data={"manifest": str(study)}, headers=TOKEN_HDR)
    assert r.status_code == 400 and "already in the study" in r.json["error"]
    assert c.post("/admin/conditions", data={"manifest": str(new)}).status_code == 401  # admins only
    # A browser: logged in through the form, the result is a message on the dashboard.
    assert c.post("/admin/login", data={"token": "test-admin-token"}).status_code == 302
    r = c.post("/admin/conditions", data={"manifest": str(new), "condition": "SYS"}, follow_redirects=True)
    page = r.get_data(as_text=True)
    assert r.status_code == 200 and "round: 2;" in page and "conditions: SYS;" in page
    assert "<td>SYS</td><td>2</td>" in page  # the conditions table
    r = c.post("/admin/conditions/withdraw", data={"condition": "<b>x</b>"}, follow_redirects=True)
    assert "no condition &#39;&lt;b&gt;x&lt;/b&gt;&#39;" in r.get_data(as_text=True)  # refused, shown as text
    r = c.post("/admin/conditions/withdraw", data={"condition": "SYS"}, follow_redirects=True)
    assert "withdrawn" in r.get_data(as_text=True)
    units = app.extensions["rating_app"]["units"]  # this worker at once
    clips = app.extensions["rating_app"]["clips"]
    assert not any("SYS" in {clips[x].condition for x in u.clips} for u in units.values() if u.role == "test")
    r = c.post("/admin/conditions", data={"manifest": str(new)}, headers={"Sec-Fetch-Site": "cross-site", **TOKEN_HDR})
    assert r.status_code == 403  # never on behalf of another site


@pytest.mark.full  # gunicorn and its workers: the full tier (the fast tier stays short)
def test_the_workers_of_a_running_gunicorn_learn_of_the_round(folders, app_db_url, tmp_path):
    """A real server, three worker processes: a crowd rates, add-condition runs beside it, a second crowd gets the
    new pairs from whichever worker it meets, and every count still adds up."""
    from helpers.concurrent_raters import cover_mismatches
    from helpers.servers import crowd_env, start_gunicorn, stop

    from moglow_eval.core.ports import free_port
    from rating_app.simulate import run_simulation
    from rating_app.store.db import make_engine

    study, new = folders
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    log = open(tmp_path / "gunicorn.log", "w")
    proc = start_gunicorn(port, crowd_env(study, app_db_url, "round-token", STUDY_DESIGN="pairwise"), log)
    try:

        def crowd(prefix):
            out = run_simulation(url, 8, manifest=study, seed=1, prefix=prefix, concurrency=8, timeout_s=120,
                                 progress=False)  # fmt: skip
            assert out["errors"] == [] and out["n_raters_completed"] == 8, out["errors"][:3]

        crowd("before")
        assert main(["add-condition", "--db", app_db_url, "--manifest", str(new)]) == 0
        crowd("after")
        r = requests.get(url + "/admin/export.csv", headers={"Authorization": "Bearer round-token"}, timeout=30)
        assert r.status_code == 200
    finally:
        stop([proc])
        log.close()
    rows = [x for x in csv.DictReader(io.StringIO(r.text)) if x["role"] == "test"]
    before = [x for x in rows if x["external_id"].startswith("before")]
    after = [x for x in rows if x["external_id"].startswith("after")]
    assert len(before) == len(after) == 16  # two test pairs a rater (crowd_env)
    assert {x["round"] for x in before} == {"1"} and {x["round"] for x in after} == {"2"}
    assert not any("SYS" in (x["condition_a"], x["condition_b"]) for x in before)
    # The new pairs are the least covered: the second crowd's first nine test slots go to them.
    assert sum("SYS" in (x["condition_a"], x["condition_b"]) for x in after) >= 3 * N_ITEMS
    engine = make_engine(app_db_url)
    try:
        assert cover_mismatches(engine) == {}
    finally:
        engine.dispose()


@pytest.mark.full  # add-condition as a process: the full tier (the fast tier keeps its first test)
def test_active_pairing_takes_in_a_new_condition_and_lets_a_withdrawn_one_go(make, folders, app_db_url):
    """With `--pairing active` the running app's ranking grows with the round: the new system's pairs, with no votes
    yet, have the weakest evidence for their order once the first three's order is backed by votes, so a new
    rater's test pairs go to it; withdrawn, it leaves the ranking."""
    study, new = folders
    app = make(study, "pairwise", ratings_per_clip=6, pairing="active", pairing_random=0.0, clips_per_rater=3)
    c = app.test_client()
    condition = {x.clip_id: x.condition for x in load_manifest(study)}
    bad = {k for k, v in condition.items() if v == "BAD"}
    rank = {"NAT": 3, "MG": 2, "FL": 1, "BAD": 0}

    def by_rank(a, b):
        return 2 if rank[condition[a]] > rank[condition[b]] else -2

    for _ in range(6):  # trusted raters, of one mind: their votes back the order of the first three
        complete(c, bad=bad, prefer=by_rank)
    ranking = c.get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]
    assert set(ranking["order"]) == {"NAT", "MG", "FL"}
    assert main(["add-condition", "--db", app_db_url, "--manifest", str(new)]) == 0
    rater = complete(c)
    test = [r for r in export(c) if r["rater_id"] == rater and r["role"] == "test"]
    assert len(test) == 3 and all("SYS" in (r["condition_a"], r["condition_b"]) for r in test), test
    assert set(c.get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]["order"]) == {"NAT", "MG", "FL", "SYS"}
    assert c.post("/admin/conditions/withdraw", data={"condition": "SYS"}, headers=TOKEN_HDR).status_code == 200
    assert set(c.get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]["order"]) == {"NAT", "MG", "FL"}
    rater = complete(c)
    assert all("SYS" not in (r["condition_a"], r["condition_b"]) for r in export(c) if r["rater_id"] == rater)
