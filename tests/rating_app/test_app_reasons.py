"""Reasons with a pairwise vote through the JSON API (CONTRACTS §8), on SQLite and PostgreSQL: the configured boxes
and free text, every bad answer refused with a clear 400 and nothing stored, the reasons stored with the vote and
exported beside it (a formula defused), the settings checked at the start, and the battle-format export."""

import csv
import io
import json

import pytest
from helpers.fake_stimuli import write_fake_stimuli
from helpers.paths import LEADERBOARD

from moglow_eval.core import votes
from rating_app import AppError, create_app
from rating_app.__main__ import main

TOKEN_HDR = {"Authorization": "Bearer test-admin-token"}
IDS = [rid for rid, _ in votes.REALISM_REASONS]


def first_rating_trial(c, reason=IDS[0]):
    """(token, the first rating-phase trial), the familiarisation trials answered (and a reason refused there)."""
    token = c.post("/api/sessions", json={}).json["session"]
    while True:
        t = c.get(f"/api/sessions/{token}/next").json["trial"]
        if t["phase"] == "rating":
            return token, t
        r = c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], "reasons": [reason]})
        assert r.status_code == 400 and "familiarisation" in r.json["error"]
        assert c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"]}).status_code == 201


def export_rows(c):
    r = c.get("/admin/export.csv", headers=TOKEN_HDR)
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.data.decode())))


def test_reasons_are_checked_stored_and_exported(make, stimuli):
    app = make(stimuli, "pairwise")
    assert app.config["VOTE_REASONS"] == votes.REALISM_REASONS and app.config["REASON_TEXT"] == votes.FREE_TEXT_MAX
    c = app.test_client()
    token, t = first_rating_trial(c)
    url = f"/api/sessions/{token}/ratings"

    def post(**extra):
        return c.post(url, json={"trial_id": t["trial_id"], "preference": -2, **extra})

    for body, words in (
        ({"reasons": ["NoSuchReason"]}, "unknown reason 'NoSuchReason'"),
        ({"reasons": "UnrealisticMotion"}, "must be a list"),
        ({"reasons": [IDS[0], IDS[0]]}, "given twice"),
        ({"reasons": [1]}, "must be a list"),
        ({"reason_text": "x" * (votes.FREE_TEXT_MAX + 1)}, f"at most {votes.FREE_TEXT_MAX} characters"),
        ({"reason_text": 5}, "must be a string"),
        ({"reason_text": "a\x00b"}, "control characters"),
        ({"why": "x"}, "unknown field 'why'"),
    ):
        r = post(**body)
        assert r.status_code == 400 and words in r.json["error"], (body, r.json)
    assert export_rows(c) == []  # nothing stored by a refused answer
    text = '=HYPERLINK("http://x")\n<b>too stiff</b>, \u00e9l\u00e9gant ' + "y" * 250
    text = text[: votes.FREE_TEXT_MAX]  # exactly the limit is kept, whole
    r = post(reasons=[IDS[3], IDS[0]], reason_text=text)
    assert r.status_code == 201, r.json
    again = post(reasons=[IDS[1]])
    assert again.status_code == 200 and again.json["preference"] == -2  # a repeat: stored once
    rows = export_rows(c)
    assert len(rows) == 1
    row = rows[0]
    cols = list(row)
    assert cols[cols.index("role") + 1 : cols.index("role") + 4] == ["round", "reasons", "reason_text"]
    assert row["reasons"] == f"{IDS[0]};{IDS[3]}"  # in the configured order
    assert row["reason_text"] == "'" + text and row["round"] == "1"
    page = c.get("/admin", headers=TOKEN_HDR).get_data(as_text=True)
    assert "&lt;b&gt;too stiff&lt;/b&gt;" in page and "<b>too stiff" not in page


def test_a_study_without_reasons_takes_none(make, stimuli):
    app = make(stimuli, "pairwise", reasons="none", reason_text=0)
    c = app.test_client()
    page = c.get("/").get_data(as_text=True)
    assert 'id="reasons"' not in page and "reason-text" not in page
    token, t = first_rating_trial(c)
    url = f"/api/sessions/{token}/ratings"
    r = c.post(url, json={"trial_id": t["trial_id"], "preference": 1, "reason_text": "hm"})
    assert r.status_code == 400 and "takes no free text" in r.json["error"]
    r = c.post(url, json={"trial_id": t["trial_id"], "preference": 1, "reasons": [IDS[0]]})
    assert r.status_code == 400 and "unknown reason" in r.json["error"]
    assert c.post(url, json={"trial_id": t["trial_id"], "preference": 1, "reasons": []}).status_code == 201
    assert export_rows(c)[0]["reasons"] == ""


def test_a_configured_list_is_shown_escaped(make, stimuli):
    app = make(stimuli, "pairwise", reasons="Jerky=Jerky <b>motion</b>, Feet=Feet slide", reason_text=50)
    assert app.config["VOTE_REASONS"] == (("Jerky", "Jerky <b>motion</b>"), ("Feet", "Feet slide"))
    page = app.test_client().get("/").get_data(as_text=True)
    assert (
        'value="Jerky"' in page and "Jerky &lt;b&gt;motion&lt;/b&gt;" in page and 'data-max-chars="50"' in page
    )  # characters, as the server counts


