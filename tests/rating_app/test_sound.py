"""The appropriateness design and studies with sound in the app (issue 32), on SQLite and PostgreSQL: units of a
system's matched and mismatched clip, the export that says which is which, the other designs leaving the
mismatched clips out, and the sound check that comes before the examples."""

import csv
import html
import io
import wave

import numpy as np
import pytest
from helpers.design_client import complete, post, shown
from helpers.fake_stimuli import write_fake_stimuli
from helpers.sound_check import sample_of

from analysis.designs import DESIGNS as DesignRegistry
from analysis.designs import Options, detect_design
from analysis.designs.appropriateness.mas import analyse, load_answers
from analysis.report import build_report
from moglow_eval.core import study
from rating_app.designs import get
from rating_app.store.manifest import AppError, load_manifest


@pytest.fixture(scope="module")
def fit_stimuli(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("fit"), n_items=4, catch_nat=True, mismatched=True)


@pytest.fixture(scope="module")
def sound_stimuli(tmp_path_factory):
    """Fake stimuli whose videos say they carry sound, with an audio_check.csv of three tone 'samples'."""
    folder = tmp_path_factory.mktemp("sound")
    manifest = write_fake_stimuli(folder, n_items=3, catch_nat=True, mismatched=True)
    with open(manifest, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r["audio"] = "1"
    with open(manifest, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (folder / "audio_check").mkdir()
    lines = ["file,answer"]
    for k, digits in enumerate(("123", "456", "789")):
        path = folder / "audio_check" / f"s{k}abcdefghijklm.wav"
        with wave.open(str(path), "wb") as w:
            w.setnchannels(1), w.setsampwidth(2), w.setframerate(16000)
            w.writeframes((0.2 * np.sin(np.arange(8000) * (k + 1) * 0.1) * 32767).astype("<i2").tobytes())
        lines.append(f"audio_check/{path.name},{digits}")
    (folder / "audio_check.csv").write_text("\n".join(lines) + "\n")
    return manifest


def _export(c):
    r = c.get("/admin/export.csv", headers={"Authorization": "Bearer test-admin-token"})
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.get_data(as_text=True)))), r.get_data(as_text=True)


# ---------------------------------------------------------------- appropriateness
@pytest.mark.parametrize("design", ["appropriateness", "dyadic", "semantic"])
def test_appropriateness_units_export_and_analysis(make, fit_stimuli, tmp_path, design):
    """The three designs of a matched and a mismatched clip (GENEA 2023's speech and interlocutor appropriateness,
    GENEA 2026's semantic alignment): one unit per item and system, the export naming what the mismatched motion was
    made for in the design's own column, which the report reads back as the same design."""
    clips = {c.clip_id: c for c in load_manifest(fit_stimuli)}
    app = make(fit_stimuli, design, ratings_per_clip=1)
    c = app.test_client()
    r = c.post("/api/sessions", json={})
    assert r.status_code == 201 and r.json["design"] == design
    seen, _ = complete(c, r.json["session"], pref=lambda t: 2)
    rating = [t for t in seen if t["phase"] == "rating"]
    for t in rating:
        a, b = (clips[x["clip_id"]] for x in shown(t))
        assert a.item == b.item
        if a.role == "test":
            assert a.condition == b.condition and bool(a.motion_item) != bool(b.motion_item)
        else:
            assert {a.condition, b.condition} == {"NAT", "BAD"}
    rows, text = _export(c)
    test = [row for row in rows if row["role"] == "test"]
    assert test and all(row["condition_a"] == row["condition_b"] for row in test)
    for row in test:
        matched = row["clip_a"] if row["matched"] == "a" else row["clip_b"]
        other = row["clip_b"] if row["matched"] == "a" else row["clip_a"]
        column = study.MISMATCH_COLUMN[design]
        assert not clips[matched].motion_item and clips[other].motion_item == row[column] != row["item"]
    assert [c for c in study.MISMATCH_COLUMN.values() if c in rows[0]] == [study.MISMATCH_COLUMN[design]]
    assert all(row["matched"] == "" for row in rows if row["role"] == "catch")
    path = tmp_path / "pairs.csv"
    path.write_text(text)
    df = load_answers(path)
    # Every answer was "A clearly": its score is +2 where A was the matched clip, else -2.
    want = [2 if row["matched"] == "a" else -2 for row in test]
    assert sorted(df["score"].dropna().astype(int)) == sorted(want)
    table = analyse(df)["mas"]
    assert table["n"].sum() == len(test)
    assert detect_design(path) == design
    # "A clearly" everywhere fails the catch pairs that show BAD as A: the report reads the test answers alone.
    lines = text.splitlines(keepends=True)
    role = next(csv.reader(lines[:1])).index("role")
    path.write_text("".join([lines[0], *(x for x in lines[1:] if next(csv.reader([x]))[role] == "test")]))
    stats = build_report(path, tmp_path / "report", Options(n_boot=50), quiet=True)
    assert stats["design"] == design and sum(v["n"] for v in stats["mas"].values()) == len(test)
    page = (tmp_path / "report" / "report.html").read_text()
    assert DesignRegistry[design].heading in page


