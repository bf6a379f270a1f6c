"""Why a system lost (analysis/designs/pairwise/reasons.py):
the share of each reason in the votes a condition lost, checked by hand
on a small table, against a plain count on the GENEA leaderboard's released votes, and through analysis.report
(stats.json's "reasons_when_lost" and a table in report.html, escaped); and the votes of each round
(analysis/designs/pairwise/rounds.py)."""

import csv
import json
from collections import Counter

import pandas as pd
import pytest
from helpers.paths import LEADERBOARD

from analysis.designs.pairwise import reasons, rounds
from analysis.report import main as report_main
from moglow_eval.core import votes

VOTES = LEADERBOARD / "battles_elo.csv"


def test_shares_by_hand():
    df = pd.DataFrame(
        {
            "condition_a": ["MG", "MG", "FL", "NAT", "MG", "BAD"],
            "condition_b": ["NAT", "NAT", "MG", "MG", "FL", "NAT"],
            "preference": [-2, -1, 1, 0, 2, 2],
            "role": ["test", "test", "test", "test", "test", "catch"],
            "reasons": ["UnrealisticMotion;MotionSmoothness", "UnrealisticMotion", "", "MotionSmoothness", "Own", "x"],
            "reason_text": ["", "arms", "", "", "", ""],
        }
    )
    t = reasons.when_lost(df).set_index("condition")
    # MG lost rows 0, 1 and 2; FL lost row 4; the tie (row 3) and the catch row name no loser.
    assert t.loc["MG", "lost"] == 3 and t.loc["FL", "lost"] == 1 and "NAT" not in t.index and "BAD" not in t.index
    assert list(t.columns) == ["lost", "UnrealisticMotion", "MotionSmoothness", "Own", reasons.TEXT]
    assert t.loc["MG", "UnrealisticMotion"] == pytest.approx(2 / 3)
    assert t.loc["MG", "MotionSmoothness"] == pytest.approx(1 / 3)
    assert t.loc["MG", reasons.TEXT] == pytest.approx(1 / 3) and t.loc["FL", "Own"] == 1.0
    assert reasons.when_lost(df.drop(columns=["reasons", "reason_text"])) is None
    assert reasons.when_lost(df.assign(reasons="", reason_text="")) is None


@pytest.fixture
def leaderboard(shared_dir):
    """(the leaderboard's released rows, those votes as a pairwise export's rows): real data, so the full tier."""
    with open(VOTES, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    out = []
    for r in rows:
        opts = json.loads(r["juiceOptions"])
        out.append(
            {
                "rater_id": r["user"],
                "item": r["input_code"],
                "clip_a": f"{r['input_code']}|{r['model_a']}",
                "clip_b": f"{r['input_code']}|{r['model_b']}",
                "condition_a": r["model_a"],
                "condition_b": r["model_b"],
                "preference": votes.battle_to_preference(r["winner"], r["is_strong"]),
                "role": "test",
                "reasons": ";".join(opts) if isinstance(opts, list) else "",
                "reason_text": json.loads(r["juiceOtherReason"]) if r["juiceOtherReason"] else "",
            }
        )
    return rows, out


def test_shares_on_the_leaderboard_votes_match_a_plain_count(leaderboard):
    rows, pairs = leaderboard
    lost, ticked = Counter(), Counter()
    for r in rows:
        if r["winner"] == "tie":
            continue
        loser = r["model_b"] if r["winner"] == "model_a" else r["model_a"]
        lost[loser] += 1
        opts = json.loads(r["juiceOptions"])
        for x in set(opts if isinstance(opts, list) else []):
            ticked[(loser, x)] += 1
    t = reasons.when_lost(pd.DataFrame(pairs)).set_index("condition")
    assert set(t.index) == set(lost) and len(lost) == 8
    assert list(t.columns[1:5]) == [rid for rid, _ in votes.REALISM_REASONS]  # GENEA's order, then the others
    for cond, n in lost.items():
        assert t.loc[cond, "lost"] == n
        for rid in t.columns[1:-1]:
            assert t.loc[cond, rid] == pytest.approx(ticked[(cond, rid)] / n)


def test_the_report_gives_the_table(tmp_path, leaderboard):
    _, pairs = leaderboard
    pairs[0]["reasons"] += ";<i>odd</i>"  # an id from a file of another tool: shown as text
    path = tmp_path / "pairs.csv"
    pd.DataFrame(pairs).to_csv(path, index=False)
    out = tmp_path / "report"
    assert report_main([str(path), "--out", str(out), "--n-boot", "20"]) == 0
    stats = json.loads((out / "stats.json").read_text())
    want = reasons.as_json(
        reasons.when_lost(pd.read_csv(path, dtype=str).assign(preference=lambda d: d.preference.astype(int)))
    )
    got = stats["reasons_when_lost"]
    assert set(got) == set(want) and all(got[c]["lost"] == want[c]["lost"] for c in want)
    assert got["AMUSE"]["shares"] == pytest.approx(want["AMUSE"]["shares"])
    page = (out / "report.html").read_text()
    assert "Why a system lost" in page and "&lt;i&gt;odd&lt;/i&gt;" in page and "<i>odd" not in page


def test_votes_per_round(tmp_path, leaderboard):
    df = pd.DataFrame(
        {
            "condition_a": ["MG", "NAT", "SYS", "NAT", "MG", "NAT", "BAD"],
            "condition_b": ["NAT", "FL", "MG", "SYS", "FL", "NEW", "NAT"],
            "role": ["test"] * 6 + ["catch"],
            "round": ["1", "", "2", "2", "2", "3", "3"],  # empty: a vote from before rounds, i.e. round 1
        }
    )
    assert rounds.per_round(df) == [
        {"round": 1, "n_votes": 2, "new_conditions": ["FL", "MG", "NAT"]},
        {"round": 2, "n_votes": 3, "new_conditions": ["SYS"]},
        {"round": 3, "n_votes": 1, "new_conditions": ["NEW"]},
    ]
    assert rounds.per_round(df.drop(columns="round")) is None
    # Through the report: a pairs.csv with rounds (the leaderboard's votes, their last rater's as a second round).
    _, pairs = leaderboard
    last = pairs[-1]["rater_id"]
    for p in pairs:
        p["round"] = 2 if p["rater_id"] == last else 1
    path = tmp_path / "pairs.csv"
    pd.DataFrame(pairs).to_csv(path, index=False)
    assert report_main([str(path), "--out", str(tmp_path / "r"), "--n-boot", "20"]) == 0
    stats = json.loads((tmp_path / "r" / "stats.json").read_text())
    n_last = sum(p["rater_id"] == last for p in pairs)
    assert [(r["round"], r["n_votes"]) for r in stats["rounds"]] == [(1, len(pairs) - n_last), (2, n_last)]
    assert "Rounds: the votes of each" in (tmp_path / "r" / "report.html").read_text()