@pytest.mark.parametrize("app_db_url", ["sqlite"], indirect=True)
def test_bad_reason_settings_stop_the_start(stimuli, app_db_url, monkeypatch):
    def start(**kw):
        return create_app(manifest=stimuli, db_url=app_db_url, **kw)

    for kw, words in (
        ({"design": "pairwise", "reasons": "1bad=x"}, "is not a reason id"),
        ({"design": "pairwise", "reasons": "A=x,A=y"}, "listed twice"),
        ({"design": "pairwise", "reason_text": votes.FREE_TEXT_MAX + 1}, f"<= {votes.FREE_TEXT_MAX}"),
        ({"design": "acr", "reasons": "A=x"}, "asks for no reasons"),
    ):
        with pytest.raises(AppError, match=words):
            start(**kw)
    monkeypatch.setenv("RATING_VOTE_REASONS", "Env=From the environment")
    assert create_app(manifest=stimuli, db_url=app_db_url, design="pairwise").config["VOTE_REASONS"] == (
        ("Env", "From the environment"),
    )


def test_the_battle_export(make, stimuli, app_db_url, tmp_path, capsys):
    app = make(stimuli, "pairwise")
    c = app.test_client()
    token, t = first_rating_trial(c)
    r = c.post(
        f"/api/sessions/{token}/ratings",
        json={"trial_id": t["trial_id"], "preference": -1, "reasons": [IDS[1]], "reason_text": 'too "stiff"'},
    )
    assert r.status_code == 201
    out = tmp_path / "battles.csv"
    assert main(["export", "--db", app_db_url, "--format", "battles", "--out", str(out)]) == 0
    pairs = [r for r in export_rows(c) if r["role"] == "test"]
    with open(out, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        fights = list(reader)
    assert tuple(reader.fieldnames) == votes.BATTLE_COLUMNS
    assert len(fights) == len(pairs)
    for p, b in zip(pairs, fights):
        assert (b["user"], b["input_code"], b["model_a"], b["model_b"]) == (
            p["rater_id"],
            p["item"],
            p["condition_a"],
            p["condition_b"],
        )
        assert votes.battle_to_preference(b["winner"], b["is_strong"]) == int(p["preference"])
        assert json.loads(b["juiceOptions"]) == [IDS[1], votes.OTHER_REASON]
        assert json.loads(b["juiceOtherReason"]) == 'too "stiff"'


def test_the_battle_export_of_another_design_is_refused(make, stimuli, app_db_url, tmp_path, capsys):
    from helpers.cli import fails_with

    make(stimuli, "acr")
    out = tmp_path / "battles.csv"
    fails_with(main, ["export", "--db", app_db_url, "--format", "battles", "--out", str(out)], capsys, "is acr")
    assert not out.exists() and not [p for p in tmp_path.iterdir() if "battles" in p.name]  # nor a partial one


@pytest.mark.parametrize("name", ["battles_elo.csv", "battles_mismatch.csv"])
def test_our_battle_rows_write_a_vote_as_the_leaderboard_does(name, shared_dir):
    """Each of the leaderboard's released votes, read into (preference, reasons, text) and written back by the
    export's battle_row, gives its own row: the same winner, strength, JSON reason list and JSON-quoted text. The
    only differences: one `[]` for no reasons (we write `{}`, as its other rows) and one `""` for no text (we
    write an empty cell, as its other rows), and the mismatch file's ties, whose strength is `False` there (empty
    in the realism file and here), as its README says."""
    path = LEADERBOARD / name
    from rating_app.operations.battles import battle_row

    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == votes.BATTLE_COLUMNS
    variants = []
    for r in rows:
        pref = votes.battle_to_preference(r["winner"], r["is_strong"])
        ticked = json.loads(r["juiceOptions"])
        text = json.loads(r["juiceOtherReason"]) if r["juiceOtherReason"] else ""
        ours = battle_row(r["user"], r["input_code"], r["model_a"], r["model_b"], pref, ticked or [], text)
        diff = [k for k in votes.BATTLE_COLUMNS if ours[k] != r[k]]
        if diff:
            variants.append(tuple((k, r[k], r["winner"] if k == "is_strong" else "") for k in diff))
    # `[]` for no reasons, `""` for no text (once each in the realism file), and a tie's strength False.
    allowed = {(("juiceOptions", "[]", ""),), (("juiceOtherReason", '""', ""),), (("is_strong", "False", "tie"),)}
    assert set(variants) <= allowed
    n_ties = sum(r["winner"] == "tie" for r in rows)
    assert len(variants) == (2 if name == "battles_elo.csv" else n_ties)


def test_appropriateness_asks_for_reasons_only_when_told(make, tmp_path):
    m = write_fake_stimuli(tmp_path / "fit", n_items=2, catch_nat=True, mismatched=True)
    plain = make(m, "appropriateness")
    assert plain.config["VOTE_REASONS"] == () and plain.config["REASON_TEXT"] == 0
    app = make(m, "appropriateness", reasons="FitRhythmTiming=Rhythm and timing", reason_text=100)
    c = app.test_client()
    assert 'value="FitRhythmTiming"' in c.get("/").get_data(as_text=True)
    token, t = first_rating_trial(c, "FitRhythmTiming")
    r = c.post(
        f"/api/sessions/{token}/ratings",
        json={"trial_id": t["trial_id"], "preference": 1, "reasons": ["FitRhythmTiming"], "reason_text": "late"},
    )
    assert r.status_code == 201, r.json
    row = export_rows(c)[0]
    assert (row["reasons"], row["reason_text"]) == ("FitRhythmTiming", "late") and "matched" in row
