"""`add-condition` takes a new system's stimulus folder as hostile (issue 55 items 3 and 4), on SQLite and
PostgreSQL: every path it names stays inside the folder and is a regular file under a cap, each cell is stripped
once, the add is all or nothing (files, folders, manifest, metrics, rows), the dashboard reads only under its
upload root, and nothing a rater's client sees (clip ids, URLs, video bytes, ETag, sizes) is something the
submitter knows."""

import csv
import hashlib
import os
import shutil

import pytest
from helpers.api_client import TOKEN_HDR
from helpers.cli import fails_with
from helpers.fake_stimuli import write_stimulus_mp4
from helpers.study_folders import dump, folder_state
from sqlalchemy.orm import Session

from rating_app.__main__ import main
from rating_app.operations import submission
from rating_app.store import rounds
from rating_app.store.db import app_engine, utcnow
from rating_app.store.manifest import load_manifest

pytestmark = pytest.mark.full  # add-condition's copies and encodes: the full tier


def sys_rows(manifest):
    return [r for r in csv.DictReader(open(manifest)) if r["condition"] == "SYS" and r["role"] == "test"]


def rewrite(manifest, edit):
    """The manifest with edit(row) applied to each of SYS's test rows."""
    rows = list(csv.DictReader(open(manifest)))
    for r in rows:
        if r["condition"] == "SYS" and r["role"] == "test":
            edit(r)
    with open(manifest, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def tree(folder):
    """Every file and folder under a stimulus folder (what a refused add must leave as it was)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture
def study_app(make, folders):
    study, new = folders
    return make(study, "pairwise", upload_root=str(new.parent.parent / "uploads")), study, new


def add(app_db_url, manifest):
    return ["add-condition", "--db", app_db_url, "--manifest", str(manifest)]


def refused(study_app, app_db_url, capsys, manifest, needle):
    """The add of `manifest` is one line saying `needle`, and the study folder and database are as they were."""
    app, study, _ = study_app
    before, files, paths = dump(app_engine(app)), folder_state(study), tree(study.parent)
    fails_with(main, add(app_db_url, manifest), capsys, needle)
    assert dump(app_engine(app)) == before and folder_state(study) == files and tree(study.parent) == paths


# ------------------------------------------------------------------------------ paths (failure 2, noticed 3)
def test_a_motion_file_that_leads_out_of_the_folder_is_refused(study_app, app_db_url, capsys, tmp_path):
    _, study, new = study_app
    secret = tmp_path / "secret.txt"
    secret.write_text("ADMIN_TOKEN=test-admin-token")
    first = sys_rows(new)[0]
    link = new.parent / first["motion"]
    link.unlink()
    link.symlink_to("/proc/self/environ")
    refused(study_app, app_db_url, capsys, new, "leaves the new manifest's folder")
    link.unlink()
    link.symlink_to(secret)
    refused(study_app, app_db_url, capsys, new, "leaves the new manifest's folder")
    rewrite(new, lambda r: r.update(motion="../secret.txt") if r["clip_id"] == first["clip_id"] else None)
    refused(study_app, app_db_url, capsys, new, "leaves the new manifest's folder")
    assert not any(b"test-admin-token" in p.read_bytes() for p in study.parent.rglob("*") if p.is_file())


def test_a_path_that_is_no_regular_file_or_too_large_is_refused(study_app, app_db_url, capsys, monkeypatch):
    _, _, new = study_app
    motion = new.parent / sys_rows(new)[0]["motion"]
    motion.unlink()
    os.mkfifo(motion)  # read, it would wait for ever
    refused(study_app, app_db_url, capsys, new, "is not a regular file")
    motion.unlink()
    motion.write_bytes(b"x" * 2048)
    monkeypatch.setitem(submission.MAX_BYTES, "motion", 1024)
    refused(study_app, app_db_url, capsys, new, "more than a motion file may be")


# ------------------------------------------------------------------------------ cells (failure 4)
def test_a_cell_with_blanks_is_stripped_once_and_the_video_is_taken(study_app, app_db_url, make):
    app, study, new = study_app
    rewrite(new, lambda r: r.update(video=r["video"] + " ", motion=" " + r["motion"], clip_id=r["clip_id"] + " "))
    assert main(add(app_db_url, new)) == 0
    added = [c for c in load_manifest(study) if c.condition == "SYS"]
    assert len(added) == len(sys_rows(new)) and all(c.video.is_file() for c in added)
    again = make(study, "pairwise")  # a restart serves the grown study
    c = again.test_client()
    assert {x.clip_id for x in added} <= set(again.extensions["rating_app"]["clips"])
    r = c.post("/api/sessions", json={})
    assert r.status_code == 201


# ------------------------------------------------------------------------------ metrics.csv (failure 8)
@pytest.mark.parametrize(
    "edit, needle",
    [
        (lambda text: text.encode("utf-8") + b"\xff\xfe,1\n", "not UTF-8 text"),
        (lambda text: text.replace(",", "," + "9" * 200_000, 1).encode(), "not CSV (field larger"),
        (lambda text: text.encode() + b"x" * (2 << 20), "line longer than"),
    ],
)
def test_a_bad_metrics_file_is_one_line(study_app, app_db_url, capsys, edit, needle):
    _, _, new = study_app
    metrics = new.parent / "metrics.csv"
    metrics.write_bytes(edit(metrics.read_text()))
    refused(study_app, app_db_url, capsys, new, needle)


def test_a_metric_that_is_not_a_number_is_refused(study_app, app_db_url, capsys):
    _, _, new = study_app
    metrics = new.parent / "metrics.csv"
    rows = list(csv.reader(open(metrics)))
    sys_id = sys_rows(new)[0]["clip_id"]
    for r in rows:
        if r[0] == sys_id:
            r[-1] = "=HYPERLINK(1)"
    with open(metrics, "w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    refused(study_app, app_db_url, capsys, new, "is not a number")


# ------------------------------------------------------------------------------ all or nothing (failure 9)
def test_a_refused_add_leaves_no_file_and_no_folder(study_app, app_db_url, capsys):
    _, study, new = study_app
    shutil.rmtree(study.parent / "clips")  # the study keeps no motion files yet: the add would make the folder
    # The last video cannot be taken (an MP4's first box, then nothing ffmpeg can read): every file before it was
    # made, then all are undone.
    size = (new.parent / sys_rows(new)[0]["video"]).stat().st_size
    (new.parent / sys_rows(new)[-1]["video"]).write_bytes(b"\0\0\0\x18ftypisom" + b"\0" * (size - 12))
    refused(study_app, app_db_url, capsys, new, "not taken")
    assert not (study.parent / "clips").exists() and not list(study.parent.glob(".adding-*"))
    # The database refuses after every file was moved into place (a condition of that name joined meanwhile):
    # the files go, and so do the folders made for them.
    write_stimulus_mp4(new.parent / sys_rows(new)[-1]["video"])
    app = study_app[0]
    with Session(app_engine(app)) as s, s.begin():
        s.add(rounds.StudyCondition(name="SYS", round=2, added_at=utcnow()))
    refused(study_app, app_db_url, capsys, new, "SYS joined the study meanwhile")
    assert not (study.parent / "clips").exists() and not list(study.parent.glob(".adding-*"))


# ------------------------------------------------------------------------------ the dashboard's upload root
def test_the_dashboard_reads_only_under_its_upload_root(make, folders, tmp_path):
    study, new = folders
    uploads = tmp_path / "uploads"
    uploads.mkdir()
    off = make(study, "pairwise").test_client()
    r = off.post("/admin/conditions", data={"manifest": str(new)}, headers=TOKEN_HDR)
    assert r.status_code == 400 and "RATING_UPLOAD_ROOT, which is not set" in r.json["error"]
    c = make(study, "pairwise", upload_root=str(uploads)).test_client()
    (uploads / "link").symlink_to(new.parent)  # a link out of the root is followed, and refused
    for path in (str(new), "../new/manifest.csv", "link/manifest.csv", "/proc/self/environ"):
        r = c.post("/admin/conditions", data={"manifest": path}, headers=TOKEN_HDR)
        assert r.status_code == 400 and "under the upload root" in r.json["error"], (path, r.json)
    assert c.post("/admin/conditions", data={"manifest": "../new/manifest.csv"}).status_code == 401  # admins only
    shutil.copytree(new.parent, uploads / "sys")
    r = c.post("/admin/conditions", data={"manifest": "sys/manifest.csv"}, headers=TOKEN_HDR)
    assert r.status_code == 200 and r.json["conditions"] == ["SYS"], r.json


# ------------------------------------------------------------------------------ blind to the submitter (failure 3)
def test_the_submitter_cannot_recognise_its_own_clips(study_app, app_db_url):
    """A bot that knows only its own folder (clip ids, video bytes and their hashes) finds none of its clips in
    what a rater's client sees: the trials' ids and URLs, the videos' bytes, ETags and sizes."""
    app, study, new = study_app
    mine = sys_rows(new)
    for k, r in enumerate(mine):  # the system's own videos: each its own bytes, of the study's one size
        write_stimulus_mp4(new.parent / r["video"], seed=k + 1)
    own_ids = {r["clip_id"] for r in mine}
    own_bytes = {(new.parent / r["video"]).read_bytes() for r in mine}
    own_hashes = {hashlib.sha256(b).hexdigest()[:n] for b in own_bytes for n in (32, 64)}
    assert main(add(app_db_url, new)) == 0
    study_sizes = {c.video.stat().st_size for c in load_manifest(study) if c.condition != "SYS"}
    c = app.test_client()
    token = c.post("/api/sessions", json={}).json["session"]
    seen_sys, recognised = 0, 0
    clips = None
    while not (r := c.get(f"/api/sessions/{token}/next")).json.get("done"):
        t = r.json["trial"]
        text = r.get_data(as_text=True)
        recognised += any(i in text for i in own_ids)
        for side in ("a", "b"):
            v = c.get(t[side]["video_url"])
            recognised += v.data in own_bytes or (v.headers.get("ETag") or "").strip('"') in own_hashes
            assert len(v.data) in study_sizes
        clips = clips or app.extensions["rating_app"]["clips"]
        seen_sys += "SYS" in {clips[t["a"]["clip_id"]].condition, clips[t["b"]["clip_id"]].condition}
        body = {"trial_id": t["trial_id"], "preference": None if t["phase"] == "training" else 0}
        assert c.post(f"/api/sessions/{token}/ratings", json=body).status_code == 201
    assert seen_sys >= 3 and recognised == 0
    # The study's own records: fresh ids, none of the submitter's, and no file of the submitted bytes.
    added = [x for x in load_manifest(study) if x.condition == "SYS"]
    assert not {x.clip_id for x in added} & own_ids
    assert not {x.video.read_bytes() for x in added} & own_bytes