@pytest.mark.parametrize("design", ["dyadic", "semantic"])
def test_the_page_asks_the_designs_question(make, fit_stimuli, design):
    """The rater's page of the dyadic and semantic designs: their own welcome and GENEA's question (or the study's)."""
    app = make(fit_stimuli, design, ratings_per_clip=1)
    page = app.test_client().get("/").get_data(as_text=True)
    assert html.escape(get(design).question, quote=True) in page
    assert {"dyadic": "two people in conversation", "semantic": "highlighted"}[design] in page
    asked = make(fit_stimuli, design, ratings_per_clip=1, question="Who listens better?")
    assert "Who listens better?" in asked.test_client().get("/").get_data(as_text=True)


@pytest.mark.parametrize("design", ["acr", "pairwise", "parallel"])
def test_other_designs_leave_the_mismatched_clips_out(make, fit_stimuli, design):
    clips = {c.clip_id: c for c in load_manifest(fit_stimuli)}
    app = make(fit_stimuli, design, ratings_per_clip=1)
    served = set(app.extensions["rating_app"]["clips"])
    assert served and not any(clips[cid].motion_item for cid in served)
    assert len(served) == sum(not c.motion_item for c in clips.values())


def test_appropriateness_needs_mismatched_clips(make, tmp_path):
    plain = write_fake_stimuli(tmp_path / "plain", n_items=2, catch_nat=True)
    with pytest.raises(AppError, match="no mismatched clips"):
        make(plain, "appropriateness")


# ---------------------------------------------------------------- the sound check
def test_sound_check_comes_first_and_two_failures_end_the_session(make, sound_stimuli):
    app = make(sound_stimuli, "appropriateness", ratings_per_clip=2)
    answers = {
        row["file"].split("/")[1][:-4]: row["answer"]
        for row in csv.DictReader(open(sound_stimuli.parent / "audio_check.csv"))
    }
    c = app.test_client()
    assert 'data-sound="1"' in c.get("/").get_data(as_text=True)
    token = c.post("/api/sessions", json={}).json["session"]
    r = c.get(f"/api/sessions/{token}/next")
    assert r.status_code == 403 and r.json["audio_check"]
    wav = c.get(f"/api/sessions/{token}/audio-check.wav")
    assert wav.status_code == 200 and wav.mimetype == "audio/wav" and wav.data[:4] == b"RIFF"
    assert "ETag" not in wav.headers
    first = sample_of(app, token)
    assert c.post(f"/api/sessions/{token}/audio-check", json={"answer": 5}).status_code == 400
    r = c.post(f"/api/sessions/{token}/audio-check", json={"answer": "000"})
    assert r.status_code == 200 and r.json == {"passed": False, "final": False, "tries_left": 1}
    assert sample_of(app, token) != first  # the second try plays another sample
    r = c.post(f"/api/sessions/{token}/audio-check", json={"answer": "999 9"})
    assert r.json["final"] and "sound" in r.json["error"]
    assert c.get(f"/api/sessions/{token}/next").status_code == 410  # the session is over
    assert c.get(f"/api/sessions/{token}/audio-check.wav").status_code == 410

    token = c.post("/api/sessions", json={}).json["session"]
    assert c.get(f"/api/sessions/{token}/audio-check.wav").status_code == 200
    digits = answers[sample_of(app, token)]
    r = c.post(f"/api/sessions/{token}/audio-check", json={"answer": " ".join(digits)})  # spaces are fine
    assert r.json == {"passed": True}
    r = c.get(f"/api/sessions/{token}/next")
    assert r.status_code == 200 and "trial" in r.json
    assert post(c, token, r.json["trial"]).status_code == 201


def test_a_study_with_sound_needs_its_audio_check(make, sound_stimuli, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(sound_stimuli.parent, copy)
    (copy / "audio_check.csv").unlink()
    with pytest.raises(AppError, match="audio_check.csv: missing"):
        make(copy / "manifest.csv", "acr")


def test_studies_without_sound_have_no_sound_check(make, fit_stimuli):
    app = make(fit_stimuli, "acr", ratings_per_clip=1)
    c = app.test_client()
    token = c.post("/api/sessions", json={}).json["session"]
    assert c.get(f"/api/sessions/{token}/next").status_code == 200
    assert c.get(f"/api/sessions/{token}/audio-check.wav").status_code == 404


def test_dashboard_of_an_appropriateness_study(make, fit_stimuli):
    app = make(fit_stimuli, "appropriateness", ratings_per_clip=1)
    c = app.test_client()
    token = c.post("/api/sessions", json={}).json["session"]
    complete(c, token, pref=lambda t: 1)
    auth = {"Authorization": "Bearer test-admin-token"}
    p = c.get("/admin/progress.json", headers=auth)
    assert p.status_code == 200 and p.json["design"] == "appropriateness"
    systems = {row["condition"] for row in p.json["per_condition"]}
    assert {"NAT vs NAT", "BAD vs NAT"} <= systems
    page = c.get("/admin", headers=auth)
    assert page.status_code == 200 and "appropriateness" in page.get_data(as_text=True)
