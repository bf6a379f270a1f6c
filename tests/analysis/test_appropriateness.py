"""The appropriateness statistics (issue 32) against an independent computation on real votes: the GENEA
leaderboard's speech-mismatch votes in ../shared (read there, never copied), where each vote compares a system's
motion for the speech heard with the motion it made for other speech."""

import csv
import math

import pytest
from helpers.paths import LEADERBOARD
from scipy import stats as sps

from analysis.designs.appropriateness.mas import analyse, load_answers
from analysis.designs.pairwise.preference import failed_raters

VOTES = LEADERBOARD / "battles_mismatch.csv"
COLUMNS = ["rater_id", "item", "clip_a", "clip_b", "condition_a", "condition_b", "preference", "role", "matched"]


def _as_export(tmp_path):
    """The votes in our export's layout (preference +-2 clearly, +-1 slightly, 0 tie; the side without
    _Mismatched is the matched one), and the scores seen from the matched clip, computed here by hand."""
    rows, scores = [], {}
    with open(VOTES, newline="") as f:
        for k, v in enumerate(csv.DictReader(f)):
            a = v["model_a"]
            system = a.removesuffix("_Mismatched")
            matched = "b" if a.endswith("_Mismatched") else "a"
            level = 0 if v["winner"] == "tie" else (2 if v["is_strong"] == "True" else 1)
            pref = level if v["winner"] == "model_a" else -level
            rows.append([v["user"], v["input_code"], f"c{k}a", f"c{k}b", system, system, pref, "test", matched])
            scores.setdefault(system, []).append(pref if matched == "a" else -pref)
    path = tmp_path / "appropriateness.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        w.writerows(rows)
    return path, scores


@pytest.mark.full  # the real votes in ../shared
def test_mas_on_real_genea_votes_matches_a_hand_computation(tmp_path):
    path, scores = _as_export(tmp_path)
    table = analyse(load_answers(path))["mas"].set_index("condition")
    assert set(table.index) == set(scores)
    for system, s in scores.items():
        n = len(s)
        mean = sum(s) / n
        assert table.at[system, "n"] == n and table.at[system, "mas"] == pytest.approx(mean)
        if n > 1:
            sd = math.sqrt(sum((x - mean) ** 2 for x in s) / (n - 1))
            half = sps.t.ppf(0.975, n - 1) * sd / math.sqrt(n)
            assert table.at[system, "ci_low"] == pytest.approx(mean - half)
        pos, tie = sum(x > 0 for x in s), sum(x == 0 for x in s)
        assert table.at[system, "percent_matched"] == pytest.approx(100 * (pos + tie / 2) / n)
    total = sum(len(s) for s in scores.values())
    assert total == 50 and table["n"].sum() == 50


def test_catch_pairs_exclude_raters_who_prefer_the_broken_clip(tmp_path):
    path = tmp_path / "a.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        w.writerow(["r1", "i1", "x1", "x2", "S", "S", 2, "test", "a"])
        w.writerow(["r2", "i1", "x1", "x2", "S", "S", -1, "test", "a"])
        w.writerow(["r1", "i2", "n1", "b1", "NAT", "BAD", 2, "catch", ""])
        w.writerow(["r2", "i2", "n1", "b1", "NAT", "BAD", -1, "catch", ""])
    df = load_answers(path)
    assert failed_raters(df) == ["r2"]
    assert list(df["score"].dropna()) == [2, -1]


def test_bad_matched_side_is_one_line(tmp_path):
    from analysis.data.load import AnalysisError

    path = tmp_path / "a.csv"
    path.write_text(",".join(COLUMNS) + "\nr1,i1,x1,x2,S,S,2,test,left\n")
    with pytest.raises(AnalysisError, match=r"a.csv:2: a test answer's matched side must be a or b"):
        load_answers(path)


def test_the_two_panels_labels_do_not_run_into_each_other(tmp_path, monkeypatch):
    """Issue 65: the dyadic design's long score name ran its label into the share panel's."""
    import pandas as pd
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from analysis.designs.dyadic.design import Dyadic
    from analysis.page import design_figures

    table = pd.DataFrame({"condition": ["A", "NAT"], "mas": [0.2, 1.0], "ci_low": [0.0, 0.8], "ci_high": [0.4, 1.2],
                          "matched": [0.5, 0.8], "tie": [0.2, 0.1], "mismatched": [0.3, 0.1]})  # fmt: skip
    seen = {}

    def keep(fig, path):
        FigureCanvasAgg(fig).draw()
        r = fig.canvas.get_renderer()
        seen["labels"] = [a.xaxis.label.get_window_extent(r) for a in fig.axes]
        return path

    monkeypatch.setattr(design_figures, "_save", keep)
    design_figures.mas_bars(table, tmp_path / "mas.png", score=Dyadic.score)
    left, right = seen["labels"]
    assert left.x1 < right.x0  # side by side, apart


def test_the_methods_paragraph_gives_no_resamples_where_none_were_drawn(tmp_path):
    """The appropriateness statistics are t intervals and sign tests: the paragraph a paper takes gives the error
    rate, and no count or seed of resamples the report never drew (it said "2000 resamples, seed 0")."""
    from analysis.designs import Options
    from analysis.report import build_report

    path = tmp_path / "a.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in range(6):
            for i in range(4):
                for system in ("S", "T"):
                    w.writerow([f"r{r}", f"i{i}", f"{system}{i}m", f"{system}{i}x", system, system,
                                (r + i) % 4 - 1, "test", "a"])  # fmt: skip
            w.writerow([f"r{r}", "k", "n1", "b1", "NAT", "BAD", 2, "catch", ""])
    doc = build_report(path, tmp_path / "rep", Options(n_boot=123, seed=4), quiet=True)
    assert doc["design"] == "appropriateness"
    assert "sign tests against chance, Holm-adjusted (family-wise error rate 0.05)." in doc["methods"]
    assert "resamples" not in doc["methods"].split("The statistics are")[1].split(".")[0]
